"""The scripts that produce the documents' evidence (docs/scripts/) still load against
the package: every name they import exists (their full runs take minutes, so only
their module level runs here, not their ``main``)."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

SCRIPTS = sorted((Path(__file__).resolve().parent.parent / "docs" / "scripts").glob("*.py"))


def test_there_are_scripts():
    assert len(SCRIPTS) >= 4


@pytest.mark.slow  # a script's imports (plotting, compiled kernels): up to seconds
@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.name)
def test_a_docs_script_imports_what_exists(path):
    ns = runpy.run_path(str(path), run_name="docs_script_under_test")
    assert callable(ns.get("main")), f"{path.name} has no main()"
