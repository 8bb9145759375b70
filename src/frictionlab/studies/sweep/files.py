"""A sweep's output files: the CSV written as chunks complete (and read back to
resume), the Parquet file written at the end from its CSV journal, and the sidecar
that refuses to mix results of different set-ups."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ...config import ConfigError, ConfigValueError
from ...model.limit_cycles import FEATURES

__all__ = ["OutputMismatch", "SweepFile", "columns"]


def columns(keys: Sequence[str], extra: Sequence[str] = ()) -> list[str]:
    """CSV columns: the varied keys, the features, ``status``, ``error``, then ``extra``
    (:data:`SWINGUP_COLUMNS` for a swing-up sweep)."""
    return [*keys, *FEATURES, "status", "error", *extra]


class OutputMismatch(ConfigError):
    """An existing output that this sweep cannot continue: its columns or the set-up
    that produced it (its ``.meta.json``) are not this sweep's.  Write another file
    or overwrite it (the command line names its options).

    Attributes
    ----------
    path : str
        The output.
    field : str
        What differs: ``"columns"``, or the set-up's field or key.
    """

    def __init__(self, path: str, field: str, message: str):
        self.path, self.field = path, field
        super().__init__(message)


def _header_mismatch(path: str, found: Sequence[str], cols: Sequence[str]) -> OutputMismatch:
    """The error for an output whose columns are not this sweep's."""
    why = ""
    if sorted(found) == sorted(cols):
        why = (" (the same columns in another order: the file was written by an earlier "
               "frictionlab, status before the features)")
    return OutputMismatch(path, "columns", f"{path} has columns {','.join(found)}; this sweep "
                                           f"writes {','.join(cols)}{why}")


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _parse_cell(col: str, text: str) -> Any:
    if col in ("status", "error"):
        return text if text != "" else None
    if text == "":
        return None
    v = float(text)
    return int(v) if v.is_integer() and "." not in text and "e" not in text.lower() else v


def _parse_csv(text: str, path: str, cols: list[str]) -> list[dict[str, Any]]:
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return []
    if header != cols:
        raise _header_mismatch(path, header, cols)
    rows = []
    for line_no, rec in enumerate(reader, start=2):
        if not rec:
            continue
        if len(rec) != len(cols):
            raise ConfigError(f"{path}:{line_no}: expected {len(cols)} fields, got {len(rec)}")
        try:
            rows.append({c: _parse_cell(c, t) for c, t in zip(cols, rec, strict=True)})
        except ValueError:
            raise ConfigError(f"{path}:{line_no}: not a number in a numeric column") from None
    return rows


