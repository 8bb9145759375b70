"""Parameter sweeps: parsing, backends (serial, pool, Dask), files, resume, CLI."""

import contextlib
import csv
import io
import itertools
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import time
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frictionlab.cli import main
from frictionlab.cli.sweep import UNDEFINED_MARKERS, markdown_table, plot_sweep
from frictionlab.config import ConfigError, build_config
from frictionlab.model.limit_cycles import FEATURES, trajectory_features
from frictionlab.runs import run_features, simulate_config
from frictionlab.studies import sweep as sweep_module
from frictionlab.studies.reference import TABLE2
from frictionlab.studies.sweep import (
    MAX_CHUNK,
    MIN_TAIL_CHUNK,
    OutputMismatch,
    SweepFile,
    columns,
    evaluate,
    get_dask,
    guided_chunks,
    make_points,
    parse_vary,
    reduce_features,
    shutdown,
)
from frictionlab.studies.sweep import engine as sweep_engine
from frictionlab.studies.sweep import work as sweep_work

BAND = "friction.zero_velocity_band=0.03"
TABLE2_FC = tuple(TABLE2)  # 1.1, 1.3, 1.5, 1.7, 1.9


@pytest.fixture(scope="module", autouse=True)
def _close_backends():
    yield
    shutdown()


def run_cli(*args):
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        rc = main(["sweep", *args])
    return rc, out.getvalue(), err.getvalue()


def summary_counts(err):
    """(computed, resumed) from the one-line summary the sweep writes on stderr."""
    m = re.search(r"\((\d+) computed, (\d+) resumed\)", err)
    assert m is not None, err
    return int(m.group(1)), int(m.group(2))


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ---------------------------------------------------------------------------
# parsing and points
# ---------------------------------------------------------------------------


def test_parse_value_list_and_range():
    assert parse_vary("friction.coulomb=1.1,1.3, 1.5") == ("friction.coulomb", [1.1, 1.3, 1.5])
    key, values = parse_vary("friction.coulomb=1.1:1.9:5")
    assert key == "friction.coulomb"
    assert values == list(TABLE2_FC)  # exactly, not 1.7000000000000002
    assert parse_vary("plant.omega0=7.5:9:1") == ("plant.omega0", [7.5])
    assert parse_vary("design.omega1=8:6:3")[1] == [8.0, 7.0, 6.0]


@settings(max_examples=60, deadline=None)
@given(start=st.floats(-1e3, 1e3), span=st.floats(0.01, 1e3), n=st.integers(2, 200))
def test_range_has_n_ordered_values_with_both_ends(start, span, n):
    stop = start + span
    _, values = parse_vary(f"friction.coulomb={start!r}:{stop!r}:{n}")
    assert len(values) == n
    assert values[0] == pytest.approx(start, rel=1e-11, abs=1e-9)
    assert values[-1] == pytest.approx(stop, rel=1e-11, abs=1e-9)
    assert all(a < b for a, b in itertools.pairwise(values))


@pytest.mark.parametrize("text,fragment", [
    ("friction.nope=1,2", "unknown key 'friction.nope'"),
    ("friction.coulomb=", "empty list"),
    ("friction.coulomb=1,,2", "empty value"),
    ("friction.coulomb=1:2:0", "must be >= 1"),
    ("friction.coulomb=1:2:2.5", "must be an integer"),
    ("friction.coulomb=1:2", "START:STOP:N"),
    ("friction.coulomb=1,abc", "'abc' is not a number"),
    ("friction.coulomb=1,nan", "not a finite number"),
    ("friction.coulomb=1,1.0", "appears twice"),
    ("friction.coulomb", "KEY=V1,V2"),
])
def test_parse_rejects(text, fragment):
    with pytest.raises(ConfigError, match=fragment):
        parse_vary(text)


def test_grid_is_the_cartesian_product_and_oat_varies_one_key_at_a_time():
    base = build_config("fast", "classical")
    varies = [("friction.coulomb", [1.1, 1.5]), ("friction.stiction", [2.1, 2.3, 2.5])]
    grid = make_points(base, varies, "grid")
    assert grid == [{"friction.coulomb": c, "friction.stiction": s}
                    for c in (1.1, 1.5) for s in (2.1, 2.3, 2.5)]
    oat = make_points(base, varies, "oat")
    fc0, fs0 = base.get("friction.coulomb"), base.get("friction.stiction")
    assert fc0 == 1.5 and fs0 == 2.3  # the thesis's base point of Tables 2-3
    # (1.5, 2.3) occurs for both keys and is run once
    assert oat == [{"friction.coulomb": 1.1, "friction.stiction": fs0},
                   {"friction.coulomb": 1.5, "friction.stiction": fs0},
                   {"friction.coulomb": fc0, "friction.stiction": 2.1},
                   {"friction.coulomb": fc0, "friction.stiction": 2.5}]
    # integer keys keep integer values
    assert make_points(base, [("sim.seed", [1.0, 2.0])]) == [{"sim.seed": 1}, {"sim.seed": 2}]
    assert all(isinstance(p["sim.seed"], int) for p in make_points(base, [("sim.seed", [3.0])]))


