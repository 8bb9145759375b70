"""Every command the README and the docs show works as written.

Each command line of a fenced ``bash``/``sh``/``shell``/``console`` block of
README.md and docs/*.md (continuation lines joined; in ``console`` blocks the
``$ `` lines) runs, unchanged, with ``bash`` in a fresh folder holding a copy
of the repository's ``examples/``, the lines of one document in order and in
one folder (a later line may use an earlier one's output); a document's
real-time runs (:func:`runs_the_loop`), with the lines of their block after
them, run in a test of their own (marker ``realtime``).  It must exit 0,
and with ``--json`` print exactly one JSON object on stdout.  Only the lines
of :data:`SKIPPED` do not run: servers that run until stopped, each smoke
tested elsewhere (named with the reason).  Every ``python`` block runs too
(:data:`PYTHON_FRAGMENTS` excepted), and every ``toml`` block must be a valid
``--config`` file.
"""

from __future__ import annotations

import functools
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from inprocess import run_cli_in_process

from frictionlab.config import build_config

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL = {"bash", "sh", "shell", "console"}

#: (pattern of a command line, why it does not run here).  Each must match a
#: documented line (checked), so the list cannot go stale.
SKIPPED = [
    (r"^\./scripts/run\b",
     "the main job, a console server until Ctrl-C: tests/test_scripts.py::"
     "test_scripts_run_installs_and_serves_the_console"),
    (r"^\./scripts/test\b", "the test suite itself (CI runs it as .ci/run)"),
    (r"^\./scripts/stress\b", "the test suite under load; scripts/stress itself: "
     "tests/test_stress_script.py"),
    (r"^frictionlab run(?!.*--headless)",
     "the console server, until stopped: tests/test_realtime_cli.py::"
     "test_console_mode_stops_on_a_signal (and the browser tests)"),
    (r"^frictionlab rig-sim\b",
     "the emulated rig, a UDP server until stopped: the rig_sim fixture of "
     "tests/test_realtime_cli.py"),
    (r"^dask (scheduler|worker)\b", "a Dask cluster's servers, until stopped"),
    (r"--dask tcp://HEAD:", "needs that Dask cluster (HEAD is a placeholder for its host)"),
]
#: Python blocks that are fragments, not programs (undefined names on purpose).
PYTHON_FRAGMENTS = {
    ("compensation.md", "make_compensator"): "shows a call with the loop's signals as names",
    ("logs.md", "pd.read_parquet"): "needs pandas (not a dependency) and names a run's files",
}
#: Stop reasons a stalled host (not the command) causes in a real-time run, as the run
#: and the experiments report them.
LOAD_STOPS = re.compile(r"stopped(?: before it finished)?: (paused|rig_silent)\b")
#: A run longer than this is a bug (the slowest documented command takes ~30 s).
TIMEOUT = 600


def blocks(path: Path):
    """(language, first line number, text) of every fenced block."""
    out, lang, start, buf = [], None, 0, []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        fence = re.match(r"^```(\S*)\s*$", line)
        if fence and lang is None:
            lang, start, buf = fence.group(1), i + 1, []
        elif line.startswith("```") and lang is not None:
            out.append((lang, start, "\n".join(buf)))
            lang = None
        elif lang is not None:
            buf.append(line)
    return out


def shell_commands(path: Path):
    """(line number, command) of every command line in the shell blocks."""
    cmds = []
    for lang, start, text in blocks(path):
        if lang not in SHELL:
            continue
        pending, first = "", 0
        for i, line in enumerate(text.splitlines(), start):
            if lang == "console" and not pending:
                if not line.startswith("$ "):
                    continue  # output shown in the block
                line = line[2:]
            if not pending:
                first = i
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            cmds.append((first, " ".join((pending + line).split())))
            pending = ""
    return cmds


