"""Bad input on the command line: exit status 2 with one line on stderr, bounded
memory and time, never a traceback.

Hypothesis builds command lines for every subcommand from the parser itself
(every option, with valid, boundary and hostile values, and generated TOML,
JSON and log files) and runs them in-process through :func:`frictionlab.cli.main`.
The functions that would start a subcommand's real work (a simulation, a
sweep, a fit, the real-time loop, the rig emulator) are replaced by a stub
that raises :class:`Reached`: whatever gets past the checks is valid input,
so each example ends in one of

* exit status 0 (``--help``, ``keys``, ``design``...), with one JSON object on
  stdout when ``--json`` was given;
* exit status 2 with exactly one line on stderr;
* :class:`Reached`: the input passed every check.

Anything else (an exception, another status, a second line) fails, as does an
example that allocates more than :data:`MEMORY_LIMIT` (traced by
:mod:`tracemalloc`) or runs for more than :data:`HANG_S` (a hang, not a
timing).  ``FRICTIONLAB_FUZZ_EXAMPLES=2000`` runs a longer, randomised search;
by default the examples are derandomised so the suite is repeatable.

A few cases from the bug reports also run through the installed entry point
in a subprocess, with its address space limited.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frictionlab import cli
from frictionlab.config import _SECTIONS, valid_keys

EXAMPLES = int(os.environ.get("FRICTIONLAB_FUZZ_EXAMPLES", "25"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=EXAMPLES <= 100,
                database=None, suppress_health_check=list(HealthCheck))
EXAMPLE = str(Path(__file__).resolve().parents[1] / "examples" / "table1.json")
MEMORY_LIMIT = 96 << 20  # bytes traced per example
HANG_S = 60.0


class Reached(BaseException):
    """The input passed every check and the subcommand's work would start."""


class Hang(BaseException):
    """An example ran for more than HANG_S."""


def _reach(*args, **kwargs):
    raise Reached


def _fake_controller(cfg, backend="sim", *args, **kwargs):
    """``frictionlab run``: the backend's syntax is checked where the controller
    checks it, then the loop would start."""
    from frictionlab.realtime.api import check_backend

    if isinstance(backend, str) and backend != "sim":
        check_backend(backend)
    raise Reached


#: Each subcommand and the functions that start its work: (module, name, stub).
WORK = {
    ("design",): (),
    ("keys",): (),
    ("simulate",): (("frictionlab.runs", "simulate_config", _reach),),
    ("sweep",): (("frictionlab.studies.sweep", "iter_evaluate", _reach),
                 ("frictionlab.studies.sweep", "get_dask", _reach)),
    ("identify", "limit-cycle"): (
        ("frictionlab.studies.identification.limit_cycle", "fit_limit_cycle", _reach),),
    # the simulated rig is stubbed; a --log is analysed for real
    ("identify", "experiment"): (
        ("frictionlab.studies.identification.simulated", "run_simulated", _reach),),
    ("compensate", "compare"): (("frictionlab.studies.compensation", "compare", _reach),),
    ("compensate", "tune"): (("frictionlab.studies.compensation", "tune", _reach),),
    ("run",): (("frictionlab.realtime", "RealtimeController", _fake_controller),),
    ("rig-sim",): (("frictionlab.realtime.rigsim", "run_rig_sim", _reach),),
    ("reproduce",): (("frictionlab.studies.reproduce", "run", _reach),
                     ("frictionlab.studies.sweep", "get_dask", _reach)),
    ("predict",): (("frictionlab.studies.predict", "predict", _reach),),
    # the log's features are computed for real (a generated log is small)
    ("features",): (),
}


def _subcommands(parser: argparse.ArgumentParser, path=()) -> dict:
    """Every leaf subcommand's parser, by path (``("identify", "experiment")``)."""
    out = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out.update(_subcommands(sub, (*path, name)))
    return out or {path: parser}


PARSERS = _subcommands(cli.build_parser())


def test_every_subcommand_is_fuzzed():
    """A new subcommand needs its entry in WORK: the functions that start its work."""
    assert set(PARSERS) == set(WORK), (
        f"add {sorted(set(PARSERS) - set(WORK))} to WORK in {__file__}")


