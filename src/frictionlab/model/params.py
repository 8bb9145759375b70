"""Validated frozen parameter dataclasses (private helpers).

Every parameter field carries its documentation, unit and allowed range in the
dataclass field metadata (in the spirit of Drake's parameter files).  The
``Validated.__post_init__`` hook checks every field and raises a
:class:`ParamError` (a ``ValueError``) that names the field and its allowed
range; the command line turns it into exit status 2 and one line on stderr.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from typing import Any

__all__ = ["ParamError", "Validated", "check_range", "param"]


class ParamError(ValueError):
    """A parameter value of the wrong type or outside its allowed range.

    Attributes
    ----------
    field : str
        The parameter's name (a configuration key such as ``plant.omega0``, or
        a function argument such as ``hold``).
    value
        The value given.
    allowed : str
        The allowed range, e.g. ``(0, 60]``.
    """

    def __init__(self, field: str, value: Any, allowed: str, message: str | None = None):
        self.field, self.value, self.allowed = field, value, allowed
        super().__init__(message or f"{field} = {_show(value)} is out of range; "
                                    f"allowed {allowed}")


def _show(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, int) and abs(value) >= 10**30:
        sign = "-" if value < 0 else ""
        return f"{sign}an integer of about {int(abs(value).bit_length() * 0.30103)} digits"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_range(field: str, value: Any, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False,
                integer: bool = False) -> float:
    """Check a number against ``[lo, hi]`` (open ends as asked); return it as float
    (int when ``integer``).  Raises :class:`ParamError` naming ``field``."""
    if type(value) is float and not integer and value - value == 0.0 and (
            lo is None or value > lo or (value == lo and not lo_open)) and (
            hi is None or value < hi or (value == hi and not hi_open)):
        return value  # the usual case, a finite float inside the range, at once
    # the range's text is built only for an error (a sweep validates every field
    # of every parameter set)
    def allowed() -> str:
        return range_text({"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open,
                           "integer": integer})

    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParamError(field, value, allowed(),
                         f"{field} must be a number, got {_show(value)}; allowed {allowed()}")
    if isinstance(value, float):  # (ints compare exactly, however large)
        if math.isnan(value):
            raise ParamError(field, value, allowed(), f"{field} is NaN; allowed {allowed()}")
        if integer and (math.isinf(value) or not value.is_integer()):
            raise ParamError(field, value, allowed(), f"{field} must be an integer, got "
                                                      f"{_show(value)}; allowed {allowed()}")
    bad = ((lo is not None and (value < lo or (lo_open and value == lo)))
           or (hi is not None and (value > hi or (hi_open and value == hi)))
           or (isinstance(value, float) and math.isinf(value)
               and not ((lo is None and value < 0) or (hi is None and value > 0))))
    if bad:
        raise ParamError(field, value, allowed())
    return int(value) if integer else float(value)


def param(
    default: Any,
    doc: str,
    unit: str = "",
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
    optional: bool = False,
    length: int | None = None,
) -> Any:
    """Declare a documented, range-checked parameter field.

    Parameters
    ----------
    default
        Default value (the thesis value where it gives one).
    doc
        One-line meaning, with the thesis symbol.
    unit
        SI unit (or "units of u" = m/s^2 for friction levels).
    lo, hi
        Bounds of the allowed range (None = unbounded).
    lo_open, hi_open
        Whether the bound itself is excluded.
    integer
        The value must be an integer.
    optional
        ``None`` is allowed (meaning "not used / same as ...").
    length
        The value is a vector of this many finite numbers (stored as a tuple
        of floats); ``lo``/``hi`` then do not apply.
    """
    meta = {
        "doc": doc,
        "unit": unit,
        "lo": lo,
        "hi": hi,
        "lo_open": lo_open,
        "hi_open": hi_open,
        "integer": integer,
        "optional": optional,
        "length": length,
    }
    return dataclasses.field(default=default, metadata=meta)


def range_text(meta: dict) -> str:
    """Human-readable allowed range of a field, e.g. ``(0, 1]``."""
    if meta.get("length"):
        return f"{meta['length']} finite numbers"
    lo, hi = meta["lo"], meta["hi"]
    left = "(" if (lo is None or meta["lo_open"]) else "["
    right = ")" if (hi is None or meta["hi_open"]) else "]"
    integer = meta["integer"]
    lo_s = "-inf" if lo is None else _bound(lo, integer)
    hi_s = "inf" if hi is None else _bound(hi, integer)
    kind = "integer in " if integer else ""
    return f"{kind}{left}{lo_s}, {hi_s}{right}"


def _vector(name: str, value: Any, meta: dict) -> tuple[float, ...]:
    """``value`` as a tuple of ``meta["length"]`` finite floats, or a ParamError."""
    n = meta["length"]
    try:
        items = list(value)
    except TypeError:
        items = None
    if items is None or len(items) != n or any(
            isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v)
            for v in items):
        raise ParamError(name, value, range_text(meta),
                         f"{name} must be {n} finite numbers, got {_show(value)}")
    return tuple(float(v) for v in items)


def _bound(v: float, integer: bool) -> str:
    return str(int(v)) if integer and float(v).is_integer() else f"{v:g}"


@functools.cache
def _param_fields(cls: type) -> tuple[tuple[str, Any], ...]:
    """``(name, metadata)`` of the ``param`` fields of a dataclass, in order (looked
    up once per class)."""
    return tuple((f.name, f.metadata) for f in dataclasses.fields(cls) if "doc" in f.metadata)


class Validated:
    """Mixin: validate every ``param`` field of a frozen dataclass on construction."""

    _prefix = ""  # config-key prefix used in error messages, e.g. "plant."

    def __post_init__(self) -> None:
        for fname, meta in _param_fields(type(self)):
            value = getattr(self, fname)
            name = f"{self._prefix}{fname}"
            if value is None:
                if meta["optional"]:
                    continue
                raise ParamError(name, value, range_text(meta),
                                 f"{name} must be set; allowed range {range_text(meta)}")
            if meta.get("length"):
                object.__setattr__(self, fname, _vector(name, value, meta))
                continue
            value = check_range(name, value, meta["lo"], meta["hi"], lo_open=meta["lo_open"],
                                hi_open=meta["hi_open"], integer=meta["integer"])
            object.__setattr__(self, fname, value)

    @classmethod
    def describe(cls) -> list[tuple[str, str, str, str]]:
        """(field, doc, unit, allowed range) for every parameter field."""
        rows = []
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if "doc" in f.metadata:
                m = f.metadata
                rows.append((f.name, m["doc"], m["unit"], range_text(m)))
        return rows
