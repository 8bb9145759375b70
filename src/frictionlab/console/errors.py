"""The console's error answers: ``{"detail": message, "errors": [{"field", "message"}]}``.

Refused changes answer ``422`` and change nothing; every error names the
request field it is about (the page shows it beside that field).  Changes the
model predicts unsafe answer ``422`` with ``confirm_required`` (and the check's
numbers) unless the request has ``"confirm": true`` (:func:`change_error`).
"""

from __future__ import annotations

from fastapi import HTTPException

from ..realtime.params import ChangeError, UnsafeChange
from .models import request_field

__all__ = ["VERDICT_TEXT", "change_error", "http_error"]


def http_error(status: int, message: str, field: str | None = None) -> HTTPException:
    """An error answer ``{"detail", "errors"}``, located at ``field`` when given."""
    return HTTPException(status, detail={"detail": message,
                                         "errors": [{"field": field, "message": message}]
                                         if field else []})


def change_error(exc: ChangeError) -> HTTPException:
    """422 for a refused change, each refused key located at its request field.

    An :class:`~frictionlab.realtime.params.UnsafeChange` also carries the
    model's diagnostics (``check``), what would pass (``safe``, by request
    field) and ``confirm_required``: the same request with ``"confirm": true``
    applies it anyway.
    """
    message = str(exc)
    fields = [request_field(k) for k in exc.keys]
    if not isinstance(exc, UnsafeChange):
        return HTTPException(422, detail={"detail": message, "errors": [
            {"field": f, "message": message} for f in fields]})
    check = exc.check
    summary = VERDICT_TEXT[check.verdict](check)
    values = exc.safe.get("values", {})
    errors = []
    for key, f in zip(exc.keys, fields, strict=True):
        text = summary
        if key in values:
            text += f"; the check passes up to {values[key]:g}"
        elif key == "error_signal" and "error_signals" in exc.safe:
            text += "; passing: " + (", ".join(exc.safe["error_signals"]) or "none")
        errors.append({"field": f, "message": text})
    safe = {request_field(k): v for k, v in values.items()}
    if "error_signals" in exc.safe:
        safe["error_signal"] = exc.safe["error_signals"]
    return HTTPException(422, detail={"detail": message, "errors": errors,
                                      "confirm_required": True, "check": check.to_json(),
                                      "safe": safe})


#: Short reasons beside a field, from a check's verdict and numbers.
VERDICT_TEXT = {
    "unstable": lambda c: (f"the loop would be unstable (eigenvalue modulus "
                           f"{c.spectral_radius:.4g} > 1)" if c.spectral_radius > 1 else
                           f"the loop would have no stability margin (eigenvalue modulus "
                           f"{c.spectral_radius:.6g}: its slowest mode hardly decays)"),
    "compensator_unstable": lambda c: f"the compensator would make the loop unstable "
                                      f"(spectral radius {c.compensator_radius:.4g} > 1)",
    "saturating": lambda c: f"u would saturate (predicted peak {c.peak_u:.3g} > "
                            f"{c.u_max:.3g} m/s^2)",
    "falls": lambda c: "the simulated pendulum would fall (" + c.reasons[0].split(", ")[-1]
                       + ")",
    "ok": lambda c: "passes",
}