# ---------------------------------------------------------------------------
# engine
# ---------------------------------------------------------------------------


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 5000), workers=st.integers(1, 64))
def test_default_chunks_cover_every_point_once_and_shrink_at_the_end(n, workers):
    chunks = guided_chunks(n, workers)
    assert [i for c in chunks for i in c] == list(range(n))  # in order, each once
    sizes = [len(c) for c in chunks]
    # at most 50 points and at most a quarter of a worker's share per chunk
    assert min(sizes) >= 1 and max(sizes) <= min(MAX_CHUNK, math.ceil(n / (4 * workers)))
    assert sizes == sorted(sizes, reverse=True)
    # the last chunk is small whenever the sweep is long enough to allow it
    if n >= 4 * workers * MIN_TAIL_CHUNK:
        assert sizes[-1] <= MIN_TAIL_CHUNK


def test_serial_rows_are_run_features_and_failures_are_rows():
    base = build_config("fast", "classical", sets=[BAND])
    points = [{"friction.coulomb": 1.3}, {"friction.coulomb": -1.0}, {"plant.omega0": 20.0}]
    calls = []
    rows = evaluate(base, points, duration=10, workers=1,
                    progress=lambda d, n: calls.append((d, n)))
    # the point's keys, then the features, then status and error (the CSV's order)
    assert [list(r) for r in rows] == [[*p, *FEATURES, "status", "error"] for p in points]
    direct = run_features(base.with_values(points[0]), 10)
    assert rows[0]["status"] == direct.status == "limit_cycle"
    assert rows[0]["error"] is None
    for name in FEATURES:
        assert rows[0][name] == getattr(direct, name)
    # an invalid point is an error row naming the problem, not an exception
    assert rows[1]["status"] == "error"
    assert "friction.coulomb" in rows[1]["error"]
    assert all(rows[1][f] is None for f in FEATURES)
    # omega0 = 20 rad/s cannot be stabilised by the fast design: the pendulum falls
    assert rows[2]["status"] == "fell"
    assert rows[2]["period"] is None and rows[2]["error"] is None
    assert calls[-1] == (3, 3)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_pool_and_dask_localcluster_give_identical_rows_for_table2(tmp_path):
    """Acceptance: Table 2's F_C values, threads vs Dask LocalCluster vs in-process,
    and the compiled batch vs one Python-driven run per point in a process pool."""
    base = build_config("fast", "classical", sets=[BAND])
    points = [{"friction.coulomb": v} for v in TABLE2_FC]
    serial = evaluate(base, points, duration=10, workers=1)
    pool = evaluate(base, points, duration=10, workers=2)
    # a new cluster while another process holds Dask's default HTTP port 8787: the
    # scheduler's HTTP server takes a free port of its own, without a warning
    shutdown()
    with socket.socket() as held, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with contextlib.suppress(OSError):  # already held by someone else: as good
            held.bind(("0.0.0.0", 8787))
            held.listen()
        dask = evaluate(base, points, duration=10, dask="local", workers=2)
    assert not [w for w in caught if "8787" in str(w.message)], [str(w.message) for w in caught]
    per_run = evaluate(base, points, duration=10, workers=2, reduce=reduce_features)
    assert pool == serial
    assert dask == pool
    assert per_run == pool
    # the cluster's workers run without Dask's malloc trim threshold (see _local_dask_config)
    client = get_dask("local", 2)
    trim = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert len(trim) == 2 and set(trim.values()) == {None}
    # joining a running scheduler by address (here the LocalCluster's own)
    address = client.scheduler.address
    assert address.startswith("tcp://")
    assert evaluate(base, points[:2], duration=10, dask=address) == pool[:2]
    assert [r["friction.coulomb"] for r in pool] == list(TABLE2_FC)
    assert all(r["status"] == "limit_cycle" for r in pool)
    # larger F_C, larger limit cycle (Table 2's trend)
    peaks = [r["peak1"] for r in pool]
    assert peaks == sorted(peaks)
    # the same through the command line: byte-identical CSV files
    common = ["--design", "fast", "--friction", "classical", "--set", BAND, "--duration", "10",
              "--vary", "friction.coulomb=1.1,1.3,1.5,1.7,1.9", "--no-progress", "--json"]
    a, b = tmp_path / "pool.csv", tmp_path / "dask.csv"
    rc, out, _ = run_cli(*common, "--workers", "2", "--out", str(a))
    assert rc == 0 and json.loads(out)["rows"] == 5
    rc, out, _ = run_cli(*common, "--dask", "local", "--workers", "2", "--out", str(b))
    assert rc == 0 and json.loads(out)["rows"] == 5
    assert a.read_bytes() == b.read_bytes()
    assert [float(r["peak1"]) for r in read_csv(a)] == peaks