def documented_output(path: Path, block_start: int) -> list[str]:
    """The output the document shows for the fenced block starting at ``block_start``: the
    lines of the markdown table or fenced ``text`` block after a paragraph that starts
    with "prints" right after the block (empty when it shows none)."""
    lines = path.read_text().splitlines()
    end = block_start - 1  # 0-based index of the block's first line
    while end < len(lines) and not lines[end].startswith("```"):
        end += 1
    i = end + 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines) or not lines[i].startswith("prints"):
        return []
    while i < len(lines) and not (lines[i].startswith("|") or lines[i].startswith("```")):
        i += 1
    out = []
    if i < len(lines) and lines[i].startswith("```"):
        if lines[i].strip() != "```text":
            return []
        i += 1
        while i < len(lines) and not lines[i].startswith("```"):
            out.append(lines[i])
            i += 1
    else:
        while i < len(lines) and lines[i].startswith("|"):
            out.append(lines[i])
            i += 1
    return [ln.strip() for ln in out if ln.strip()]


def check_documented_output(doc: Path, line: int, stdout: str) -> None:
    """The numbers a document shows come from the program: every line it shows as the
    output of the block holding ``line`` is a line of what the block printed."""
    got = {ln.strip() for ln in stdout.splitlines()}
    for want in documented_output(doc, _block_start(doc, line)):
        assert want in got, (f"{doc.name}:{line}: the document shows\n  {want}\nbut the "
                             f"program printed:\n{stdout[-3000:]}")


def skip_reason(command: str) -> str | None:
    return next((why for pat, why in SKIPPED if re.search(pat, command)), None)


COMMANDS = [(p, n, c) for p in DOCUMENTS for n, c in shell_commands(p)]


def test_the_documents_show_commands_and_every_skip_is_used():
    assert len(COMMANDS) >= 30
    for pattern, _why in SKIPPED:
        assert any(re.search(pattern, c) for _, _, c in COMMANDS), f"unused skip {pattern!r}"
    # the test suite's own lines (the suite cannot run itself) aside, a small list:
    # servers only
    skipped = [c for _, _, c in COMMANDS
               if skip_reason(c) and not re.match(r"\./scripts/(test|stress)\b", c)]
    assert len(skipped) <= 12, skipped


def _folder(tmp_path: Path) -> Path:
    """A working folder for one document, with a copy of examples/."""
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    (tmp_path / "docs" / "figures").mkdir(parents=True)
    return tmp_path


_SHELL_SYNTAX = re.compile(r"[|&;<>()$`*?{}\\!]")


def runs_the_loop(command: str) -> bool:
    """Does the command run the 200 Hz loop in real time (``frictionlab run``, an
    experiment on a ``--backend``)?"""
    return command.startswith("frictionlab run") or "--backend" in command.split()


def plain_frictionlab(command: str) -> list[str] | None:
    """The arguments of a plain ``frictionlab ...`` command line (no pipes,
    redirections, variables or globs: bash would pass it on unchanged; not ``run``,
    an experiment on a ``--backend`` or ``rig-sim``), else None.

    Such a line runs in-process (:func:`inprocess.run_cli_in_process`); the
    installed ``frictionlab`` executable itself is tested in tests/test_cli.py
    and tests/test_startup.py.
    """
    try:
        words = shlex.split(command, comments=True)
    except ValueError:
        return None
    code = command.split(" #", 1)[0]
    if words[:1] != ["frictionlab"] or _SHELL_SYNTAX.search(code) or "=" in words[0]:
        return None
    if words[1:2] in (["run"], ["rig-sim"]) or runs_the_loop(command):
        # the real-time loop installs signal handlers and leaves threads finishing its
        # logs: it runs as the process it is
        return None
    return words[1:]


def _env() -> dict:
    env = dict(os.environ)
    # the frictionlab of this interpreter first on PATH
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    return env


