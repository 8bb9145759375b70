"""The plants: one module per plant behind one interface (docs/architecture.md).

``furuta_dc``: the full two-link Furuta pendulum driven by a DC motor (the
QUBE-Servo 2 and 3, a home-built rig), with its controller design in
``furuta_dc_design``.
"""