@pytest.fixture(scope="module")
def stubbed():
    """Replace every work function, and every module-level alias of it.  The
    libraries the checks may load are imported first, so that an example's traced
    memory is its own, not a first import's."""
    for name in ("scipy.signal", "scipy.optimize", "scipy.ndimage", "scipy.linalg",
                 "matplotlib.pyplot", "frictionlab.studies.identification.plots"):
        importlib.import_module(name)
    with pytest.MonkeyPatch.context() as mp:
        for entries in WORK.values():
            for module, name, stub in entries:
                mod = importlib.import_module(module)
                real = getattr(mod, name)
                for other in list(sys.modules.values()):
                    if getattr(other, "__name__", "").startswith("frictionlab") and \
                            getattr(other, name, None) is real:
                        mp.setattr(other, name, stub)
        yield


# ---------------------------------------------------------------------------
# values
# ---------------------------------------------------------------------------

NUMBER_TEXT = st.one_of(
    st.sampled_from(["0", "-1", "1", "2", "0.5", "0.005", "30", "1e9", "-1e9", "1e309",
                     "nan", "-nan", "inf", "-inf", "1e-9", "5e-324", "abc", "", " ", "0x10",
                     "1_000", " 3 ", "1" * 5000, "None", "true", "1,2", "--json"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**6), 10**25).map(str),
)
KEYS = list(valid_keys())
KEY_TEXT = st.one_of(st.sampled_from(KEYS), st.sampled_from(
    ["plant.omega", "coulomb", "nope", "", "plant.", ".omega0", "plant.omega0.x", "PLANT.G",
     "friction.coulomb=1", "a" * 500]), st.text(max_size=12))
RANGE_TEXT = st.builds(
    lambda a, b, n: f"{a}:{b}:{n}", NUMBER_TEXT,
    NUMBER_TEXT, st.sampled_from(["0", "1", "2", "3", "-1", "x", "1e3", "100001",
                                  "100000000", "1" * 40]))
VALUES_TEXT = st.one_of(NUMBER_TEXT, RANGE_TEXT,
                        st.lists(NUMBER_TEXT, max_size=4).map(",".join))
ASSIGNMENT = st.one_of(st.builds(lambda k, v: f"{k}={v}", KEY_TEXT, VALUES_TEXT),
                       st.text(max_size=15))
BACKENDS = st.sampled_from(["sim", "udp://127.0.0.1:9", "udp://127.0.0.1", "udp://:1",
                            "udp://h:99999", "serial:///dev/null", "serial://", "bogus", "",
                            "tcp://x:1"])
DASK = st.sampled_from(["local", "tcp://127.0.0.1:1", "tcp://", "x", ""])


def _toml_scalar(draw) -> str:
    kind = draw(st.sampled_from(["float", "int", "bool", "str", "date", "array", "deep",
                                 "table"]))
    if kind == "float":
        v = draw(st.floats(allow_nan=True, allow_infinity=True))
        return {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(repr(v), repr(v))
    if kind == "int":
        return str(draw(st.integers(-(10**30), 10**30)))
    if kind == "bool":
        return draw(st.sampled_from(["true", "false"]))
    if kind == "str":
        return json.dumps(draw(st.one_of(NUMBER_TEXT, st.text(max_size=8))))
    if kind == "date":
        return draw(st.sampled_from(["1979-05-27", "07:32:00", "1979-05-27T07:32:00Z"]))
    if kind == "array":
        return "[" + ", ".join(draw(st.lists(st.sampled_from(["1", "2.5", '"x"']),
                                             max_size=3))) + "]"
    if kind == "deep":
        depth = draw(st.sampled_from([2, 50, 1000, 5000]))
        return "[" * depth + "]" * depth
    return "{x = 1}"


@st.composite
def toml_text(draw) -> bytes:
    if draw(st.integers(0, 9)) == 0:
        return draw(st.binary(max_size=200))
    lines = []
    for _ in range(draw(st.integers(0, 4))):
        section = draw(st.sampled_from([*_SECTIONS, "bogus", "plant.x"]))
        style = draw(st.sampled_from(["table", "dotted", "top"]))
        fields = draw(st.lists(st.one_of(
            st.sampled_from([k.split(".", 1)[1] for k in KEYS]), st.sampled_from(["nope", ""])),
            max_size=3))
        if style == "table":
            lines.append(f"[{section}]")
        for f in fields:
            key = f if style != "dotted" else f"{section}.{f}"
            lines.append(f"{json.dumps(key) if not key else key} = {_toml_scalar(draw)}")
    return "\n".join(lines).encode()


JSON_VALUE = st.recursive(
    st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False), st.integers(),
              st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.text(max_size=8), inner, max_size=3)),
    max_leaves=8)
