"""The one JSON sanitiser: what every JSON the package writes goes through
(``--json`` output, reports, the run log's sidecar, the console's API and
stream)."""

from __future__ import annotations

import math
from pathlib import PurePath

__all__ = ["json_safe"]


def json_safe(obj):
    """A JSON-safe copy of ``obj``: NaN and infinities become None (JSON has no
    such numbers), tuples lists, mapping keys and paths strings; everything
    else is returned as is."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, PurePath):
        return str(obj)
    return obj