def _run_command(cwd: Path, doc: Path, line: int, command: str) -> None:
    argv = plain_frictionlab(command)
    if argv is not None:  # the same command line, without paying the interpreter's start-up
        res = run_cli_in_process(argv, cwd=cwd, env={"MPLBACKEND": "Agg"})
    else:
        before = set(cwd.rglob("*"))
        for _attempt in range(3):
            res = subprocess.run(["bash", "-c", command], cwd=cwd, env=_env(),
                                 capture_output=True, text=True, timeout=TIMEOUT)
            # a real-time run that a stalled host stopped (as it must on a rig: the
            # safety stops are tested in tests/test_realtime_*) is repeated; what is
            # tested here is that the documented command works
            if not (runs_the_loop(command) and res.returncode == 1
                    and LOAD_STOPS.search(res.stderr)):
                break
            # the stopped run's files go, as if it had not run (a later line's glob,
            # run-*.csv, matched both runs' logs)
            for path in sorted(set(cwd.rglob("*")) - before, reverse=True):
                path.rmdir() if path.is_dir() else path.unlink()
            # shown in pytest's warnings summary: how often a host stalls this long
            warnings.warn(f"{doc.name}:{line}: a stalled host stopped the run, run again: "
                          f"{res.stderr.strip().splitlines()[-1][:200]}", stacklevel=1)
    where = f"{doc.name}:{line}: {command}"
    assert res.returncode == 0, f"{where}\nexit {res.returncode}\n{res.stderr[-3000:]}"
    if _last_in_block(doc, line):
        check_documented_output(doc, line, res.stdout)
    if "--json" in command.split():
        lines = res.stdout.strip().splitlines()
        assert len(lines) == 1, f"{where}: stdout is not one JSON line:\n{res.stdout[:2000]}"
        assert isinstance(json.loads(lines[0]), dict), where
    # the files (or, for reproduce --out, the folder) it was asked to write exist
    for opt in ("--plot", "--out", "--save", "--report"):
        args = command.split()
        if opt in args:
            target = cwd / args[args.index(opt) + 1]
            made = (target.is_file() and target.stat().st_size > 0) or (
                target.is_dir() and any(target.iterdir()))
            assert made, f"{where}: nothing written to {target}"


PYTHON = [(p, n, t) for p in DOCUMENTS for lang, n, t in blocks(p) if lang == "python"]


def _fragment(doc: Path, text: str) -> bool:
    return any(doc.name == name and marker in text for name, marker in PYTHON_FRAGMENTS)


@functools.cache
def _block_starts(doc: Path) -> tuple[int, ...]:
    return tuple(start for _lang, start, _text in blocks(doc))


def _block_start(doc: Path, line: int) -> int:
    """The first line of the fenced block holding ``line``."""
    return max(start for start in _block_starts(doc) if start <= line)


def _last_in_block(doc: Path, line: int) -> bool:
    """``line`` is the last command of its fenced block (whose output a document shows)."""
    block = _block_start(doc, line)
    return max(n for d, n, _c in COMMANDS if d == doc and _block_start(d, n) == block) == line


def _real_time(doc: Path, line: int, command: str) -> bool:
    """A line of a real-time run (:func:`runs_the_loop`), or a later line of its block
    (which may read the run's files)."""
    block = _block_start(doc, line)
    return any(runs_the_loop(c) and n <= line
               for d, n, c in COMMANDS if d == doc and _block_start(d, n) == block)


def _work(real_time: bool) -> dict:
    """Per document: its command lines (not skipped), then its Python blocks (not
    fragments), those of real-time runs or the others."""
    return {p: ([(n, c) for d, n, c in COMMANDS
                 if d == p and not skip_reason(c) and _real_time(d, n, c) == real_time],
                [(n, t) for d, n, t in PYTHON
                 if d == p and not _fragment(d, t) and ("--headless" in t) == real_time])
            for p in DOCUMENTS}


#: Per document: the lines that compute (scripts/test runs them on every CPU) ...
WORK = _work(real_time=False)
#: ... and the real-time runs (marker ``realtime``: phase 2 of scripts/test, one at a
#: time, not beside the suite computing on every CPU; docs/development.md)
REAL_TIME_WORK = _work(real_time=True)