def test_worker_failures_are_rows_in_the_pool():
    base = build_config("fast", "classical")
    points = [{"friction.coulomb": 1.3}, {"friction.coulomb": 1e9}, {"friction.coulomb": 1.5}]
    rows = evaluate(base, points, duration=3, workers=2, chunk_size=1)
    assert rows[0]["error"] is None and rows[2]["error"] is None
    assert rows[1]["status"] == "error" and "out of range" in rows[1]["error"]
    assert rows[0] == evaluate(base, points[:1], duration=3, workers=1)[0]


def _reduce_with_final_arm_angle(cfg, duration, window):
    """A reduction with an extra column (top level here: the pool gets it by reference)."""
    traj = simulate_config(cfg, duration)
    feats = trajectory_features(traj, window)
    return {**feats.interface_dict(), "status": feats.status,
            "final_arm_angle": float(traj["arm"][-1])}


def _reduce_that_fails_above_1_6(cfg, duration, window):
    if cfg.get("friction.coulomb") > 1.6:
        raise RuntimeError("no reduction above F_C 1.6")
    return reduce_features(cfg, duration, window)


def _reduce_without_status(cfg, duration, window):
    return dict.fromkeys(FEATURES, 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_reduce_hook_replaces_the_feature_reduction(workers):
    """A caller's reduce runs for every point (in-process and in the pool): its
    features and status make the row, its extra columns follow error."""
    base = build_config("fast", "classical", sets=[BAND])
    points = [{"friction.coulomb": v} for v in (1.3, 1.5, 1.7)]
    rows = evaluate(base, points, duration=5, window=3, workers=workers, chunk_size=1,
                    reduce=_reduce_with_final_arm_angle)
    plain = evaluate(base, points, duration=5, window=3, workers=1)
    for p, row, ref in zip(points, rows, plain, strict=True):
        assert list(row) == [*p, *FEATURES, "status", "error", "final_arm_angle"]
        assert {k: row[k] for k in ref} == ref  # the default reduction's row, exactly
        traj = simulate_config(base.with_values(p), 5)
        assert row["final_arm_angle"] == float(traj["arm"][-1])
    # the default reduction is reduce_features
    assert evaluate(base, points[:1], duration=5, window=3, workers=workers,
                    reduce=reduce_features) == plain[:1]


# workers=2 starts the process pool (new interpreters): slow
@pytest.mark.parametrize("workers", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_a_reduce_that_raises_gives_an_error_row(workers):
    base = build_config("fast", "classical")
    points = [{"friction.coulomb": v} for v in (1.3, 1.7)]
    rows = evaluate(base, points, duration=3, workers=workers, chunk_size=1,
                    reduce=_reduce_that_fails_above_1_6)
    assert rows[0] == evaluate(base, points[:1], duration=3, workers=1)[0]
    assert rows[1]["status"] == "error"
    assert rows[1]["error"] == "RuntimeError: no reduction above F_C 1.6"
    assert all(rows[1][f] is None for f in FEATURES)
    # a result without a status is an error row too, naming what is missing
    (row,) = evaluate(base, points[:1], duration=3, workers=workers,
                      reduce=_reduce_without_status)
    assert row["status"] == "error" and "status" in row["error"]


def test_a_reduce_the_workers_cannot_receive_is_refused_before_any_run(monkeypatch):
    ran = []
    monkeypatch.setattr(sweep_engine, "run_chunk", lambda *a: ran.append(a))
    base = build_config("fast", "classical")
    for bad in (lambda cfg, d, w: {}, "reduce_features"):
        with pytest.raises(TypeError, match="reduce must be"):
            evaluate(base, [{"friction.coulomb": 1.3}], duration=3, workers=1, reduce=bad)
    assert not ran


#: The engine's own chunk function (also in a worker process that imports this module).
_RUN_CHUNK = sweep_work.run_chunk


def _chunk_that_kills_its_worker(base, points, duration, window, reduce):
    """A chunk function whose worker process dies on the point F_C = 1.7.

    Workers receive it by reference (this module's name), so it must live at
    module level here.
    """
    if any(p.get("friction.coulomb") == 1.7 for p in points):
        os._exit(3)
    return _RUN_CHUNK(base, points, duration, window, reduce)


@pytest.mark.slow  # a process pool, one of whose workers dies
def test_a_worker_process_that_dies_gives_error_rows_not_a_crash(monkeypatch):
    base = build_config("fast", "classical")
    points = [{"friction.coulomb": v} for v in (1.3, 1.5, 1.7, 1.9)]
    monkeypatch.setattr(sweep_engine, "run_chunk", _chunk_that_kills_its_worker)
    # a custom reduce runs in the process pool (the default reduction runs on threads)
    rows = evaluate(base, points, duration=3, workers=2, chunk_size=1, reduce=reduce_features)
    monkeypatch.undo()
    assert [r["friction.coulomb"] for r in rows] == [1.3, 1.5, 1.7, 1.9]
    dead = rows[2]
    assert dead["status"] == "error" and dead["error"].startswith("worker failed: ")
    assert "BrokenProcessPool" in dead["error"]
    assert all(dead[f] is None for f in FEATURES)
    # the other chunks either finished before the death or share its fate
    for r in rows:
        assert (r["status"], r["error"] is None) in {("limit_cycle", True), ("error", False)}
    # the broken pool was dropped: the next sweep gets a fresh one
    again = evaluate(base, points, duration=3, workers=2, chunk_size=1, reduce=reduce_features)
    assert [r["status"] for r in again] == ["limit_cycle"] * 4


# ---------------------------------------------------------------------------
# files and resume
# ---------------------------------------------------------------------------

KILL_SWEEP = ["--vary", "friction.coulomb=1.0:2.0:40", "--set", "sim.substeps=300",
              "--duration", "20", "--workers", "2", "--chunk-size", "2", "--no-progress"]


def _data_lines(path):
    return max(0, Path(path).read_text().count("\n") - 1) if Path(path).exists() else 0


@pytest.mark.slow
@pytest.mark.timeout(400)
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["term", "kill"])
def test_killed_sweep_resumes_with_every_point_exactly_once(tmp_path, sig):
    """Acceptance: terminate a sweep part-way, resume it, every point once."""
    out = tmp_path / "killed.csv"
    cmd = [sys.executable, "-m", "frictionlab", "sweep", *KILL_SWEEP, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while _data_lines(out) < 4 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0, "the sweep finished before it could be interrupted"
    if sig == signal.SIGTERM:  # a clean stop says how to continue
        assert "--resume" in err
    meta = json.loads(Path(f"{out}.meta.json").read_text())
    partial = SweepFile(str(out), ["friction.coulomb"], meta).load()  # drops a cut line
    assert 4 <= len(partial) < 40
    done_before = {r["friction.coulomb"] for r in partial}
    assert len(done_before) == len(partial)

    rc = subprocess.run([*cmd, "--json"], capture_output=True, text=True, timeout=300)
    assert rc.returncode == 2 and "exists" in rc.stderr  # no silent overwrite

    res = subprocess.run([*cmd, "--resume", "--json"], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert set(summary) == {"rows", "out", "seconds"}
    assert summary["rows"] == 40 and summary["out"] == str(out)
    assert summary_counts(res.stderr) == (40 - len(done_before), len(done_before))
    rows = read_csv(out)
    values = [float(r["friction.coulomb"]) for r in rows]
    assert len(values) == len(set(values)) == 40
    assert values == parse_vary("friction.coulomb=1.0:2.0:40")[1]  # sweep order
    assert all(r["status"] == "limit_cycle" for r in rows)
    # a row written before the kill holds the same result as a fresh run
    v = min(done_before)
    base = build_config("fast", "classical", sets=["sim.substeps=300"])
    fresh = run_features(base.with_values({"friction.coulomb": v}), 20)
    row = next(r for r in rows if float(r["friction.coulomb"]) == v)
    assert float(row["peak1"]) == fresh.peak1


def test_resume_skips_done_points_reruns_errors_and_drops_a_cut_line(tmp_path):
    path = str(tmp_path / "s.csv")
    keys = ["friction.coulomb"]
    f = SweepFile(path, keys, {"keys": keys, "duration": 5.0, "window": None, "base": {}})
    f.open()
    ok = {"friction.coulomb": 1.3, "status": "limit_cycle", "peak1": 0.1, "error": None}
    bad = {"friction.coulomb": 1.5, "status": "error", "error": "worker failed: x, y"}
    f.append([ok, bad])
    f.close()
    with open(path, "a") as fh:
        fh.write("1.7,limit_cyc")  # a row cut short by a kill
    rows = SweepFile(path, keys, f.meta).load()
    assert [r["friction.coulomb"] for r in rows] == [1.3, 1.5]
    assert rows[0]["peak1"] == 0.1 and rows[0]["peak2"] is None
    assert rows[1]["error"] == "worker failed: x, y"  # commas survive the CSV round trip
    assert Path(path).read_text().endswith("\n")

    # via the CLI: 1.3 is kept as is, 1.5 (error) and 1.7 (cut) are computed
    rc, out, _ = run_cli("--vary", "friction.coulomb=1.3,1.5,1.7", "--duration", "5",
                         "--out", path, "--resume", "--json", "--no-progress")
    assert rc == 2  # the sidecar says base = {} which is not this sweep's base
    os.remove(path + ".meta.json")
    rc, out, err = run_cli("--vary", "friction.coulomb=1.3,1.5,1.7", "--duration", "5",
                           "--out", path, "--resume", "--json", "--no-progress")
    assert rc == 0
    assert json.loads(out)["rows"] == 3
    assert summary_counts(err) == (2, 1)
    final = read_csv(path)
    assert [r["friction.coulomb"] for r in final] == ["1.3", "1.5", "1.7"]
    assert final[0]["peak1"] == "0.1"
    assert final[1]["status"] == "limit_cycle" and final[1]["error"] == ""


def test_resume_refuses_a_different_setup(tmp_path):
    path = str(tmp_path / "r.csv")
    args = ["--vary", "friction.coulomb=1.3,1.5", "--duration", "4", "--out", path,
            "--no-progress", "--json"]
    assert run_cli(*args)[0] == 0
    rc, _, err = run_cli(*args, "--resume", "--set", "plant.omega0=7.5")
    assert rc == 2 and "plant.omega0" in err and len(err.strip().splitlines()) == 1
    assert "--resume" in err and "--force" in err  # the command line names its options
    meta = json.loads(Path(f"{path}.meta.json").read_text())
    with pytest.raises(OutputMismatch) as info:  # the library names what differs
        SweepFile(path, meta["keys"], {**meta, "duration": 5.0}).load()
    assert info.value.field == "duration" and "--" not in str(info.value)
    rc, _, err = run_cli(*args[:3], "5", *args[4:], "--resume")
    assert rc == 2 and "duration" in err
    # the same set-up resumes with nothing to compute; more values extend it
    rc, out, err = run_cli(*args, "--resume")
    assert rc == 0 and summary_counts(err) == (0, 2)
    rc, out, err = run_cli("--vary", "friction.coulomb=1.3,1.5,1.7", *args[2:], "--resume")
    assert rc == 0 and json.loads(out)["rows"] == 3 and summary_counts(err) == (1, 2)
    rc, out, _ = run_cli(*args, "--force")
    assert rc == 0 and json.loads(out)["rows"] == 2 and len(read_csv(path)) == 2


@pytest.mark.slow
def test_resume_refuses_a_file_with_the_earlier_column_order(tmp_path):
    """Files of an earlier frictionlab (status between the keys and the
    features) are not resumed into: exit 2, one line, the file untouched."""
    import pyarrow.parquet as pq

    keys = ["friction.coulomb"]
    old_cols = [*keys, "status", *FEATURES, "error"]
    args = ["--vary", "friction.coulomb=1.3,1.5", "--duration", "4", "--no-progress", "--json"]
    for name in ("old.csv", "old.parquet"):
        path = tmp_path / name
        assert run_cli(*args, "--out", str(path))[0] == 0
        if name.endswith(".csv"):
            rows = read_csv(path)
            with open(path, "w", newline="") as fh:
                w = csv.DictWriter(fh, old_cols, lineterminator="\n")
                w.writeheader()
                w.writerows(rows)
        else:
            pq.write_table(pq.read_table(path).select(old_cols), path)
        before = path.read_bytes()
        rc, out, err = run_cli(*args, "--out", str(path), "--resume")
        assert rc == 2 and out == ""
        assert len(err.strip().splitlines()) == 1
        assert "earlier frictionlab" in err and "--force" in err
        assert path.read_bytes() == before
        # --force starts afresh in the current order
        assert run_cli(*args, "--out", str(path), "--force")[0] == 0


def test_parquet_output_matches_csv(tmp_path):
    import pyarrow.parquet as pq

    args = ["--vary", "friction.coulomb=1.1,1.5", "--vary", "sim.seed=0,1", "--duration", "4",
            "--set", "sim.noise=0.001", "--no-progress", "--json"]
    c, p = str(tmp_path / "a.csv"), str(tmp_path / "a.parquet")
    assert run_cli(*args, "--out", c)[0] == 0
    assert run_cli(*args, "--out", p)[0] == 0
    assert not os.path.exists(p + ".partial.csv")
    table = pq.read_table(p)
    assert table.column_names == columns(["friction.coulomb", "sim.seed"])
    assert str(table.schema.field("sim.seed").type) == "int64"
    with open(c + ".meta.json") as fh:
        meta = json.load(fh)
    from_csv = SweepFile(c, ["friction.coulomb", "sim.seed"], meta).load()
    assert table.to_pylist() == from_csv
    # noise seeds differ, so the rows do
    assert from_csv[0]["peak1"] != from_csv[1]["peak1"]


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("args,fragment", [
    (["--vary", "friction.nope=1,2"], "unknown key"),
    (["--vary", "friction.coulomb="], "empty list"),
    (["--vary", "friction.coulomb=1:2:0"], ">= 1"),
    (["--vary", "friction.coulomb=1,x"], "not a number"),
    (["--vary", "friction.coulomb=-1,1.5"], "out of range"),
    (["--vary", "plant.omega0=5,6", "--vary", "plant.omega0=7"], "more than once"),
    ([], "--vary"),
    (["--vary", "friction.coulomb=1", "--dask", "udp://x:1"], "--dask"),
    (["--vary", "friction.coulomb=1", "--workers", "0"], "--workers"),
    (["--vary", "friction.coulomb=1", "--duration", "-3"], "--duration"),
    (["--vary", "friction.coulomb=1", "--plot", "x.txt"], "--plot"),
])
def test_bad_sweeps_exit_2_before_any_work(tmp_path, args, fragment):
    out = tmp_path / "never.csv"
    rc, stdout, err = run_cli(*args, "--out", str(out), "--json")
    assert rc == 2
    assert stdout == ""
    assert fragment in err and len(err.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_bad_output_extension_exits_2(tmp_path):
    rc, _, err = run_cli("--vary", "friction.coulomb=1", "--out", str(tmp_path / "x.txt"))
    assert rc == 2 and ".csv or .parquet" in err


def test_json_is_one_object_and_csv_has_documented_columns(tmp_path):
    path = str(tmp_path / "j.csv")
    rc, out, err = run_cli("--vary", "friction.coulomb=1.3,1.5", "--vary", "plant.omega0=7,20",
                           "--duration", "5", "--out", path, "--json", "--table")
    assert rc == 0
    lines = out.strip().splitlines()
    assert len(lines) == 1
    summary = json.loads(lines[0])
    assert set(summary) == {"rows", "out", "seconds"}  # exactly the interface's fields
    assert summary["rows"] == 4 and summary["out"] == path and summary["seconds"] >= 0
    assert "fell: 2" in err  # omega0 = 20 falls
    assert "| friction.coulomb | plant.omega0 |" in err  # --table goes to stderr with --json
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    # docs/cli.md: the varied keys, then the feature columns (then status, error)
    assert header == ["friction.coulomb", "plant.omega0", *FEATURES, "status", "error"]
    assert header == columns(["friction.coulomb", "plant.omega0"])
    rows = read_csv(path)
    assert [(r["friction.coulomb"], r["plant.omega0"]) for r in rows] == [
        ("1.3", "7.0"), ("1.3", "20.0"), ("1.5", "7.0"), ("1.5", "20.0")]
    assert [r["status"] for r in rows][1::2] == ["fell", "fell"]


def test_table_has_the_shape_of_table2(tmp_path):
    path = str(tmp_path / "t.csv")
    rc, out, _ = run_cli("--set", BAND, "--vary", "friction.coulomb=1.1,1.5,1.9",
                         "--vary", "friction.stiction=2.1,2.3", "--mode", "oat",
                         "--duration", "10", "--out", path, "--table", "--no-progress")
    assert rc == 0
    blocks = out.strip().split("\n\n")
    assert len(blocks) == 2  # one table per varied key, like Tables 2 and 3
    rows = read_csv(path)
    fc_table = blocks[0].splitlines()
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in fc_table]
    assert cells[0] == ["friction.coulomb", "peak1", "peak2", "valley", "T", "max(u)",
                        "max(Ω̇)"]
    assert set(cells[1]) == {"---"}
    assert [c[0] for c in cells[2:]] == ["1.1", "1.5", "1.9"]
    for c, r in zip(cells[2:], rows[:3], strict=True):
        assert len(c) == 7
        assert float(c[1]) == pytest.approx(float(r["peak1"]), rel=5e-3)
        assert float(c[4]) == pytest.approx(float(r["period"]), rel=5e-3)
    fs_cells = [line.split("|")[1].strip() for line in blocks[1].splitlines()[2:]]
    assert fs_cells == ["2.1", "2.3"]  # the base point (F_C 1.5, F_S 2.3) is in both
    assert len(rows) == 4


def test_table_marks_rows_that_are_not_limit_cycles():
    rows = [{"plant.omega0": 6.8, "status": "limit_cycle", **dict.fromkeys(FEATURES, 0.1)},
            {"plant.omega0": 20.0, "status": "fell", **dict.fromkeys(FEATURES)}]
    lines = markdown_table(rows, [("plant.omega0", [6.8, 20.0])]).splitlines()
    assert lines[0].endswith("| status |")
    assert lines[3].split("|")[2].strip() == "-" and lines[3].rstrip("| ").endswith("fell")



def test_a_swing_up_sweeps_table_shows_whether_and_when_it_caught():
    rows = [{"plant.omega0": 6.8, "status": "limit_cycle", "caught": 1, "swing_up_time": 2.345,
             **dict.fromkeys(FEATURES, 0.1)},
            {"plant.omega0": 6.2, "status": "not_caught", "caught": 0, "swing_up_time": None,
             **dict.fromkeys(FEATURES)}]
    lines = markdown_table(rows, [("plant.omega0", [6.8, 6.2])]).splitlines()
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    assert head[-3:] == ["caught", "swing_up_time", "status"]
    first = [c.strip() for c in lines[2].strip("|").split("|")]
    second = [c.strip() for c in lines[3].strip("|").split("|")]
    assert first[-3:] == ["yes", "2.35", "limit_cycle"]
    assert second[-3:] == ["no", "-", "not_caught"]
    # a sweep without --swing-up has no such columns
    plain = markdown_table([{k: v for k, v in r.items() if k not in ("caught", "swing_up_time")}
                            for r in rows[:1]], [("plant.omega0", [6.8])])
    assert "caught" not in plain

@pytest.mark.slow
def test_plot_leaves_undefined_features_out_and_marks_falls_on_the_edge(tmp_path, monkeypatch):
    """A fallen run is no point of the line (which breaks there) but a marker
    on the panel's bottom edge, outside the data: the y range is that of the
    defined values, not pulled to 0."""
    import matplotlib.figure

    figures = []
    save = matplotlib.figure.Figure.savefig

    def keep(fig, *a, **k):
        figures.append(fig)
        return save(fig, *a, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)

    def row(w, status, value):
        feats = dict.fromkeys(FEATURES, value)
        if status == "fell":  # a fall still has maxima, which are not a cycle's
            feats.update(max_u=45.0, max_arm_velocity=30.0, peak_to_peak=2.0)
        return {"plant.omega0": w, **feats, "status": status, "error": None}

    rows = [row(6.8, "limit_cycle", 0.10), row(7.0, "limit_cycle", 0.12),
            row(12.0, "fell", None), row(14.0, "limit_cycle", 0.11)]
    png = tmp_path / "p.png"
    plot_sweep(rows, [("plant.omega0", [6.8, 7.0, 12.0, 14.0])], str(png))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (fig,) = figures
    axes = fig.axes
    assert len(axes) == len(FEATURES)
    for ax, feat in zip(axes, FEATURES, strict=True):
        line, edge = ax.get_lines()
        y = line.get_ydata()
        assert math.isnan(y[2]) and not any(math.isnan(v) for v in y[[0, 1, 3]])
        # the fall: its own marker at the fall's x, on the bottom edge (axes y = 0)
        assert edge.get_marker() == UNDEFINED_MARKERS["fell"]
        assert list(edge.get_xdata()) == [12.0] and list(edge.get_ydata()) == [0.0]
        assert edge.get_transform() == ax.get_xaxis_transform()
        lo, hi = ax.get_ylim()
        assert 0.05 < lo < 0.10 and 0.12 < hi < 0.2, (feat, lo, hi)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any(t.startswith("fell") for t in legend)


@pytest.mark.slow
def test_plot_file(tmp_path):
    png = tmp_path / "s.png"
    rc, out, _ = run_cli("--vary", "friction.coulomb=1.1,1.5", "--vary", "plant.omega0=6.8,7.5",
                         "--duration", "5", "--out", str(tmp_path / "p.csv"),
                         "--plot", str(png), "--json", "--no-progress")
    assert rc == 0 and json.loads(out)["rows"] == 4
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


#: What the engine must not import: the command line, plotting, terminal output.
EDGE_MODULES = ("frictionlab.cli", "frictionlab.cli.sweep", "matplotlib", "rich")


@pytest.mark.slow
def test_engine_imports_no_cli_plotting_or_terminal_code():
    """frictionlab.studies.sweep is numerics and files: no import of the CLI, matplotlib or
    rich anywhere in its source (also inside functions), and none at run time."""
    import ast

    imported = set()
    for path in Path(sweep_module.__file__).parent.glob("*.py"):  # the package's modules
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                imported.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = ".".join(filter(None, ["frictionlab" if node.level else "",
                                              node.module]))
                imported.add(base)
                imported.update(f"{base}.{a.name}" for a in node.names)
    bad = {m for m in imported for edge in EDGE_MODULES
           if m == edge or m.startswith(edge + ".")}
    assert not bad, bad
    code = ("import sys, frictionlab.studies.sweep as s\n"
            "from frictionlab.config import build_config\n"
            "s.evaluate(build_config(), [{'friction.coulomb': 1.3}], duration=2, workers=1)\n"
            f"print([m for m in {EDGE_MODULES!r} if m in sys.modules])")
    probe = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           timeout=120)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.strip() == "[]"


def test_thread_backend_runs_chunks_on_every_thread_while_the_caller_takes_the_rows(
        monkeypatch):
    """The thread backend's threads run their chunks at the same time (each takes the
    next chunk when done, no thread waits for another), and go on while the caller
    holds a chunk's rows; every point's row comes once, equal to a single batch's."""
    import threading

    from frictionlab.studies import batch

    real_run = batch.run
    both = threading.Barrier(2, timeout=60)  # a failing run (one at a time) breaks it
    started = []

    def logged_run(b):
        started.append(b.points[0]["friction.coulomb"])
        if len(started) <= 2:
            both.wait()  # the first two chunks run at once, one on each thread
        return real_run(b)

    monkeypatch.setattr(batch, "run", logged_run)
    base = build_config("fast", "classical")
    values = (1.2, 1.4, 1.6, 1.8)
    pts = [{"friction.coulomb": c} for c in values]
    got = {}
    gen = sweep_module.iter_evaluate(base, pts, duration=0.5, workers=2, chunk_size=1)
    idx, rows = next(gen)
    # the caller has not taken the other chunks' rows: the threads run them meanwhile
    for _ in range(6000):
        if len(started) == len(values):
            break
        threading.Event().wait(0.01)
    assert sorted(started) == sorted(values)
    got.update(zip(idx, rows, strict=True))
    for idx, rows in gen:
        assert len(idx) == len(rows) == 1
        got.update(zip(idx, rows, strict=True))
    monkeypatch.setattr(batch, "run", real_run)
    assert sorted(got) == [0, 1, 2, 3]
    assert [got[i] for i in range(4)] == batch.evaluate_rows(base, pts, 0.5, None)


def test_closing_a_thread_sweep_early_cancels_the_chunks_not_started(monkeypatch):
    """Closing the generator after the first chunk: the chunks not started never run
    (the running ones finish first, so closing returns only when no thread computes)."""
    import threading

    from frictionlab.studies import batch

    real_run = batch.run
    started, release = [], threading.Event()

    def held_run(b):
        started.append(b.points[0]["friction.coulomb"])
        if len(started) > 2:
            release.wait(60)  # the threads' second chunks wait until the caller closes
        return real_run(b)

    monkeypatch.setattr(batch, "run", held_run)
    base = build_config("fast", "classical")
    pts = [{"friction.coulomb": 1.0 + 0.1 * k} for k in range(8)]
    gen = sweep_module.iter_evaluate(base, pts, duration=0.5, workers=2, chunk_size=1)
    next(gen)
    timer = threading.Timer(0.5, release.set)
    timer.start()
    gen.close()
    timer.join()
    n = len(started)
    threading.Event().wait(0.2)
    assert len(started) == n <= 4  # 2 threads: at most 2 chunks each, the rest cancelled
