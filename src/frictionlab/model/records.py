"""Structured float records: the one mechanism behind the model's typed state and
parameter records (the controller state, the swing-up state, the friction
parameters; docs/architecture.md, "Typed records").

A record type is one float64 per named field (:func:`float_record_dtype`), with
:class:`numpy.record` as its scalar type, so that in Python an element of an
array of it is a record whose fields are attributes.  Compiled code receives a
record by reference and reads and sets its fields by name; a record stored in a
float row (:func:`record_row`, :func:`row_record`; in compiled code
``row.view(dtype)[0]``) is how it crosses a batch's rows or a per-tick call
from Python.  Each owning module names its own helpers after these
(``copy_state``, ``swing_vector``, ``friction_record``...).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["copy_record", "float_record_dtype", "new_record", "record_row", "row_record"]


def float_record_dtype(fields: Sequence[str]) -> np.dtype:
    """The record type with one float64 per name of ``fields``, in that order,
    whose scalars are :class:`numpy.record`."""
    return np.dtype((np.record, np.dtype([(name, np.float64) for name in fields],
                                         align=True)))


def new_record(dtype: np.dtype, **values: float) -> np.record:
    """A zeroed record of ``dtype`` (fields set from ``values``), backed by its
    own one-element array: compiled code may update it in place."""
    arr = np.zeros(1, dtype)
    for name, value in values.items():
        arr[name] = value
    return arr[0]


def copy_record(r: np.record) -> np.record:
    """An independent copy of the record ``r``."""
    arr = np.empty(1, r.dtype)
    arr[0] = r
    return arr[0]


def record_row(r: np.record) -> np.ndarray:
    """The record ``r`` as a float row (a copy, fields in storage order)."""
    return np.array(r.tolist(), dtype=np.float64)


def row_record(x, dtype: np.dtype) -> np.record:
    """The record of ``dtype`` stored in the float64 row ``x``, by reference:
    setting a field, here or in compiled code, writes ``x``."""
    return np.asarray(x, dtype=np.float64).view(dtype)[0]