FEATURES = ["peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity", "peak_to_peak"]


@st.composite
def measured_text(draw) -> bytes:
    kind = draw(st.integers(0, 5))
    if kind == 0:
        return draw(st.binary(max_size=100))
    if kind == 1:
        depth = draw(st.sampled_from([10, 5000, 100000]))
        return ('{"experiments": ' + "[" * depth + "]" * depth + "}").encode()
    if kind == 2:
        return json.dumps(draw(JSON_VALUE)).encode()
    number = st.one_of(st.floats(allow_nan=False), st.integers(-5, 5), st.text(max_size=4),
                       st.none())
    exps = draw(st.lists(st.fixed_dictionaries(
        {"design": st.sampled_from(["fast", "slow", "medium", 3])},
        optional={"set": st.dictionaries(KEY_TEXT, number, max_size=2),
                  "features": st.dictionaries(st.sampled_from([*FEATURES, "bogus"]), number,
                                              max_size=4),
                  "name": st.one_of(st.text(max_size=5), st.integers())}), max_size=3))
    return json.dumps({"experiments": exps}).encode()


@st.composite
def log_text(draw) -> tuple[str, bytes]:
    """A recorded log (.csv with a header, or .dat), sometimes malformed."""
    ext = draw(st.sampled_from([".csv", ".dat", ".txt"]))
    cell = st.one_of(st.floats(-10, 10).map(repr), st.sampled_from(["nan", "inf", "x", ""]))
    ncol = draw(st.integers(1, 11))
    rows = draw(st.lists(st.lists(cell, min_size=ncol, max_size=ncol), max_size=12))
    sep = "," if ext == ".csv" else " "
    lines = [sep.join(r) for r in rows]
    if ext == ".csv":
        cols = ["t", "theta_m", "u", "arm_m", "arm_dot_m", "friction", "x", "t"]
        lines.insert(0, ",".join(draw(st.lists(st.sampled_from(cols), min_size=ncol,
                                               max_size=ncol))))
    return ext, "\n".join(lines).encode()


def _path(draw, folder: Path, dest: str) -> str:
    """A path for option ``dest``: generated input files, good and bad outputs."""
    if dest == "config":
        p = folder / "c.toml"
        p.write_bytes(draw(toml_text()))
    elif dest == "measured":
        p = folder / "m.json"
        p.write_bytes(draw(measured_text()))
    elif dest == "log":
        ext, data = draw(log_text())
        p = folder / f"log{ext}"
        p.write_bytes(data)
    else:
        name = draw(st.sampled_from(["x.csv", "x.dat", "x.png", "x.json", "x.parquet",
                                     "x.txt", "sub", "out"]))
        where = draw(st.sampled_from(["here", "missing", "proc", "dir", "existing"]))
        if where == "missing":  # under a regular file: cannot exist, cannot be created
            (folder / "file").write_text("")
            return str(folder / "file" / name)
        if where == "proc":
            return f"/proc/nope/{name}"
        if where == "dir":
            return str(folder)
        p = folder / name
        if where == "existing":
            p.write_bytes(draw(st.binary(max_size=50)))
            Path(str(p) + ".meta.json").write_bytes(draw(measured_text()))
    return str(p) if draw(st.integers(0, 9)) else str(p) + "/"


