"""A stand-in for Quanser's ``quanser`` Python package, for the test suite only.

Only :mod:`quanser.hardware` is emulated (see its docstring).  The tests put
``tests/fake_quanser`` first on ``sys.path`` / ``PYTHONPATH``; the real SDK is
never needed to run them.
"""
