"""Print markdown tables comparing frictionlab with the thesis's Tables 2-3 and Table 1.

Run: .venv/bin/python docs/scripts/reproduce_tables.py
"""

from frictionlab.config import build_config
from frictionlab.simulation import run_features

COLS = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity")
TABLE2 = {1.1: (0.143, 0.142, 0.135, 0.888, 6.0, 2.70), 1.3: (0.157, 0.154, 0.146, 0.901, 6.5, 3.05),
          1.5: (0.172, 0.168, 0.159, 0.911, 7.0, 3.35), 1.7: (0.187, 0.182, 0.172, 0.916, 7.6, 3.70),
          1.9: (0.199, 0.192, 0.182, 0.921, 8.2, 4.00)}
TABLE3 = {1.9: (0.169, 0.164, 0.157, 0.920, 6.7, 3.23), 2.1: (0.171, 0.165, 0.157, 0.916, 6.8, 3.31),
          2.3: (0.173, 0.167, 0.159, 0.910, 7.0, 3.35), 2.5: (0.176, 0.172, 0.164, 0.900, 7.3, 3.45),
          2.7: (0.178, 0.174, 0.165, 0.897, 7.5, 3.50)}
TABLE1 = {"fast": (0.080, 0.095, 0.074, 1.1, 4.4, 2.0), "slow": (0.18, 0.22, 0.15, 2.1, 6.4, 5.2)}


def fmt(v):
    return "-" if v is None else f"{v:.3g}"


def row(f, ref):
    cells = []
    for name, r in zip(COLS, ref, strict=True):
        v = getattr(f, name)
        cells.append(f"{fmt(v)} ({(v - r) / r * 100:+.1f}%)" if v is not None else "-")
    return cells


def main() -> None:
    head = "| {} | peak1 | peak2 | valley | T | max(u) | max(Ω̇) |"
    for title, key, table in (("Table 2 (F_S = 2.3)", "friction.coulomb", TABLE2),
                              ("Table 3 (F_C = 1.5)", "friction.stiction", TABLE3)):
        print(f"\n**{title}**: frictionlab (difference to the thesis)\n")
        print(head.format(key))
        print("|---" * 7 + "|")
        for val, ref in table.items():
            cfg = build_config("fast", "classical", sets=[
                "friction.zero_velocity_band=0.03", f"{key}={val}"])
            print(f"| {val} | " + " | ".join(row(run_features(cfg, 40), ref)) + " |")
    print("\n**Table 1 (real rig) against simulations with a different plant omega0**\n")
    print(head.format("case"))
    print("|---" * 7 + "|")
    for design, sets in (("fast", []), ("fast", ["plant.omega0=7.5", "friction.coulomb=1.3"]),
                         ("slow", []), ("slow", ["plant.omega0=6.1", "friction.coulomb=1.3"])):
        cfg = build_config(design, "classical",
                           sets=["friction.zero_velocity_band=0.03", *sets])
        label = f"{design} " + (", ".join(sets) or "nominal")
        print(f"| {label} | " + " | ".join(row(run_features(cfg, 40), TABLE1[design])) + " |")


if __name__ == "__main__":
    main()
