"""Print markdown tables comparing frictionlab with the thesis's Tables 2-3 and Table 1.

Run: .venv/bin/python docs/scripts/reproduce_tables.py
"""

from frictionlab.config import build_config
from frictionlab.reference import TABLE1, TABLE2, TABLE3, TABLE_COLUMNS
from frictionlab.simulation import run_features

COLS = TABLE_COLUMNS


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
