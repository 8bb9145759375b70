"""Start-up: the light commands load neither numba nor scipy (nor plotting, Dask, the
console); a kernel still compiles on first use, exactly as before."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numba", "llvmlite", "scipy", "matplotlib", "dask", "distributed", "fastapi",
         "uvicorn", "pyarrow", "rich", "serial")

#: Run a command in a fresh interpreter, then list the heavy top-level packages loaded.
PROBE = """
import contextlib, io, json, sys
argv = json.loads(sys.argv[1])
out = io.StringIO()
with contextlib.redirect_stdout(out):
    if argv is None:
        import frictionlab
    else:
        from frictionlab.cli import main
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
        assert rc in (0, None), rc
heavy = sorted({m.split(".")[0] for m in sys.modules} & set(json.loads(sys.argv[2])))
print(json.dumps({"heavy": heavy, "stdout": out.getvalue()}))
"""


def _probe(argv):
    res = subprocess.run([sys.executable, "-c", PROBE, json.dumps(argv), json.dumps(HEAVY)],
                         capture_output=True, text=True, timeout=120, check=True)
    return json.loads(res.stdout)


@pytest.mark.slow
@pytest.mark.parametrize("argv", [
    None,  # import frictionlab
    ["--help"],
    ["keys"],
    ["keys", "--json"],
    ["design", "--json"],
    ["design", "--design", "slow", "--set", "design.omega1=5"],
    ["sweep", "--help"],
    ["identify", "experiment", "--help"],
    ["run", "--help"],
])
def test_light_commands_load_no_heavy_module(argv):
    got = _probe(argv)
    assert got["heavy"] == [], f"{argv} imported {got['heavy']}"
    if argv and argv[0] == "design":
        assert "L" in got["stdout"]


@pytest.mark.slow
def test_design_json_is_the_closed_form_design():
    obj = json.loads(_probe(["design", "--json"])["stdout"])
    from frictionlab.model.design import design

    d = design("fast")
    assert obj["L"] == pytest.approx(list(d.L), rel=1e-12)
    assert obj["K"] == pytest.approx(list(d.K), rel=1e-12)


def test_a_kernel_compiles_on_first_use_and_calls_its_callees():
    """A kernel defined with ``@jit`` is a lazy proxy; numba types it (and the
    kernels it calls) through the dispatcher, so results equal the Python
    function's."""
    import numpy as np

    from frictionlab.model.plants import thesis as plant

    args = (0.1, 0.2, 0.3, 1.0, 6.8, 0.04, 9.82, 0.21)
    compiled = plant.accelerations(*args)  # calls accelerations_sc inside nopython code
    sin_cos = (np.sin(0.1), np.cos(0.1))
    reference = plant.accelerations_sc.py_func(*sin_cos, 0.2, 0.3, 1.0, 6.8, 0.04, 9.82,
                                               0.21)
    assert compiled == pytest.approx(reference, rel=1e-14)
    assert plant.accelerations.signatures  # the dispatcher's API is reachable
    assert "numba" in sys.modules
