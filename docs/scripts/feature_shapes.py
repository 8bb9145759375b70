"""The two top shapes of the limit-cycle features (docs/cli.md, "Features"):
a shallow double top (peak1, valley, peak2) and a shoulder (peak1, peak2, no
valley), each one half-cycle of a `frictionlab simulate` run with the points
the feature extraction found.

    .venv/bin/python docs/scripts/feature_shapes.py   # writes docs/figures/features_*.png
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from frictionlab.config import build_config
from frictionlab.model.limit_cycles import features

OUT = Path(__file__).resolve().parent.parent / "figures"
#: (file, title, --set of a LuGre eq. (21) run with k = 1, fast design)
CASES = (
    ("features_double_top.png", "A shallow double top: LuGre eq. (21), F_S = 1.9",
     ("friction.observer_gain=1", "friction.stiction=1.9")),
    ("features_shoulder.png", "A shoulder: LuGre eq. (21), sigma1 = 0",
     ("friction.observer_gain=1", "friction.sigma1=0")),
)


def one(path: Path, title: str, sets) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from frictionlab.runs import simulate_config

    traj = simulate_config(build_config("fast", "lugre", sets=sets), 40.0)
    t, y = traj.t, traj["theta_m"]
    f = features(t, y, window=20.0)
    # the last whole positive half-cycle
    up = np.flatnonzero((y[:-1] <= 0) & (y[1:] > 0))
    dn = np.flatnonzero((y[:-1] > 0) & (y[1:] <= 0))
    a = up[-2]
    b = dn[dn > a][0] + 1
    fig, ax = plt.subplots(figsize=(6.4, 3.6), constrained_layout=True)
    ax.plot(t[a:b] - t[a], y[a:b], "k.-", lw=0.8, ms=3, label="measured angle")
    for name, style in (("peak1", "C1--"), ("peak2", "C3:"), ("valley", "C2-.")):
        v = getattr(f, name)
        label = f"{name} = {v:.4f} rad" if v is not None else f"{name}: none"
        if v is not None:
            ax.axhline(v, color=style[:2], ls=style[2:], lw=1.2, label=label)
        else:
            ax.plot([], [], " ", label=label)
    top = y[a:b].max()
    ax.set_ylim(0.75 * top, 1.03 * top)
    ax.set_xlabel("time from the upward zero crossing (s)")
    ax.set_ylabel("theta_m (rad)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(path, f.peak1, f.peak2, f.valley)


def main() -> None:
    for name, title, sets in CASES:
        one(OUT / name, title, sets)


if __name__ == "__main__":
    main()
