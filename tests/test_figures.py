"""Every figure a command writes: units on the axes, a title naming the design and
the parameters, traces told apart by line style as well as colour, the path on stderr.

Each command runs in-process (``frictionlab.cli.main``); the figures are taken
from ``Figure.savefig`` and inspected as matplotlib objects.
"""

import itertools
import json
import re
from pathlib import Path

import matplotlib.figure
import numpy as np
import pytest
from matplotlib.colors import to_rgba

from frictionlab.cli import main
from frictionlab.config import build_config
from frictionlab.model.limit_cycles import FEATURES
from frictionlab.plotting import config_title, feature_label, key_label, series_style
from frictionlab.runs import run_features

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
UNIT = re.compile(r"\[[^\]]+\]")


@pytest.fixture
def figures(monkeypatch):
    """The figures saved while a test runs."""
    saved = []
    save = matplotlib.figure.Figure.savefig

    def keep(fig, *args, **kwargs):
        saved.append(fig)
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return saved


def _has_data(ax) -> bool:
    return bool(ax.get_lines() or ax.collections or ax.patches)


def _labelled(ax):
    return [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]


def _categorical(ax) -> bool:
    return any(t.get_text() and not re.fullmatch(r"[-−\d.e+ ]+", t.get_text())
               for t in ax.get_xticklabels())


def check_figure(fig, *, title_has=()):
    """The house style; returns the title text."""
    title = fig.get_suptitle()
    axes = [ax for ax in fig.axes if _has_data(ax)]
    assert axes
    for ax in axes:
        # every y axis says what it shows and in which unit; a panel of a shared
        # column may leave it to the column's first panel
        ylabels = [a.get_ylabel() for a in ax.get_shared_y_axes().get_siblings(ax)]
        assert any(UNIT.search(y) for y in ylabels), (title, ax.get_ylabel())
        xlabels = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)]
        assert any(UNIT.search(x) for x in xlabels) or _categorical(ax), (title, xlabels)
        # traces in one panel differ in line style or marker, not in colour alone
        lines = _labelled(ax)
        for a, b in itertools.combinations(lines, 2):
            assert (a.get_linestyle(), a.get_marker()) != (b.get_linestyle(),
                                                           b.get_marker()), (
                title, a.get_label(), b.get_label())
        # a measured trace and an estimate of it: style and colour both differ
        meas = [ln for ln in lines if ln.get_label().startswith("measured")]
        est = [ln for ln in lines if ln.get_label().startswith("estimate")]
        for a, b in itertools.product(meas, est):
            assert a.get_linestyle() != b.get_linestyle()
            assert to_rgba(a.get_color())[:3] != to_rgba(b.get_color())[:3]
    # the title's words, however the lines wrap
    text = " ".join((title + " " + " ".join(ax.get_title() for ax in fig.axes)).split())
    for part in title_has:
        assert part in text, (part, text)
    return text


def _announced(err: str, path) -> bool:
    return f"frictionlab: plot written to {path}" in err


@pytest.mark.slow
def test_simulate_plot(figures, capsys, tmp_path):
    png = tmp_path / "cycle.png"
    assert main(["simulate", "--friction", "lugre", "--compensation", "lugre", "--duration",
                 "6", "--set", "plant.omega0=7.5", "--plot", str(png), "--json"]) == 0
    err = capsys.readouterr().err
    assert _announced(err, png) and png.read_bytes()[:4] == b"\x89PNG"
    (fig,) = figures
    check_figure(fig, title_has=("simulate: fast design, lugre friction, lugre compensator",
                                 "plant: omega0=7.5", "sigma0=100", "compensation: ",
                                 "sigma0=300"))
    ax_theta, ax_arm, ax_u, ax_f = fig.axes
    assert "[rad]" in ax_theta.get_ylabel() and "[rad/s]" in ax_arm.get_ylabel()
    assert "m/s" in ax_u.get_ylabel() and ax_f.get_xlabel() == "time [s]"
    # measured vs estimated, true vs estimated friction: both drawn, styles apart
    assert [ln.get_label() for ln in _labelled(ax_f)] == ["friction (plant, true)",
                                                          "estimate (compensator)"]
    assert len({ln.get_linestyle() for ln in _labelled(ax_f)}) == 2


