"""Print the evidence table of docs/model.md, "The observer gain k in the plant".

Which error e does eq. (19)'s term -k e use inside the simulated LuGre plant
(Sec. 5.3, App. F)?  Each of the thesis's three statements about its LuGre
simulations is checked with e = -theta (frictionlab's plant: the balancing
loop's control error, 0 - theta), e = +theta and e = 0 (no term), fast design,
eq. (21) defaults, 40 s runs, features over the last 20 s.

Run: .venv/bin/python docs/scripts/observer_gain_evidence.py
"""

from __future__ import annotations

import dataclasses

from frictionlab.config import Config, build_config
from frictionlab.model.friction import FrictionParams
from frictionlab.runs import run_features

DURATION = 40.0
SIGMA0 = (50.0, 100.0, 200.0)
GAINS = (0.0, 0.5, 1.0, 1.5, 2.0)
#: the classical-model runs the LuGre cycles are compared with (Sec. 5.2's
#: settings: band 0.03 rad/s for the fast design)
FIGS_17_18 = ("fast", "classical", ["friction.zero_velocity_band=0.03"])
FIGS_21_22 = ("fast", "classical", ["friction.zero_velocity_band=0.03", "plant.omega0=7.5",
                                    "friction.coulomb=1.3"])
COMPARED = ("peak1", "period", "max_u", "max_arm_velocity")


@dataclasses.dataclass(frozen=True)
class _PlusTheta(FrictionParams):
    """The counterfactual e = +theta: the same term with the opposite sign (the
    simulator reads e = -theta, so the record's gain is negated)."""

    def record(self, zero_velocity_band=None):
        p = super().record(zero_velocity_band)
        p["k"] = -p["k"]
        return p


ERRORS = ("-theta", "+theta", "0")


def config(error: str, *sets: str) -> Config:
    """Eq. (21) (k = 1 unless ``sets`` change it) with the given error signal."""
    cfg = build_config("fast", "lugre", sets=["friction.observer_gain=1", *sets])
    if error == "0":
        return cfg.with_values({"friction.observer_gain": 0.0})
    if error == "+theta":
        return dataclasses.replace(cfg, friction=_PlusTheta(**{
            f.name: getattr(cfg.friction, f.name) for f in dataclasses.fields(FrictionParams)}))
    return cfg


def fmt(v) -> str:
    return "-" if v is None else f"{v:#.3g}"


def series(feats, name: str, mark: int | None = None) -> str:
    cells = [fmt(getattr(f, name)) for f in feats]
    if mark is not None:
        cells[mark] = f"**{cells[mark]}**"
    return " / ".join(cells)


def extremal(feats, i: int) -> dict[str, bool]:
    """Is entry ``i`` the largest period and the smallest amplitudes?"""
    out = {}
    for name, sign in (("period", 1), ("peak1", -1), ("max_u", -1), ("max_arm_velocity", -1)):
        vals = [sign * getattr(f, name) for f in feats]
        out[name] = all(vals[i] > v for j, v in enumerate(vals) if j != i)
    return out


def resemblance(f, ref) -> str:
    parts = []
    for name in COMPARED:
        a, b = getattr(f, name), getattr(ref, name)
        parts.append(f"{name} {fmt(a)} ({(a - b) / b * 100:+.0f}%)")
    shape = "two peaks" if f.peak2 is not None else "one peak"
    return ", ".join(parts) + f"; {shape}"


def main() -> None:
    sig = {e: [run_features(config(e, f"friction.sigma0={s}"), DURATION) for s in SIGMA0]
           for e in ERRORS}
    gain = {e: [run_features(config(e, f"friction.observer_gain={k}"), DURATION)
                for k in GAINS] for e in ERRORS}
    default = {e: run_features(config(e), DURATION) for e in ERRORS}
    w75 = {e: run_features(config(e, "plant.omega0=7.5"), DURATION) for e in ERRORS}
    ref1718 = run_features(build_config(FIGS_17_18[0], FIGS_17_18[1], sets=FIGS_17_18[2]),
                           DURATION)
    ref2122 = run_features(build_config(FIGS_21_22[0], FIGS_21_22[1], sets=FIGS_21_22[2]),
                           DURATION)

    head = "| check | " + " | ".join(f"e = {e}" for e in ERRORS) + " |"
    print(head)
    print("|---" * (len(ERRORS) + 1) + "|")
    i100 = SIGMA0.index(100.0)
    s0 = " / ".join(f"{s:g}" for s in SIGMA0)
    for name, unit in (("period", "s"), ("peak1", "rad"), ("max_u", "m/s^2"),
                       ("max_arm_velocity", "rad/s")):
        print(f"| sigma0 = {s0}: {name} ({unit}) | "
              + " | ".join(series(sig[e], name, i100) for e in ERRORS) + " |")
    verdicts = []
    for e in ERRORS:
        ex = extremal(sig[e], i100)
        if all(ex.values()):
            verdicts.append("yes: longest period, smallest amplitudes")
        else:
            verdicts.append("no: not extremal in " + ", ".join(k for k, v in ex.items() if not v))
    print("| sigma0 = 100 extremal in amplitudes and period (App. F)? | "
          + " | ".join(verdicts) + " |")
    ks = " / ".join(f"{k:g}" for k in GAINS)
    for name, unit in (("period", "s"), ("peak1", "rad")):
        print(f"| k = {ks}: {name} ({unit}) | "
              + " | ".join(series(gain[e], name) for e in ERRORS) + " |")
    effects = []
    for e in ERRORS:
        p = [f.period for f in gain[e]]
        effects.append("none" if max(p) == min(p) else
                       f"period {(p[-1] - p[0]) / p[0] * 100:+.0f}% from k = 0 to 2")
    print("| k changes the cycle (App. F varies k from 0 to 2)? | " + " | ".join(effects) + " |")
    print("| eq. (21) (k = 1) vs the classical Figs. 17-18 run (T "
          f"{fmt(ref1718.period)} s, peak1 {fmt(ref1718.peak1)} rad, max u "
          f"{fmt(ref1718.max_u)}, max arm speed {fmt(ref1718.max_arm_velocity)}; two peaks) | "
          + " | ".join(resemblance(default[e], ref1718) for e in ERRORS) + " |")
    print("| eq. (21), plant omega0 7.5 vs the classical Figs. 21-22 run (T "
          f"{fmt(ref2122.period)} s, peak1 {fmt(ref2122.peak1)} rad, max u "
          f"{fmt(ref2122.max_u)}, max arm speed {fmt(ref2122.max_arm_velocity)}) | "
          + " | ".join(resemblance(w75[e], ref2122) for e in ERRORS) + " |")


if __name__ == "__main__":
    main()
