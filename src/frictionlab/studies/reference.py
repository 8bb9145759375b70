"""Published numbers of the thesis, for comparisons, tests and examples.

Feature tuples are in the order of :data:`TABLE_COLUMNS`
(peak1, peak2, valley, period T, max|u|, max|arm velocity|), SI units.
"""

from __future__ import annotations

__all__ = ["APPENDIX_D", "SIMULATED_PERIODS", "TABLE1", "TABLE2", "TABLE3", "TABLE_COLUMNS"]

TABLE_COLUMNS = ("peak1", "peak2", "valley", "period", "max_u", "max_arm_velocity")

#: Table 1: limit cycles of the real rig (fast and slow designs).
TABLE1 = {
    "fast": (0.080, 0.095, 0.074, 1.1, 4.4, 2.0),
    "slow": (0.18, 0.22, 0.15, 2.1, 6.4, 5.2),
}

#: Table 2: fast design, classical model, F_S = 2.3, F_C varied (key: F_C).
TABLE2 = {
    1.1: (0.143, 0.142, 0.135, 0.888, 6.0, 2.70),
    1.3: (0.157, 0.154, 0.146, 0.901, 6.5, 3.05),
    1.5: (0.172, 0.168, 0.159, 0.911, 7.0, 3.35),
    1.7: (0.187, 0.182, 0.172, 0.916, 7.6, 3.70),
    1.9: (0.199, 0.192, 0.182, 0.921, 8.2, 4.00),
}

#: Table 3: fast design, classical model, F_C = 1.5, F_S varied (key: F_S).
TABLE3 = {
    1.9: (0.169, 0.164, 0.157, 0.920, 6.7, 3.23),
    2.1: (0.171, 0.165, 0.157, 0.916, 6.8, 3.31),
    2.3: (0.173, 0.167, 0.159, 0.910, 7.0, 3.35),
    2.5: (0.176, 0.172, 0.164, 0.900, 7.3, 3.45),
    2.7: (0.178, 0.174, 0.165, 0.897, 7.5, 3.50),
}

#: Sec. 5.2 ("Simulation"): periods of the simulated limit cycles of Figs. 17-18
#: (fast design) and Figs. 19-20 (slow design), classical model with eq. (20).
SIMULATED_PERIODS = {"fast": 0.91, "slow": 3.3}

#: Appendix D: state-feedback gains L and observer gains K as printed.
APPENDIX_D = {
    "fast": ((-86.6267, -11.8530, -19.7987, -6.89851), (28, 65.6235, 0.07002, 0.48280)),
    "slow": ((-31.3510, -4.13566, -1.82609, -1.23275), (28, 65.6235, 0.05251, 0.27396)),
}