@pytest.mark.slow
def test_sweep_plot(figures, capsys, tmp_path):
    png = tmp_path / "grid.png"
    assert main(["sweep", "--friction", "classical", "--set", "friction.zero_velocity_band=0.03",
                 "--vary", "friction.coulomb=1.3,1.7", "--vary", "friction.stiction=2.1,2.5",
                 "--duration", "6", "--workers", "1", "--no-progress",
                 "--out", str(tmp_path / "g.csv"), "--plot", str(png), "--json"]) == 0
    err = capsys.readouterr().err
    assert _announced(err, png)
    (fig,) = figures
    text = check_figure(fig, title_has=("sweep of friction.coulomb, friction.stiction",
                                        "fast design, classical friction",
                                        "zero_velocity_band=0.03"))
    assert "friction: coulomb=" not in text  # the swept keys are on the axes, not the title
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert ylabels == [feature_label(f) for f in FEATURES]
    assert ylabels[3] == "period [s]" and fig.axes[-1].get_xlabel() == (
        "friction.coulomb [m/s$^2$]")
    # one line per stiction value, apart in colour, line style and marker
    a, b = _labelled(fig.axes[0])
    assert a.get_label() == "friction.stiction=2.1" and b.get_label() == "friction.stiction=2.5"
    assert a.get_color() != b.get_color() and a.get_linestyle() != b.get_linestyle()
    assert a.get_marker() != b.get_marker()


@pytest.mark.slow
def test_compensate_compare_and_tune_plots(figures, capsys, tmp_path):
    png = tmp_path / "ba.png"
    assert main(["compensate", "compare", "--friction", "classical", "--compensation",
                 "coulomb", "--set", "compensation.hysteresis=0.05", "--duration", "6",
                 "--plot", str(png), "--json"]) == 0
    assert _announced(capsys.readouterr().err, png)
    png2 = tmp_path / "tuned.png"
    assert main(["compensate", "tune", "--friction", "lugre", "--compensation", "lugre",
                 "--vary", "compensation.observer_gain=3,7", "--duration", "6", "--workers",
                 "1", "--no-progress", "--plot", str(png2), "--json"]) == 0
    assert _announced(capsys.readouterr().err, png2)
    compare, tune = figures
    check_figure(compare, title_has=("compensate compare: fast design, classical friction, "
                                     "coulomb compensator", "hysteresis=0.05"))
    check_figure(tune, title_has=("compensate tune, best setting", "lugre compensator",
                                  "observer_gain="))
    for fig in figures:
        assert fig.axes[0].get_title().startswith("without compensation")
        assert fig.axes[-1].get_xlabel() == "time in the window [s]"


@pytest.mark.slow
def test_identify_limit_cycle_plot(figures, capsys, tmp_path):
    png = tmp_path / "fit.png"
    assert main(["identify", "limit-cycle", "--measured", str(EXAMPLES / "table1.json"),
                 "--fit", "friction.coulomb", "--bounds", "friction.coulomb=1.0:2.0",
                 "--duration", "8", "--window", "5", "--maxiter", "1", "--popsize", "2",
                 "--workers", "1", "--quiet", "--set", "friction.zero_velocity_band=0.03",
                 "--plot", str(png), "--json"]) == 0
    assert _announced(capsys.readouterr().err, png)
    (fig,) = figures
    text = check_figure(fig, title_has=("identify limit-cycle", "estimate: friction.coulomb",
                                        "fast: status", "slow: status", "slow design"))
    assert "zero_velocity_band=0.03" in text
    top = fig.axes[0]
    labels = [ln.get_label() for ln in _labelled(top)]
    assert labels[0] == "fitted simulation" and "measured peak1" in labels
    assert fig.axes[2].get_ylabel() == "fitted / measured feature [1]"  # row 2, column 1


