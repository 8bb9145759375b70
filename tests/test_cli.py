"""Command-line habits: `keys` shows the defaults, an unknown key suggests the nearest
ones, every subcommand has a one-line summary and a description, help shows the real
defaults, notes never join an error line."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from frictionlab.cli import build_parser, main
from frictionlab.config import build_config, valid_keys
from frictionlab.model.design import preset


def _run(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _walk(parser, path=()):
    """(path, parser, help line in the parent's listing) for every subcommand."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield (*path, name), sub, helps.get(name)
                yield from _walk(sub, (*path, name))


@pytest.mark.parametrize("argv, design, compensation", [
    ([], "fast", "none"),
    (["--design", "slow", "--compensation", "classical"], "slow", "classical"),
])
def test_keys_json_lists_every_key_with_its_default(capsys, argv, design, compensation):
    rc, out, _ = _run(capsys, "keys", *argv, "--json")
    assert rc == 0
    obj = json.loads(out)
    assert (obj["design"], obj["compensation"]) == (design, compensation)
    rows = obj["keys"]
    assert [r["key"] for r in rows] == valid_keys()
    cfg = build_config(design=design, compensation=compensation)
    for r in rows:
        assert r["default"] == cfg.get(r["key"]), r["key"]
        assert r["range"] and r["doc"] and "unit" in r
    by_key = {r["key"]: r for r in rows}
    # the preset and the compensator choose defaults
    assert by_key["design.omega2"]["default"] == preset(design).omega2
    assert by_key["compensation.hysteresis"]["default"] == (
        0.08 if compensation == "classical" else 0.0)
    assert by_key["friction.stiction_negative"]["default"] is None


def test_keys_table_shows_defaults(capsys):
    rc, out, _ = _run(capsys, "keys", "--design", "slow")
    assert rc == 0
    lines = out.splitlines()
    assert "--design slow" in lines[0]
    assert lines[1].split()[:3] == ["key", "default", "allowed"]
    row = next(ln for ln in lines if ln.startswith("design.omega2 "))
    assert float(row.split()[1]) == preset("slow").omega2 != preset("fast").omega2
    row = next(ln for ln in lines if ln.startswith("sim.seed "))
    assert "[0, 4294967295]" in row  # integers in full, not 4.29497e+09
    assert len(lines) == 2 + len(valid_keys())


@pytest.mark.parametrize("argv, hint", [
    (["design", "--set", "plant.omga0=7"], "did you mean plant.omega0?"),
    (["simulate", "--set", "coulomb=1.2"],
     "did you mean friction.coulomb or compensation.coulomb?"),
    (["sweep", "--vary", "friction.coloumb=1,2", "--out", "x.csv"],
     "did you mean friction.coulomb?"),
    (["design", "--set", "xyz=1"], "'frictionlab keys' lists them"),
])
def test_unknown_key_suggests_nearest_in_one_short_line(capsys, tmp_path, monkeypatch,
                                                        argv, hint):
    monkeypatch.chdir(tmp_path)
    rc, out, err = _run(capsys, *argv)
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and hint in err
    assert "friction.sigma1_velocity" not in err  # not the list of all keys


def test_every_subcommand_has_a_one_line_summary_and_a_description():
    parser = build_parser()
    found = list(_walk(parser))
    assert {p for p, _, _ in found} >= {("design",), ("simulate",), ("keys",), ("sweep",),
                                        ("identify",), ("identify", "limit-cycle"),
                                        ("identify", "experiment"), ("compensate",),
                                        ("compensate", "compare"), ("compensate", "tune"),
                                        ("run",), ("rig-sim",)}
    for path, sub, summary in found:
        assert summary and "\n" not in summary, path
        assert sub.description, path


@pytest.mark.slow
def test_top_level_help_lists_each_subcommand_on_one_line():
    res = subprocess.run([sys.executable, "-m", "frictionlab", "--help"], capture_output=True,
                         text=True, env={"COLUMNS": "80", "PATH": ""}, timeout=60, check=True)
    parser = build_parser()
    names = [p[0] for p, _, _ in _walk(parser) if len(p) == 1]
    lines = res.stdout.splitlines()
    for name in names:
        line = next(ln for ln in lines if ln.split()[:1] == [name])
        assert len(line.split()) > 2 and len(line) <= 80, line  # name and summary together


def test_help_shows_the_real_defaults():
    """Every option whose default is a value says so in its help, with that value
    (``compensate compare`` once claimed ``--compensation`` defaulted to none)."""
    checked = 0
    for path, sub, _ in _walk(build_parser()):
        formatter = sub._get_formatter()
        for action in sub._actions:
            d = action.default
            if d is None or d == argparse.SUPPRESS or isinstance(d, bool | list) \
                    or not action.help:
                continue
            text = formatter._expand_help(action)
            shown = [str(d)] + ([f"{d:g}"] if isinstance(d, float) else [])
            assert "default" in text and any(s in text for s in shown), (path, action.dest)
            checked += 1
    assert checked > 40
    parser = build_parser()
    compare = parser._subparsers._group_actions[0].choices["compensate"]
    compare = compare._subparsers._group_actions[0].choices["compare"]
    assert "(default: lugre)" in " ".join(compare.format_help().split())


def test_notes_wait_until_the_input_is_checked(capsys):
    # an inert key's note, then a bad option: the error line alone
    rc, _, err = _run(capsys, "simulate", "--set", "friction.sigma0=200", "--window", "-1")
    assert rc == 2 and err.count("\n") == 1 and "--window" in err
    # good input: the note is printed (before the work)
    rc, _, err = _run(capsys, "simulate", "--set", "friction.sigma0=200", "--duration", "1",
                        "--json")
    assert rc == 0 and "friction.sigma0 has no effect" in err


@pytest.mark.parametrize("argv", [
    ["sweep", "--vary", "friction.coulomb=1,2", "--out", "{tmp}/s.csv"],
    ["reproduce", "--out", "{tmp}/r"],
    ["compensate", "tune"],
    ["identify", "limit-cycle", "--measured", "{tmp}/m.json", "--fit", "friction.coulomb"],
])
@pytest.mark.parametrize("extra, message", [
    (["--workers", "0"], "--workers must be in 1.."),
    (["--dask", "udp://nowhere"], "--dask: must be 'local' or tcp://HOST:PORT"),
])
def test_the_sweep_engine_s_options_are_checked_alike(capsys, tmp_path, argv, extra, message):
    """--workers and --dask: one parser and one check for every command that runs the
    sweep engine, refused before any work."""
    (tmp_path / "m.json").write_text(json.dumps(
        {"experiments": [{"design": "fast", "features": {"period": 1.0, "peak1": 0.1}}]}))
    rc, out, err = _run(capsys, *[a.format(tmp=tmp_path) for a in argv], *extra)
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("action", ["compare", "tune"])
def test_compensate_needs_a_compensator_and_lists_every_kind(capsys, action):
    rc, _, err = _run(capsys, "compensate", action, "--compensation", "none")
    assert rc == 2
    assert "--compensation must be coulomb, classical, lugre or adaptive" in err
