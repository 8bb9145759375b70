// frictionlab operator console (Sec. 7.1 of the thesis, in a browser).
// Plain script, no build step; the plot is uPlot (static/vendor).
"use strict";

(() => {
  const TOKEN = new URLSearchParams(location.search).get("token");
  const KEEP_S = 30;          // seconds of samples kept for the plot (longest window)

  // Signals of the plot: the four measured ones on by default, the estimates on demand.
  const GROUPS = [
    { id: "angles", unit: "rad", height: 170 },
    { id: "velocities", unit: "rad/s", height: 150 },
    { id: "control", unit: "m/s²", height: 150 },
  ];
  // Estimates are dashed, measured signals and u solid: told apart by line style as well
  // as by colour (an estimate of a measured signal shares its hue).  Every trace has its
  // own colour and dash pattern pair, and every toggle shows it: the pendulum-rate
  // estimate (no measured twin) is orange dash-dot, not a second dashed blue, and the
  // friction estimate F-hat a dark dotted line, not a brown dashed one beside u.
  const DASH = [6, 4];
  const DASH_DOT = [8, 3, 2, 3];
  const DOTTED = [2, 3];
  const SIGNALS = [
    { key: "theta_m", label: "θ measured", group: "angles", color: "#1f6feb", on: true },
    { key: "arm_m", label: "arm Ω measured", group: "angles", color: "#2e7d32", on: true },
    { key: "theta_hat", label: "θ̂ angle estimate", group: "angles", color: "#1f6feb", on: false, est: true, dash: DASH },
    { key: "arm_hat", label: "Ω̂ arm estimate", group: "angles", color: "#2e7d32", on: false, est: true, dash: DASH },
    { key: "arm_dot_m", label: "arm velocity measured", group: "velocities", color: "#8e24aa", on: true },
    { key: "arm_dot_hat", label: "arm velocity estimate", group: "velocities", color: "#8e24aa", on: false, est: true, dash: DASH },
    { key: "theta_dot_hat", label: "θ̇ pendulum rate estimate", group: "velocities", color: "#e69f00", on: false, est: true, dash: DASH_DOT },
    { key: "u", label: "control u", group: "control", color: "#d84315", on: true },
    { key: "friction_hat", label: "friction estimate F̂", group: "control", color: "#263238", on: false, est: true, dash: DOTTED, width: 2 },
  ];
  // Time axis: ticks at whole multiples of one of these steps (s), at least 80 px apart.
  const X_STEPS = [0.5, 1, 2, 5, 10];

  const $ = (id) => document.getElementById(id);
  // State shared with the browser tests (read-only for them).
  const ui = (window.__console = {
    frames: 0, renders: 0, lastT: null, status: null, schema: null, connected: false,
    ended: false, frameEnds: [], frameWall: [], xRange: null,
  });

  // --- HTTP -------------------------------------------------------------------------------
  async function api(method, path, body) {
    const headers = {};
    if (TOKEN) headers.Authorization = "Bearer " + TOKEN;
    const init = { method, headers, credentials: "same-origin" };
    if (method !== "GET") {
      headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(body || {});
    }
    let resp;
    try {
      resp = await fetch(path, init);
    } catch (err) {
      return { ok: false, status: 0, data: { detail: "no connection to the console", errors: [] } };
    }
    let data = null;
    try { data = await resp.json(); } catch (err) { data = { detail: resp.statusText, errors: [] }; }
    if (resp.ok && data && data.status && typeof data.status === "object") showStatus(data.status);
    return { ok: resp.ok, status: resp.status, data };
  }
  const withToken = (url) => (TOKEN ? url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN) : url);

  // --- number fields --------------------------------------------------------------------
  const NUMBER = /^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/;

  function rangeText(f) {
    const lo = f.lo === null ? "-inf" : f.lo;
    const hi = f.hi === null ? "inf" : f.hi;
    return (f.lo_open || f.lo === null ? "(" : "[") + lo + ", " + hi + (f.hi_open || f.hi === null ? ")" : "]");
  }

  // Parse and range-check one field; returns {value} or {error}.
  function checkNumber(f, text) {
    text = text.trim();
    if (!NUMBER.test(text)) return { error: `${f.name} must be a number` };
    const v = Number(text);
    if (!Number.isFinite(v)) return { error: `${f.name} must be a finite number` };
    const below = f.lo !== null && (v < f.lo || (f.lo_open && v === f.lo));
    const above = f.hi !== null && (v > f.hi || (f.hi_open && v === f.hi));
    const unit = f.unit && f.unit !== "1" ? " " + f.unit : "";
    if (below || above) return { error: `${f.name} = ${v}${unit} is out of range; allowed ${rangeText(f)}${unit}` };
    return { value: v };
  }

  function fieldRow(container, f, prefix, onEdit) {
    const row = document.createElement("div");
    row.className = "field";
    const id = `${prefix}-${f.name}`;
    row.innerHTML = `<label for="${id}"></label><input id="${id}" type="text" inputmode="decimal" autocomplete="off"><span class="error" id="${id}-error"></span>`;
    const label = row.querySelector("label");
    // a long name breaks after an underscore, not inside a word (<wbr>)
    f.name.split("_").forEach((part, i) => {
      if (i) label.append("_", document.createElement("wbr"));
      label.append(part);
    });
    if (f.unit && f.unit !== "1") label.append(` (${f.unit})`);
    label.title = `${f.doc}; allowed ${rangeText(f)}`;
    const input = row.querySelector("input");
    input.dataset.field = f.name;
    input.title = label.title;
    input.addEventListener("input", () => { setError(input, ""); onEdit(); });
    container.appendChild(row);
    return input;
  }

  function setError(input, message) {
    const span = $(input.id + "-error");
    if (span) span.textContent = message || "";
    input.classList.toggle("invalid", !!message);
    if (message) input.setAttribute("aria-invalid", "true"); else input.removeAttribute("aria-invalid");
  }

  function setMsg(id, text, bad) {
    const el = $(id);
    el.textContent = text || "";
    el.classList.toggle("bad", !!bad);
  }

  // Validate a panel's inputs; returns {values} or null after showing the errors.
  function collect(panel) {
    const values = {};
    let bad = false;
    for (const [name, input] of Object.entries(panel.inputs)) {
      const r = checkNumber(panel.fields[name], input.value);
      if (r.error) { setError(input, r.error); bad = true; } else { setError(input, ""); values[name] = r.value; }
    }
    return bad ? null : values;
  }

  // Show the server's refusal beside the fields it names.
  function showServerErrors(panel, data, msgId) {
    let shown = false;
    for (const e of (data && data.errors) || []) {
      const name = (e.field || "").replace(/^params\./, "");
      const input = panel && panel.inputs[name];
      if (input) { setError(input, e.message); shown = true; }
      else if (panel === panels.friction && name === "error_signal") { $("error-signal-error").textContent = e.message; shown = true; }
    }
    const why = data && data.confirm_required ? "refused (unsafe): " : "refused: ";
    setMsg(msgId, shown ? why + "see the marked fields" : why + ((data && data.detail) || "invalid input"), true);
  }

  // --- changes the model predicts unsafe -----------------------------------------------
  // The server refuses a change that would make the loop unstable or saturate u (422 with
  // confirm_required, the reason and what would pass); the operator may apply it anyway.
  let confirmResolve = null;
  function confirmUnsafe(data, title, apply) {
    $("confirm-title").textContent = title || "The model predicts this change is unsafe";
    $("confirm-apply").textContent = apply || "Apply anyway";
    $("confirm-text").textContent = data.detail;
    $("confirm").hidden = false;
    $("confirm-cancel").focus();
    return new Promise((resolve) => { confirmResolve = resolve; });
  }
  function closeConfirm(answer) {
    $("confirm").hidden = true;
    if (confirmResolve) { const r = confirmResolve; confirmResolve = null; r(answer); }
  }

  // POST a parameter change; if the model refuses it, ask, and resend with confirm.
  async function change(path, body) {
    const r = await api("POST", path, body);
    if (r.ok || !(r.data && r.data.confirm_required)) return r;
    if (await confirmUnsafe(r.data)) {
      const again = await api("POST", path, { ...body, confirm: true });
      if (again.ok) again.confirmed = true;
      return again;
    }
    return r;
  }

  // --- panels ---------------------------------------------------------------------------
  const panels = {
    feedback: { inputs: {}, fields: {}, dirty: false },
    observer: { inputs: {}, fields: {}, dirty: false },
    friction: { inputs: {}, fields: {}, dirty: false, kind: null },
  };

  function buildDesignPanel(name, fields) {
    const panel = panels[name];
    const box = $(`${name}-fields`);
    box.textContent = "";
    for (const f of fields) {
      panel.fields[f.name] = f;
      panel.inputs[f.name] = fieldRow(box, f, name, () => { panel.dirty = true; });
    }
  }

  function buildFrictionFields(kind) {
    const panel = panels.friction;
    if (panel.kind === kind) return;
    panel.kind = kind;
    panel.inputs = {};
    panel.fields = {};
    panel.dirty = false;
    const box = $("friction-fields");
    box.textContent = "";
    for (const f of ui.schema.compensation.fields[kind]) {
      panel.fields[f.name] = f;
      panel.inputs[f.name] = fieldRow(box, f, "friction", () => { panel.dirty = true; });
    }
    $("error-signal-row").hidden = kind !== "lugre" && kind !== "adaptive";
  }

  async function applyDesign(name) {
    const panel = panels[name];
    const values = collect(panel);
    if (!values) { setMsg(`${name}-msg`, "not applied: correct the marked fields", true); return; }
    const r = await change("/api/design", values);
    if (r.ok) { panel.dirty = false; setMsg(`${name}-msg`, r.confirmed ? "applied (unsafe, confirmed)" : "applied", r.confirmed); }
    else showServerErrors(panel, r.data, `${name}-msg`);
  }

  async function applyPreset(preset) {
    const r = await change("/api/design", { preset });
    if (r.ok) {
      panels.feedback.dirty = panels.observer.dirty = false;
      for (const p of [panels.feedback, panels.observer]) for (const i of Object.values(p.inputs)) setError(i, "");
      setMsg("feedback-msg", `${preset} design applied`);
      setMsg("observer-msg", "");
      if (r.data && r.data.status) showStatus(r.data.status, true);
    } else setMsg("feedback-msg", "refused: " + r.data.detail, true);
  }

  async function applyFriction() {
    const panel = panels.friction;
    const values = collect(panel);
    if (!values) { setMsg("friction-msg", "not applied: correct the marked fields", true); return; }
    const body = { params: values };
    if (panel.kind === "lugre" || panel.kind === "adaptive") body.error_signal = $("error-signal").value;
    const r = await change("/api/compensation", body);
    if (r.ok) { panel.dirty = false; setMsg("friction-msg", r.confirmed ? "applied (unsafe, confirmed)" : "applied", r.confirmed); }
    else showServerErrors(panel, r.data, "friction-msg");
  }

  function fillInputs(panel, values, force) {
    if (panel.dirty && !force) return;
    for (const [name, input] of Object.entries(panel.inputs)) {
      if (document.activeElement === input && !force) continue;
      const v = values[name];
      if (v !== undefined && v !== null) input.value = String(+v.toPrecision(6));
    }
  }

  // --- status line --------------------------------------------------------------------------
  const unitText = (u) => (u || "m/s^2").replace("^2", "²");
  const fmt = (v, d = 3) => (v === null || v === undefined || Number.isNaN(v) ? "-" : String(+Number(v).toPrecision(d)));
  const gains = (arr) => (arr ? "[" + arr.flat().map((v) => Number(v).toPrecision(4)).join(", ") + "]" : "-");

  function showStatus(st, force) {
    ui.status = st;
    const running = !!st.running;
    const state = $("run-state");
    state.textContent = running ? "running" : (st.stop_reason ? `stopped: ${st.stop_reason}` : "stopped");
    state.className = running ? "running" : "stopped";
    const detail = !running && st.stop_detail ? ` (${st.stop_detail})` : "";
    $("run-info").textContent = `${detail} t = ${fmt(st.t, 4)} s · ticks ${st.ticks ?? 0} · missed ${st.missed ?? 0} · overruns ${st.overruns ?? 0}` +
      (st.recording ? " · recording" : "") + (st.run_id ? ` · run ${st.run_id}` : "");
    const j = st.jitter_ms || {}, c = st.compute_us || {};
    $("timing").textContent = `jitter p50 ${fmt(j.p50)} ms, p99 ${fmt(j.p99)} ms, max ${fmt(j.max)} ms · ` +
      `compute p50 ${fmt(c.p50)} µs, p99 ${fmt(c.p99)} µs · dropped to console ${(st.console && st.console.samples_dropped) || 0}`;
    const lc = (st.console && st.console.limit_cycle) || {};
    $("lc-window").textContent = lc.window ?? 5;
    $("lc-ptp").textContent = fmt(lc.peak_to_peak);
    $("lc-ptp").dataset.value = lc.peak_to_peak ?? "";
    $("lc-period").textContent = fmt(lc.period);
    $("lc-period").dataset.value = lc.period ?? "";
    // the figures only while balancing: a hanging, swinging or fallen pendulum is said as such
    const pend = lc.pendulum || "unknown";
    $("limit-cycle").dataset.pendulum = pend;
    $("lc-figures").hidden = pend !== "balancing";
    $("lc-status").textContent = pend === "balancing"
      ? (lc.status ? lc.status.replace("_", " ") : "-")
      : (PENDULUM_TEXT[pend] || pend);

    const comp = st.compensation || {};
    const friction = st.friction ? `${st.friction} friction` : "real rig";
    $("setup").textContent = `plant ${st.plant || "thesis"} (u in ${unitText(st.u_unit)}) · backend ${st.backend} (${friction}) · design ${(st.design && st.design.preset) || "custom"} · ` +
      `compensation ${comp.enabled ? "on" : "off"} (${comp.kind || "-"})` + (st.pending_changes ? " · change pending" : "");

    const sw = st.swing_up;
    const phase = $("swing-phase");
    phase.dataset.phase = sw ? sw.phase : "";
    phase.textContent = sw ? ` · swing-up: ${sw.phase}` +
      (sw.swing_up_time !== null && sw.swing_up_time !== undefined ? ` (caught at ${fmt(sw.swing_up_time, 4)} s)` : "") : "";
    $("swingup").disabled = running || !!(st.console && st.console.exited);

    const start = $("start");
    start.disabled = !!(st.console && st.console.exited);
    start.textContent = running ? "Stop" : "Start";
    start.classList.toggle("danger", running);
    start.classList.toggle("primary", !running);

    if (st.design) {
      $("gains-L").textContent = gains(st.design.L);
      $("gains-K").textContent = gains(st.design.K);
      fillInputs(panels.feedback, st.design.spec, force);
      fillInputs(panels.observer, st.design.spec, force);
    }
    if (ui.schema && comp.kind) {
      const btn = $("compensation");
      btn.setAttribute("aria-pressed", comp.enabled ? "true" : "false");
      btn.textContent = comp.enabled ? "Compensating" : "Compensation";
      const sel = $("friction-type");
      if (document.activeElement !== sel) sel.value = comp.kind;
      buildFrictionFields(comp.kind);
      fillInputs(panels.friction, comp.params || {}, force);
      const es = $("error-signal");
      if (document.activeElement !== es && comp.error_signal && !panels.friction.dirty) es.value = comp.error_signal;
    }
    // the adaptive compensator: its estimates beside the panel, and F̂ on the plot
    const ad = st.adaptation;
    $("adapted").hidden = !ad;
    if (ad) {
      $("adapted-coulomb").textContent = fmt(ad.coulomb);
      $("adapted-stiction").textContent = fmt(ad.stiction);
      $("adapted-status").textContent = String(ad.status).replace("_", " ");
      if (!ui.estimateShown) {
        ui.estimateShown = true;
        showSignal("friction_hat");
      }
    }
    const save = $("save");
    const recording = !!st.recording;
    save.setAttribute("aria-pressed", recording ? "true" : "false");
    save.textContent = recording ? "Stop saving" : "Save";
    $("save-state").textContent = recording ? "recording…" : "";
    const pending = st.console && st.console.pending_recording;
    if (pending && $("save-prompt").hidden) { $("save-prompt").hidden = false; }
    if (!pending && !$("save-prompt").hidden && !recording) { $("save-prompt").hidden = true; }
    const emulated = st.backend === "sim" || String(st.backend || "").startsWith("udp://");
    $("push").disabled = !running || !emulated;
    $("push").title = emulated ? "disturb the pendulum" : "only on simulated rigs";
    showExperiment(st, running);
  }

  const PENDULUM_TEXT = {
    hanging: "pendulum hanging (limit-cycle figures are measured while balancing)",
    swinging: "pendulum swinging (limit-cycle figures are measured while balancing)",
    catching: "pendulum caught, settling (limit-cycle figures once the window holds only balancing)",
    fallen: "pendulum fallen",
    stopped: "stopped",
    unknown: "-",
  };

  // --- Experiments panel: progress while it runs, the estimate when done ----------------------
  function showExperiment(st, running) {
    $("experiment-run").disabled = running;
    const e = st.console && st.console.experiment;
    if (!e) return;
    const live = st.experiment;
    if (e.state === "running") {
      // from the first phase on: what it does now, how long it has run, the share done
      const pct = live ? Math.round(100 * (live.progress || 0)) : 0;
      const secs = e.elapsed != null ? `, ${Math.round(e.elapsed)} s` : "";
      setMsg("experiment-msg", `${e.name} running (${pct} % done${secs}): ` +
        `${live && live.phase ? live.phase : "starting"}`);
      $("experiment-progress").hidden = false;
      $("experiment-progress").value = live ? (live.progress || 0) : 0;
      $("experiment-result").textContent = "";
    } else {
      $("experiment-progress").hidden = true;
      setMsg("experiment-msg", `${e.name}: ${e.message || e.state}`, e.state !== "done");
      const lines = [];
      const units = e.units || {};
      for (const [k, v] of Object.entries(e.estimates || {})) {
        const unit = units[k] && units[k] !== "1" ? ` ${units[k]}` : "";
        lines.push(`${k} = ${v === null ? "-" : Number(v).toPrecision(5) + unit}`);
      }
      for (const w of e.warnings || []) lines.push(`warning: ${w}`);
      if (e.log) lines.push(`log: ${e.log}`);
      $("experiment-result").textContent = lines.join("\n");
    }
  }

  async function runExperiment() {
    let options = {};
    try {
      options = JSON.parse($("experiment-options").value || "{}");
      if (typeof options !== "object" || options === null || Array.isArray(options)) throw new Error("an object");
    } catch (err) {
      setError($("experiment-options"), 'options must be a JSON object, e.g. {"hold": 0.2}');
      return;
    }
    setError($("experiment-options"), "");
    const body = { name: $("experiment-name").value, options };
    let r = await api("POST", "/api/experiment", body);
    if (!r.ok && r.data && r.data.confirm_required) {
      if (!(await confirmUnsafe(r.data, "The experiment drives the motor", "Run"))) { setMsg("experiment-msg", "cancelled"); return; }
      r = await api("POST", "/api/experiment", { ...body, confirm: true });
    }
    if (!r.ok) {
      const e = (r.data && r.data.errors && r.data.errors[0]) || {};
      if (e.field && e.field.startsWith("options")) setError($("experiment-options"), e.message);
      setMsg("experiment-msg", "refused: " + ((r.data && r.data.detail) || "invalid input"), true);
      return;
    }
    showStatus(r.data.status);
  }

  // --- plot ------------------------------------------------------------------------------------
  const data = { t: [] };
  for (const s of SIGNALS) data[s.key] = [];
  // The plotted samples of one signal from loop time `since` on: {t: [...], v: [...]}.
  ui.samples = (key, since) => {
    const out = { t: [], v: [] };
    for (let i = 0; i < data.t.length; i++) {
      if (data.t[i] >= since) { out.t.push(data.t[i]); out.v.push(data[key][i]); }
    }
    return out;
  };
  const charts = {};
  let dirty = false;
  let windowS = 10;

  // Evenly spaced time ticks: whole multiples of the smallest step of X_STEPS that keeps
  // labels 80 px apart (uPlot's own choice gave rounded, uneven labels such as 0.3, 0.5, 0.8).
  const xTicks = {};
  const tickStep = (ticks) => (ticks.length > 1 ? +(ticks[1] - ticks[0]).toFixed(6) : 1);
  function timeTicks(u, min, max) {
    const px = u.bbox.width / (window.devicePixelRatio || 1);
    const step = X_STEPS.find((s) => ((max - min) / s) * 80 <= px) || X_STEPS[X_STEPS.length - 1];
    const out = [];
    for (let k = Math.ceil(min / step - 1e-9); k * step <= max + 1e-9; k++) out.push(+(k * step).toFixed(6));
    return out;
  }

  function buildPlots() {
    const box = $("plots");
    const width = Math.max(320, box.clientWidth - 4);
    for (const g of GROUPS) {
      const sigs = SIGNALS.filter((s) => s.group === g.id);
      const el = document.createElement("div");
      el.className = "chart";
      el.id = `plot-${g.id}`;
      box.appendChild(el);
      const opts = {
        width, height: g.height,
        legend: { show: false },
        cursor: { drag: { x: false, y: false } },
        scales: { x: { time: false } },
        series: [{}, ...sigs.map((s) => ({ label: s.label, stroke: s.color, width: s.width || 1.5,
          show: s.on, dash: s.dash, points: { show: false } }))],
        axes: [
          { label: "t (s)", labelSize: 18, size: 32, splits: (u, i, min, max) => (xTicks[g.id] = timeTicks(u, min, max)),
            values: (u, ticks) => ticks.map((v) => v.toFixed(tickStep(ticks) < 1 ? 1 : 0)) },
          { label: g.unit, size: 64, space: 20, values: (u, ticks) => ticks.map((v) => +v.toPrecision(3)) },
        ],
      };
      charts[g.id] = { plot: new uPlot(opts, [[], ...sigs.map(() => [])], el), sigs };
    }
    ui.charts = charts;
    ui.shown = (key) => {   // whether a signal's curve is drawn (for tests)
      const s = SIGNALS.find((x) => x.key === key), c = charts[s.group];
      return c.plot.series[c.sigs.indexOf(s) + 1].show;
    };
    ui.style = (key) => {   // a curve's colour and dash pattern (for tests)
      const s = SIGNALS.find((x) => x.key === key), c = charts[s.group];
      const ser = c.plot.series[c.sigs.indexOf(s) + 1];
      return { color: s.color, dash: ser.dash || null };
    };
    ui.xAxis = (group) => ({ label: charts[group].plot.axes[0].label, ticks: xTicks[group] || [] });
    window.addEventListener("resize", () => {
      const w = Math.max(320, box.clientWidth - 4);
      for (const c of Object.values(charts)) c.plot.setSize({ width: w, height: c.plot.height });
    });
  }

  // Turn a signal's curve on (as its toggle would), if it is off.
  function showSignal(key) {
    const s = SIGNALS.find((x) => x.key === key);
    if (s.on) return;
    s.on = true;
    const b = document.querySelector(`#signal-toggles [data-signal="${key}"]`);
    if (b) b.setAttribute("aria-pressed", "true");
    const c = charts[s.group];
    if (c) c.plot.setSeries(c.sigs.indexOf(s) + 1, { show: true });
  }

  function buildToggles() {
    const box = $("signal-toggles");
    for (const s of SIGNALS) {
      const b = document.createElement("button");
      b.type = "button";
      b.dataset.signal = s.key;
      b.setAttribute("aria-pressed", s.on ? "true" : "false");
      // the curve's own colour, width and dash pattern, drawn
      b.innerHTML = `<svg class="swatch${s.est ? " dashed" : ""}" width="24" height="6" aria-hidden="true">` +
        `<line x1="0" y1="3" x2="24" y2="3" stroke="${s.color}" stroke-width="${s.width || 2}"` +
        `${s.dash ? ` stroke-dasharray="${s.dash.join(" ")}"` : ""}/></svg>`;
      b.appendChild(document.createTextNode(s.label));
      b.addEventListener("click", () => {
        s.on = !s.on;
        b.setAttribute("aria-pressed", s.on ? "true" : "false");
        const c = charts[s.group];
        c.plot.setSeries(c.sigs.indexOf(s) + 1, { show: s.on });
      });
      box.appendChild(b);
    }
  }

  function onFrame(f) {
    if (f.reset) for (const k in data) data[k].length = 0;
    const n = f.t.length;
    if (n === 0) return;
    if (data.t.length && f.t[0] < data.t[data.t.length - 1]) for (const k in data) data[k].length = 0;
    for (let i = 0; i < n; i++) data.t.push(f.t[i]);
    for (const s of SIGNALS) {
      const src = f[s.key], dst = data[s.key];
      for (let i = 0; i < n; i++) dst.push(src[i]);
    }
    const tEnd = data.t[data.t.length - 1];
    let cut = 0;
    while (cut < data.t.length && data.t[cut] < tEnd - KEEP_S) cut++;
    if (cut) for (const k in data) data[k].splice(0, cut);
    ui.frames++;
    ui.lastT = tEnd;
    ui.frameEnds.push(tEnd);
    ui.frameWall.push(performance.now());   // when each frame arrived (ms, page clock)
    if (ui.frameEnds.length > 200) { ui.frameEnds.shift(); ui.frameWall.shift(); }
    dirty = true;
  }

  function render() {
    if (dirty && data.t.length) {
      dirty = false;
      const tEnd = data.t[data.t.length - 1];
      const min = Math.max(0, tEnd - windowS), max = Math.max(tEnd, windowS);
      for (const c of Object.values(charts)) {
        c.plot.batch(() => {
          c.plot.setData([data.t, ...c.sigs.map((s) => data[s.key])], false);
          c.plot.setScale("x", { min, max });
        });
      }
      ui.renders++;
      ui.xRange = [min, max];
    }
    requestAnimationFrame(render);
  }

  // --- stream ------------------------------------------------------------------------------------
  let ws = null, retry = 500;

  function connect() {
    if (ui.ended) return;
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    ws = new WebSocket(withToken(`${proto}//${location.host}/ws`));
    ws.onopen = () => { ui.connected = true; retry = 500; $("conn").textContent = "live"; $("conn").className = "conn live"; };
    ws.onmessage = (ev) => {
      const msg = JSON.parse(ev.data);
      if (msg.type === "samples") onFrame(msg);
      else if (msg.type === "status") showStatus(msg.status);
      else if (msg.type === "exit") ended(msg.status);
    };
    ws.onclose = () => {
      ui.connected = false;
      if (ui.ended) return;
      $("conn").textContent = "reconnecting";
      $("conn").className = "conn lost";
      setTimeout(connect, retry);
      retry = Math.min(retry * 2, 5000);
    };
  }

  function ended(st) {
    ui.ended = true;
    if (st) showStatus(st);
    $("conn").textContent = "ended";
    $("conn").className = "conn lost";
    $("ended").hidden = false;
    for (const b of document.querySelectorAll("button")) b.disabled = true;
    if (ws) ws.close();
  }

  // --- buttons ------------------------------------------------------------------------------------
  async function stopRecording() {
    const r = await api("POST", "/api/record/stop");
    if (!r.ok) { setMsg("save-msg", "refused: " + r.data.detail, true); return false; }
    setMsg("save-msg", `${r.data.rows} samples recorded; name the file (no extension, .dat is added)`);
    $("save-prompt").hidden = false;
    $("save-name").focus();
    return true;
  }

  function wire() {
    $("start").addEventListener("click", async () => {
      const running = ui.status && ui.status.running;
      const r = await api("POST", running ? "/api/stop" : "/api/start");
      if (!r.ok) setMsg("feedback-msg", "refused: " + r.data.detail, true);
    });

    $("swingup").addEventListener("click", async () => {
      const r = await api("POST", "/api/swingup");
      if (!r.ok) setMsg("feedback-msg", "refused: " + r.data.detail, true);
    });

    let exitArmed = null;
    $("exit").addEventListener("click", async () => {
      if (!exitArmed) {   // two presses: a stray click must not drop the pendulum
        const st = ui.status || {};
        if (st.recording) await stopRecording();
        if (st.recording || (st.console && st.console.pending_recording)) {
          // as in the thesis, Exit asks for the recording's name first
          setMsg("save-msg", "name the recording at out> before you exit (Exit again keeps it " +
            "under its automatic name in the log directory)");
        }
        $("exit").textContent = "Confirm exit";
        exitArmed = setTimeout(() => { exitArmed = null; $("exit").textContent = "Exit"; }, 4000);
        return;
      }
      clearTimeout(exitArmed);
      const r = await api("POST", "/api/exit");
      ended(r.ok ? r.data.status : null);
    });

    $("feedback-apply").addEventListener("click", () => applyDesign("feedback"));
    $("observer-apply").addEventListener("click", () => applyDesign("observer"));
    $("fast").addEventListener("click", () => applyPreset("fast"));
    $("slow").addEventListener("click", () => applyPreset("slow"));

    $("compensation").addEventListener("click", async () => {
      const on = $("compensation").getAttribute("aria-pressed") === "true";
      const r = await change("/api/compensation", { enabled: !on });
      setMsg("friction-msg", r.ok ? (on ? "compensation off" : "compensation on") : "refused: " + r.data.detail, !r.ok);
    });
    $("friction-type").addEventListener("change", async () => {
      const on = $("compensation").getAttribute("aria-pressed") === "true";
      const kind = $("friction-type").value;
      const r = await change("/api/compensation", { kind, enabled: on });
      setMsg("friction-msg", r.ok ? `friction type ${kind}` : "refused: " + r.data.detail, !r.ok);
      $("friction-type").blur();
    });
    $("friction-apply").addEventListener("click", applyFriction);
    $("error-signal").addEventListener("change", () => { panels.friction.dirty = true; });

    $("save").addEventListener("click", async () => {
      const recording = $("save").getAttribute("aria-pressed") === "true";
      if (!recording) {
        const r = await api("POST", "/api/record/start");
        setMsg("save-msg", r.ok ? "recording; press again to stop" : "refused: " + r.data.detail, !r.ok);
        if (r.ok) { $("save-links").textContent = ""; $("save-prompt").hidden = true; }
        return;
      }
      await stopRecording();
    });
    $("save-prompt").addEventListener("submit", async (ev) => {
      ev.preventDefault();
      const input = $("save-name");
      const name = input.value.trim().replace(/\.(dat|csv)$/, "");
      if (!new RegExp(ui.schema.record.pattern).test(name)) {
        setError(input, "use 1-64 letters, digits, '_' or '-' (no extension: .dat and .csv are added)");
        return;
      }
      const r = await api("POST", "/api/record/name", { name });
      if (!r.ok) { setError(input, (r.data.errors[0] || {}).message || r.data.detail); return; }
      setError(input, "");
      $("save-prompt").hidden = true;
      input.value = "";
      setMsg("save-msg", `${r.data.rows} samples written to ${r.data.dat} and .csv`);
      const links = $("save-links");
      links.textContent = "download: ";
      for (const ext of ["dat", "csv"]) {
        const a = document.createElement("a");
        a.href = withToken(r.data.urls[ext]);
        a.download = `${r.data.name}.${ext}`;
        a.textContent = `${r.data.name}.${ext}`;
        a.id = `download-${ext}`;
        links.appendChild(a);
      }
    });
    $("save-name").addEventListener("input", () => setError($("save-name"), ""));

    $("push").addEventListener("click", async () => {
      const f = { name: "kick", lo: ui.schema.push.lo, hi: ui.schema.push.hi, lo_open: false, hi_open: false };
      const r0 = checkNumber(f, $("kick").value);
      if (r0.error || r0.value === 0) { setError($("kick"), r0.error || "kick must not be 0"); return; }
      setError($("kick"), "");
      const r = await api("POST", "/api/push", { kick: r0.value });
      if (!r.ok) { setError($("kick"), (r.data.errors[0] || {}).message || r.data.detail); setMsg("push-msg", "refused", true); }
      else setMsg("push-msg", `pushed ${r0.value} rad/s`);
    });
    $("kick").addEventListener("input", () => setError($("kick"), ""));
    $("experiment-run").addEventListener("click", runExperiment);
    $("experiment-options").addEventListener("input", () => setError($("experiment-options"), ""));

    $("confirm-apply").addEventListener("click", () => closeConfirm(true));
    $("confirm-cancel").addEventListener("click", () => closeConfirm(false));
    $("error-signal").addEventListener("input", () => { $("error-signal-error").textContent = ""; });

    $("window").addEventListener("change", () => {
      const f = { name: "window", lo: 2, hi: KEEP_S, lo_open: false, hi_open: false };
      const r = checkNumber(f, $("window").value);
      $("window-error").textContent = r.error || "";
      $("window").classList.toggle("invalid", !!r.error);
      if (!r.error) { windowS = r.value; dirty = true; }
    });
  }

  async function init() {
    const r = await api("GET", "/api/schema");
    if (!r.ok) {
      $("run-state").textContent = r.status === 401 ? "not authorised: open the address printed by frictionlab run (with ?token=...)" : "cannot reach the console";
      return;
    }
    ui.schema = r.data;
    // the plant's unit of u and of the friction levels (V for a motor plant)
    const uUnit = unitText(r.data.u_unit);
    GROUPS.find((g) => g.id === "control").unit = uUnit;
    for (const el of document.querySelectorAll(".u-unit")) el.textContent = uUnit;
    $("plant").textContent = `plant ${r.data.plant} · u in ${uUnit}`;
    buildDesignPanel("feedback", r.data.feedback);
    buildDesignPanel("observer", r.data.observer);
    const es = $("error-signal");
    for (const name of r.data.compensation.error_signals) {
      const o = document.createElement("option");
      o.value = o.textContent = name;
      es.appendChild(o);
    }
    $("kick").value = r.data.push.default;
    buildPlots();
    buildToggles();
    wire();
    const st = await api("GET", "/api/status");
    if (st.ok) showStatus(st.data, true);
    connect();
    requestAnimationFrame(render);
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", init);
  else init();
})();
