"""The model: parameters, plant (eq. 6), friction laws, sensor conversions
(App. B), controller design (Sec. 2.4), observers, controller, the simulator
and the limit-cycle analysis.

The innermost layer: its modules import only numpy, scipy, numba, the
standard library and each other (docs/architecture.md;
``tests/test_architecture.py`` and the import-linter contract check it).
"""