class SweepFile:
    """The output of a sweep: incremental crash-safe CSV, resume, final rewrite.

    Parameters
    ----------
    path : str
        ``FILE.csv`` or ``FILE.parquet``.
    keys : sequence of str
        The varied keys (the leading columns).
    meta : dict
        What produced the rows (base configuration, duration, window); stored
        in ``FILE.meta.json`` and compared on resume.
    extra : sequence of str
        Columns after ``error`` (:data:`SWINGUP_COLUMNS`).
    """

    def __init__(self, path: str, keys: Sequence[str], meta: dict, extra: Sequence[str] = ()):
        if not path.endswith((".csv", ".parquet")):
            raise ConfigValueError("path", path, ".csv or .parquet",
                                   f"{path}: the extension must be .csv or .parquet")
        self.path = path
        self.keys = list(keys)
        self.cols = columns(keys, extra)
        self.meta = meta
        self.parquet = path.endswith(".parquet")
        self.journal = path + ".partial.csv" if self.parquet else path
        self.meta_path = path + ".meta.json"
        self._fh: io.TextIOBase | None = None

    def _files(self) -> list[str]:
        return [p for p in dict.fromkeys((self.path, self.journal, self.meta_path))
                if os.path.exists(p)]

    def exists(self) -> bool:
        return bool([p for p in self._files() if p != self.meta_path])

    def remove(self) -> None:
        for p in self._files():
            os.remove(p)

    def load(self) -> list[dict[str, Any]]:
        """Rows already present (for ``--resume``), after checking the set-up matches."""
        if not self.exists():
            return []
        self._check_meta()
        rows: list[dict[str, Any]] = []
        if self.parquet and os.path.exists(self.path):
            rows.extend(self._read_parquet())
        if os.path.exists(self.journal):
            rows.extend(self._read_journal())
        return rows

    def _check_meta(self) -> None:
        if not os.path.exists(self.meta_path):
            return
        try:
            with open(self.meta_path, encoding="utf-8") as fh:
                old = json.load(fh)
        except (OSError, ValueError, RecursionError) as exc:
            raise ConfigError(f"cannot read {self.meta_path}: {exc}") from None
        if not isinstance(old, dict):
            raise ConfigError(f"{self.meta_path} is not a sweep's description (a JSON object)")
        for field in ("keys", "duration", "window"):
            if old.get(field) != self.meta.get(field):
                raise OutputMismatch(
                    self.path, field, f"{self.path} was produced with {field} = "
                    f"{old.get(field)!r}, this sweep has {self.meta.get(field)!r}")
        # compared as stored: a tuple value (design.gains) reads back as a list
        ob, nb = old.get("base"), json.loads(json.dumps(self.meta.get("base", {})))
        ob = ob if isinstance(ob, dict) else {}
        for k in sorted(set(ob) | set(nb)):
            if k in self.keys:
                continue
            if ob.get(k) != nb.get(k):
                raise OutputMismatch(
                    self.path, k, f"{self.path} was produced with {k} = {ob.get(k)!r}, "
                    f"this sweep has {nb.get(k)!r}")

    def _read_journal(self) -> list[dict[str, Any]]:
        with open(self.journal, "rb") as fh:
            data = fh.read()
        end = data.rfind(b"\n") + 1
        if end < len(data):
            # a line cut short by a kill: drop it (its chunk is run again)
            with open(self.journal, "r+b") as fh:
                fh.truncate(end)
            data = data[:end]
        return _parse_csv(data.decode("utf-8"), self.journal, self.cols)

    def _read_parquet(self) -> list[dict[str, Any]]:
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(self.path)
        except Exception as exc:
            raise ConfigError(f"cannot read {self.path}: {exc}") from None
        if table.column_names != self.cols:
            raise _header_mismatch(self.path, table.column_names, self.cols)
        return table.to_pylist()

    def open(self) -> None:
        """Start appending (writing the header and the sidecar when new)."""
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        with open(self.meta_path, "w", encoding="utf-8") as fh:
            json.dump(self.meta, fh, indent=1)
        new = not os.path.exists(self.journal) or os.path.getsize(self.journal) == 0
        self._fh = open(self.journal, "a", encoding="utf-8", newline="")
        if new:
            self._write_lines([self.cols])

    def _write_lines(self, records: list[list[Any]]) -> None:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        for rec in records:
            w.writerow(rec)
        assert self._fh is not None
        self._fh.write(buf.getvalue())
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def append(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Append rows and make them durable (flush + fsync)."""
        self._write_lines([[_fmt(r.get(c)) for c in self.cols] for r in rows])

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def finish(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Replace the output with ``rows`` (sweep order), atomically."""
        self.close()
        tmp = self.path + ".tmp"
        if self.parquet:
            _write_parquet(tmp, rows, self.keys, self.cols)
        else:
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                w = csv.writer(fh, lineterminator="\n")
                w.writerow(self.cols)
                for r in rows:
                    w.writerow([_fmt(r.get(c)) for c in self.cols])
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        if self.parquet and os.path.exists(self.journal):
            os.remove(self.journal)


def _write_parquet(path: str, rows: Sequence[Mapping[str, Any]], keys: Sequence[str],
                   cols: Sequence[str]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = []
    for c in cols:
        if c in ("status", "error"):
            t = pa.string()
        elif c in keys and all(isinstance(r.get(c), int) or r.get(c) is None for r in rows):
            t = pa.int64()
        else:
            t = pa.float64()
        fields.append(pa.field(c, t))
    schema = pa.schema(fields)
    table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows], schema=schema)
    pq.write_table(table, path)