def _value(draw, action: argparse.Action, folder: Path) -> str:
    dest = action.dest
    if dest in ("config", "measured", "log", "out", "save", "plot", "report", "log_dir"):
        return _path(draw, folder, dest)
    if action.choices:
        if draw(_MOSTLY):
            return draw(st.sampled_from(list(action.choices)))
        return draw(st.text(max_size=8))
    if dest in ("sets", "vary", "fault", "bounds", "weights"):
        return draw(ASSIGNMENT)
    if dest == "fit":
        return ",".join(draw(st.lists(KEY_TEXT, max_size=3)))
    if dest in ("references", "levels"):
        return ",".join(draw(st.lists(NUMBER_TEXT, max_size=4)))
    if dest == "backend":
        return draw(BACKENDS)
    if dest == "dask":
        return draw(DASK)
    if action.type in (int, float) or dest == "cpu":
        return draw(NUMBER_TEXT)
    return draw(st.one_of(st.text(max_size=10), NUMBER_TEXT))


#: True 29 times in 30 (hypothesis favours the ends of a range, so not 0 or 29).
_MOSTLY = st.integers(0, 29).map(lambda i: i != 13)

#: Valid options that let the examples of a subcommand get past its first checks.
VALID = {
    ("sweep",): (("--vary", "friction.coulomb=1.3,1.5"), ("--out", "s.csv")),
    ("identify", "limit-cycle"): (("--measured", "{example}"), ("--fit", "friction.coulomb")),
    ("compensate", "tune"): (("--vary", "compensation.sigma0=100,300"),),
}


def _argv(draw, path, parser, folder: Path) -> list[str]:
    argv = list(path)
    for action in parser._actions:
        if not action.option_strings and action.nargs != 0 and action.choices:
            argv.append(draw(st.sampled_from(list(action.choices)))
                        if draw(_MOSTLY) else draw(st.text(max_size=6)))
        elif not action.option_strings and action.dest == "log" and draw(_MOSTLY):
            argv.append(_path(draw, folder, "log"))  # features LOG
    for flag, value in VALID.get(path, ()):
        if draw(_MOSTLY):
            argv += [flag, value.format(example=EXAMPLE)]
    options = [a for a in parser._actions if a.option_strings and a.dest != "help"]
    valid = {flag for flag, _ in VALID.get(path, ())}
    required = [a for a in options if a.required and not valid & set(a.option_strings)
                and draw(_MOSTLY)]
    for action in required + draw(st.lists(st.sampled_from(options), max_size=6)):
        flag = draw(st.sampled_from(action.option_strings))
        if action.nargs == 0:
            argv.append(flag)
        elif draw(st.booleans()):  # --opt=VALUE: any value, "-1e9" too
            argv.append(f"{flag}={_value(draw, action, folder)}")
        else:
            argv += [flag, _value(draw, action, folder)]
    if draw(st.integers(0, 30)) == 0:
        argv.append(draw(st.sampled_from(["--help", "--nope", "-x", "extra"])))
    return argv


# ---------------------------------------------------------------------------
# the property
# ---------------------------------------------------------------------------


def _on_alarm(signum, frame):
    raise Hang