def _run_document(tmp_path: Path, doc: Path, work: dict) -> None:
    cwd = _folder(tmp_path)
    commands, python = work[doc]
    for line, command in commands:
        _run_command(cwd, doc, line, command)
    for line, code in python:
        res = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=_env(),
                             capture_output=True, text=True, timeout=TIMEOUT)
        assert res.returncode == 0, f"{doc.name}:{line}\n{res.stderr[-3000:]}"
        check_documented_output(doc, line, res.stdout)


# one test per document: its lines depend on each other (a file one writes, the next
# reads), so they run in order, in one folder, in one process (under pytest-xdist a
# group of separate tests was seen split across workers)
@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("doc", [pytest.param(p, id=p.name) for p in DOCUMENTS
                                 if WORK[p][0] or WORK[p][1]])
def test_documented_commands_and_python_run_as_written(tmp_path, doc):
    _run_document(tmp_path, doc, WORK)


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("doc", [pytest.param(p, id=p.name) for p in DOCUMENTS
                                 if REAL_TIME_WORK[p][0] or REAL_TIME_WORK[p][1]])
def test_documented_real_time_runs_work_as_written(tmp_path, doc):
    _run_document(tmp_path, doc, REAL_TIME_WORK)


def test_the_real_time_runs_are_split_off_with_the_lines_reading_their_files():
    """Every documented real-time run is in the real-time set, with the lines after it in
    its block (cli.md reads the run's log) and nothing else."""
    runs = [(d, n) for d, n, c in COMMANDS if runs_the_loop(c) and not skip_reason(c)]
    assert len(runs) >= 5
    assert any("identify experiment" in c and "--backend" in c
               for c in (c for _, c in REAL_TIME_WORK[ROOT / "README.md"][0]))
    for d, n in runs:
        assert n in [line for line, _ in REAL_TIME_WORK[d][0]]
        assert n not in [line for line, _ in WORK[d][0]]
    cli = ROOT / "docs" / "cli.md"
    features = [c for n, c in REAL_TIME_WORK[cli][0] if c.startswith("frictionlab features")]
    assert features and all("feature-runs" in c or ".dat" in c for c in features)
    # the split loses and repeats no line
    for doc in DOCUMENTS:
        both = [n for n, _ in WORK[doc][0]] + [n for n, _ in REAL_TIME_WORK[doc][0]]
        assert sorted(both) == [n for d, n, c in COMMANDS if d == doc and not skip_reason(c)]
    assert any("--headless" in t for _, t in REAL_TIME_WORK[ROOT / "docs" / "logs.md"][1])


def test_every_python_fragment_exemption_is_used():
    for (name, marker), _why in PYTHON_FRAGMENTS.items():
        assert any(p.name == name and marker in t for p, _, t in PYTHON), (name, marker)


@pytest.mark.parametrize("doc,line,text", [
    pytest.param(p, n, t, id=f"{p.name}:{n}")
    for p in DOCUMENTS for lang, n, t in blocks(p) if lang == "toml"])
def test_documented_toml_is_a_valid_config(tmp_path, doc, line, text):
    path = tmp_path / "c.toml"
    path.write_text(text)
    cfg = build_config(config_file=path)  # unknown keys and bad values raise
    assert cfg != build_config()


def test_documented_outputs_are_found_and_compared():
    """The outputs documents show are read (a table after "prints", a ``text`` block), and
    a line the program did not print fails the check."""
    doc = ROOT / "docs" / "sweep.md"
    start = next(n for d, n, c in COMMANDS if d == doc and "--table" in c)
    shown = documented_output(doc, _block_start(doc, start))
    assert shown[0].startswith("| friction.coulomb |") and len(shown) == 7
    check_documented_output(doc, start, "\n".join(shown) + "\nsomething else\n")
    with pytest.raises(AssertionError, match="the document shows"):
        check_documented_output(doc, start, "\n".join(shown[:-1]))

