"""The model: parameters, plant (eq. 6), friction laws, the sensor model
(App. B), controller design (Sec. 2.4), observers, controller and its
compensators (the adaptive one included), swing-up, the simulator and the
limit-cycle analysis.

The innermost layer: its modules import only numpy, scipy, numba, the
standard library and each other (docs/architecture.md;
``tests/test_architecture.py`` and the import-linter contract check it).
"""
