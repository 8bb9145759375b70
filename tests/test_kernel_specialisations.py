"""The longest compiles of the package happen once per signature: the compiled batch
evaluator calls the closed loop and the limit-cycle features with the argument types
the Python callers use, not with numba's literal types of constants (each literal
signature is a compile of its own on a fresh clone: docs/performance.md, "CI time")."""

from __future__ import annotations

import pytest

from frictionlab.config import build_config
from frictionlab.model.closedloop import run_loop
from frictionlab.model.limit_cycles import features_kernel
from frictionlab.runs import run_features
from frictionlab.studies.batch import evaluate_rows

pytestmark = pytest.mark.slow


def _literal(sig) -> bool:
    from numba.core.types import Literal

    return any(isinstance(a, Literal) for a in sig)


def test_the_batch_and_python_callers_share_one_closed_loop_and_features_signature():
    cfg = build_config("fast", "classical")
    run_features(cfg, 1.0, 0.5)  # the Python callers: simulate, then the features
    rows = evaluate_rows(cfg, [{}], 1.0, 0.5)  # the compiled batch evaluator
    assert rows and rows[0]  # it ran
    for kernel in (run_loop, features_kernel):
        sigs = kernel.dispatcher.signatures
        assert sigs, kernel.__name__
        assert not any(_literal(s) for s in sigs), (kernel.__name__, sigs)
        assert len(sigs) == 1, (kernel.__name__, sigs)