def run_in_process(argv: list[str], folder: Path):
    """main(argv) with stdout/stderr captured, cwd in ``folder``, memory traced."""
    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    cwd = os.getcwd()
    os.chdir(folder)
    tracemalloc.start()
    signal.setitimer(signal.ITIMER_REAL, HANG_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = cli.main(argv)
            except SystemExit as exc:  # argparse: --help, usage errors
                rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
            except Reached:
                rc = "reached"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        os.chdir(cwd)
        signal.signal(signal.SIGALRM, previous)
    return rc, out.getvalue(), err.getvalue(), peak


def check_outcome(argv, rc, out, err, peak):
    assert peak < MEMORY_LIMIT, f"{argv}: {peak / 2**20:.0f} MB traced"
    assert "Traceback" not in err, f"{argv}: {err}"
    if rc == "reached":
        return
    assert rc in (0, 2), f"{argv}: exit status {rc}; stderr {err!r}"
    if rc == 2:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1, f"{argv}: {len(lines)} lines on stderr: {err!r}"
        assert "error" in lines[0]
    elif "--json" in argv and not {"--help", "-h"} & set(argv) and out:
        assert len(out.splitlines()) == 1 and isinstance(json.loads(out), dict), argv


@pytest.mark.slow
@pytest.mark.parametrize("path", sorted(WORK), ids=" ".join)
@FUZZ
@given(data=st.data())
def test_bad_input_exits_2_with_one_line(stubbed, path, data):
    parser = PARSERS[path]
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        folder = Path(tmp)
        argv = _argv(data.draw, path, parser, folder)
        rc, out, err, peak = run_in_process(argv, folder)
        check_outcome(argv, rc, out, err, peak)


# ---------------------------------------------------------------------------
# the reported cases, each once, in-process and (a few) through the entry point
# ---------------------------------------------------------------------------

DEEP_TOML = "[plant]\nomega0 = " + "[" * 5000 + "]" * 5000 + "\n"
DEEP_JSON = '{"experiments": ' + "[" * 100000 + "]" * 100000 + "}"

REPORTED = [
    (["design", "--config", "{deep.toml}"], "nested too deeply"),
    (["identify", "limit-cycle", "--measured", "{deep.json}", "--fit", "friction.coulomb"],
     "nested too deeply"),
    (["run", "--cpu", "-1"], "--cpu"),
    (["run", "--cpu", "abc"], "--cpu"),
    (["rig-sim", "--cpu", "-1"], "--cpu"),
    (["sweep", "--vary", "friction.coulomb=1:2:100000000", "--out", "x.csv"], "<= 100000"),
    (["sweep", "--vary", "friction.coulomb=1:2:1000", "--vary", "plant.omega0=6:7:1000",
      "--out", "x.csv"], "1000000 parameter sets"),
    (["identify", "experiment", "stiction", "--hold", "1e9"], "--hold = 1e+09 is out of range"),
    (["run", "--headless", "--duration", "1", "--log-dir", "/proc/nope"], "--log-dir"),
    (["identify", "limit-cycle", "--measured", EXAMPLE, "--fit", "friction.coulomb",
      "--report", "/nonexistent/r.json"], "/nonexistent does not exist"),
    (["design", "--config", "{str.toml}"], "is a string '7.0'; it must be a number"),
    (["design", "--set", "plant.omga0=7"], "did you mean plant.omega0?"),
]


def _files(folder: Path) -> dict:
    files = {"deep.toml": DEEP_TOML, "deep.json": DEEP_JSON,
             "str.toml": '[plant]\nomega0 = "7.0"\n'}
    for name, text in files.items():
        (folder / name).write_text(text)
    return {f"{{{name}}}": str(folder / name) for name in files}


@pytest.mark.parametrize("argv, message", REPORTED, ids=lambda v: " ".join(v)[:50]
                         if isinstance(v, list) else "")
def test_reported_bad_input_in_process(stubbed, tmp_path, argv, message):
    names = _files(tmp_path)
    argv = [names.get(a, a) for a in argv]
    rc, out, err, peak = run_in_process(argv, tmp_path)
    check_outcome(argv, rc, out, err, peak)
    assert rc == 2 and message in err


@pytest.mark.slow
@pytest.mark.parametrize("argv, message", [REPORTED[i] for i in (0, 1, 2, 5, 7, 8)],
                         ids=lambda v: " ".join(v)[:40] if isinstance(v, list) else "")
def test_reported_bad_input_through_the_entry_point(tmp_path, argv, message):
    """The console script itself, in 1 GB of address space: exit 2, one line."""
    names = _files(tmp_path)
    argv = [names.get(a, a) for a in argv]
    script = Path(sys.executable).with_name("frictionlab")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "frictionlab"]

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))

    res = subprocess.run([*cmd, *argv], capture_output=True, text=True, cwd=tmp_path,
                         preexec_fn=limit, timeout=120)
    assert res.returncode == 2, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and message in res.stderr
    assert res.stdout == ""
