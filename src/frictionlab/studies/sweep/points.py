"""The points of a sweep: the varied keys' values (``KEY=V1,V2,...`` or
``KEY=START:STOP:N``) and the parameter sets they make, as a grid or one key at a
time (the thesis's Tables 2-3 and Appendix F)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ...config import Config, ConfigError, ConfigValueError, UnknownKeyError, valid_keys

__all__ = ["MAX_POINTS", "MODES", "VARY_FORMS", "make_points", "parse_vary", "point_ident",
           "validate_points"]

#: Sweep modes: Cartesian product of the value lists, or one key at a time.
MODES = ("grid", "oat")
#: Most parameter sets in one sweep (and values of one key): the points and
#: their rows are held in memory (about 1 kB a set), so a typing slip such as
#: ``1:2:100000000`` is refused at once instead of exhausting memory; a larger
#: study is several sweeps.
MAX_POINTS = 100_000


#: What a varied key's values may be (the ``allowed`` of a refused one).
VARY_FORMS = "KEY=V1,V2,... or KEY=START:STOP:N"


def _vary_error(value: Any, message: str) -> ConfigValueError:
    """A refused varied key: field ``vary`` (the command line's ``--vary``)."""
    return ConfigValueError("vary", value, VARY_FORMS, message)


def _number(key: str, text: str) -> float:
    t = text.strip()
    if not t:
        raise _vary_error(key, f"{key}: empty value in the list")
    try:
        v = float(t)
    except ValueError:
        raise _vary_error(key, f"{key}: {t!r} is not a number") from None
    if not math.isfinite(v):
        raise _vary_error(key, f"{key}: {t!r} is not a finite number")
    return v


def _tidy(v: float) -> float:
    """Round a computed grid value to 12 significant digits (1.7, not 1.7000000000000002)."""
    return float(f"{v:.12g}")


def parse_vary(text: str, plant: str = "thesis") -> tuple[str, list[float]]:
    """Parse ``KEY=V1,V2,...`` or ``KEY=START:STOP:N`` (N evenly spaced values),
    KEY a key of the plant ``plant`` (a ``--plant`` name).

    ``START:STOP:N`` includes both ends (``N = 1`` gives ``START``); its
    values are rounded to 12 significant digits.

    Raises
    ------
    ConfigError
        Unknown key, empty list, non-numeric value, bad N (at most
        :data:`MAX_POINTS`), duplicate value.
    """
    if "=" not in text:
        raise _vary_error(text, f"expected {VARY_FORMS}, got {text!r}")
    key, spec = (s.strip() for s in text.split("=", 1))
    if key not in valid_keys(plant):
        raise UnknownKeyError(key, field="vary", plant=plant)
    if not spec:
        raise _vary_error(key, f"{key}: empty list of values")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise _vary_error(key, f"{key}: a range is START:STOP:N, got {spec!r}")
        start, stop = _number(key, parts[0]), _number(key, parts[1])
        try:
            n = int(parts[2].strip())
        except ValueError:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be an integer >= 1, "
                                   f"got {parts[2]!r}") from None
        if n < 1:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be >= 1, got {n}")
        if n > MAX_POINTS:
            raise _vary_error(key, f"{key}: N in START:STOP:N must be <= {MAX_POINTS}, "
                              f"got {n}")
        if n == 1:
            values = [start]
        else:
            values = [_tidy(start + (stop - start) * i / (n - 1)) for i in range(n)]
    else:
        values = [_number(key, t) for t in spec.split(",")]
    seen = set()
    for v in values:
        if v in seen:
            raise _vary_error(key, f"{key}: value {v:g} appears twice")
        seen.add(v)
    return key, values


def _as_key_type(base: Config, key: str, value: Any) -> Any:
    """Integer-valued keys (``sim.seed``, ``sim.substeps``) keep integer values."""
    if isinstance(value, float) and value.is_integer():
        current = base.get(key)
        if isinstance(current, int) and not isinstance(current, bool):
            return int(value)
    return value


def make_points(base: Config, varies: Sequence[tuple[str, Sequence[float]]],
                mode: str = "grid") -> list[dict[str, Any]]:
    """The parameter sets of a sweep.

    Parameters
    ----------
    base : Config
        The configuration every point modifies.
    varies : sequence of (key, values)
        As returned by :func:`parse_vary`, in the order given.
    mode : {"grid", "oat"}
        ``grid``: the Cartesian product (the last key varies fastest).
        ``oat``: one key at a time, the others at their base values, as in
        the thesis's Tables 2-3 and Appendix F; a point that occurs for two
        keys (both at their base values) is run once.

    Returns
    -------
    list of dict
        Each point gives a value for every varied key.
    """
    if mode not in MODES:
        raise ConfigValueError("mode", mode, ", ".join(MODES),
                               f"must be one of {', '.join(MODES)}; got {mode!r}")
    if not varies:
        raise _vary_error(None, "a sweep needs at least one varied key (KEY=VALUES)")
    keys = [k for k, _ in varies]
    for k in keys:
        if keys.count(k) > 1:
            raise _vary_error(k, f"{k} given more than once")
    for k, values in varies:
        if not values:
            raise _vary_error(k, f"{k}: empty list of values")
    sizes = [len(values) for _, values in varies]
    total = math.prod(sizes) if mode == "grid" else sum(sizes)
    if total > MAX_POINTS:
        raise ConfigError(f"the sweep has {total} parameter sets ({' x '.join(map(str, sizes))}"
                          f"{'' if mode == 'grid' else ', one key at a time'}); at most "
                          f"{MAX_POINTS} fit in one sweep: split it into several")
    if mode == "grid":
        points: list[dict[str, Any]] = [{}]
        for k, values in varies:
            points = [{**p, k: _as_key_type(base, k, v)} for p in points for v in values]
        return points
    base_vals = {k: base.get(k) for k in keys}
    out, seen = [], set()
    for k, values in varies:
        for v in values:
            p = {**base_vals, k: _as_key_type(base, k, v)}
            ident = point_ident(p, keys)
            if ident not in seen:
                seen.add(ident)
                out.append(p)
    return out


def validate_points(base: Config, points: Sequence[Mapping[str, Any]]) -> None:
    """Build every point's configuration; raise :class:`ConfigError` at the first bad one."""
    for p in points:
        try:
            base.with_values(p)
        except ValueError as exc:
            raise ConfigError(f"sweep point {describe_point(p)}: {exc}") from None


def describe_point(p: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in p.items())


def point_ident(p: Mapping[str, Any], keys: Sequence[str]) -> tuple:
    """Identity of a point for resume: its varied values as floats (None kept)."""
    return tuple(None if p.get(k) is None else float(p[k]) for k in keys)