@pytest.mark.slow
@pytest.mark.parametrize("argv,title", [
    (["stiction", "--simulate", "--step", "0.1", "--hold", "0.1"],
     "identify experiment stiction (App. E.1): simulated rig, classical friction"),
    (["stribeck", "--log", str(EXAMPLES / "stribeck_run.csv")],
     f"identify experiment stribeck (App. E.2): log {EXAMPLES / 'stribeck_run.csv'}"),
    (["free-oscillation", "--simulate", "--duration", "6", "--set", "plant.omega0=7.1"],
     "identify experiment free-oscillation (App. A): simulated rig, classical friction"),
    (["control-scaling", "--simulate", "--levels", "3,5", "--set", "plant.input_gain=1.2"],
     "identify experiment control-scaling (App. B.4): simulated rig"),
])
def test_identify_experiment_plots(figures, capsys, tmp_path, argv, title):
    png = tmp_path / "e.png"
    assert main(["identify", "experiment", *argv, "--plot", str(png), "--json"]) == 0
    out = capsys.readouterr()
    assert _announced(out.err, png) and json.loads(out.out)["plot"] == str(png)
    (fig,) = figures
    text = check_figure(fig, title_has=(title,))
    if "--simulate" in argv:
        assert "friction: " in text  # the simulated rig's friction parameters
    for part in [a for a in argv if "=" in a and a.startswith("plant.")]:
        assert part.replace("plant.", "plant: ") in text


def test_config_title_names_design_friction_compensator_and_changed_values():
    cfg = build_config("slow", "classical", "lugre",
                       sets=["plant.omega0=7.2", "design.observer_omega2=9", "sim.noise=0.002"])
    title = config_title(cfg, "simulate")
    lines = title.split("\n")
    assert lines[0] == "simulate: modified slow design, classical friction, lugre compensator"
    assert "friction: coulomb=1.5, stiction=2.3, zero_velocity_band=0.001" in title
    assert "plant: omega0=7.2" in title and "design: observer_omega2=9" in title
    assert "sim: noise=0.002" in title and "compensation: " in title
    cfg = build_config("fast", "none", sets=["design.gains=-80,-11,-18,-6.5"])
    title = config_title(cfg, width=60)
    assert title.startswith("modified fast design, none friction, no compensation")
    assert "gains=(-80, -11, -18, -6.5)" in title
    assert all(len(line) <= 60 for line in title.split("\n"))
    assert key_label("friction.coulomb") == "friction.coulomb [m/s$^2$]"
    assert key_label("plant.zeta") == "plant.zeta [1]"
    # successive series differ in all of colour, line style and marker
    for a, b in itertools.pairwise(series_style(i) for i in range(8)):
        assert all(a[k] != b[k] for k in ("color", "ls", "marker"))


def test_features_the_plot_shows_are_the_ones_simulate_reports():
    # the sweep panel units follow the features' definitions
    f = run_features(build_config("fast", "classical"), 10.0)
    assert f.period is not None and 0.5 < f.period < 2.0  # seconds, as labelled
    assert np.isfinite(f.peak1) and f.peak1 < np.pi  # radians


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["angle_velocity", "control_friction"])
def test_reproduce_cycle_figures(figures, capsys, tmp_path, kind):
    from frictionlab.plotting import plot_cycle_figure
    from frictionlab.runs import simulate_config

    traj = simulate_config(build_config("fast", "classical"), 4.0)
    trace = {k: traj[k] for k in ("t", "theta_m", "arm_dot_m", "u", "friction")}
    png = tmp_path / "f.png"
    plot_cycle_figure(trace, str(png), kind, "Fig. 17 (simulated): fast design\nF_C 1.5")
    assert _announced(capsys.readouterr().err, png)
    (fig,) = figures
    check_figure(fig, title_has=("fast design",))
