"""Lossless, crash-safe logging of the loop's samples (Sec. 7.1 "Save Data").

The thesis's controller kept its data in a linked list until exit (Sec. 7.2,
module LinkList); a crash lost everything.  Here the tick hands each sample
to :meth:`LogWriter.put` (a deque append: never blocks, bounded, overflow
counted as dropped) and a writer thread drains the queue every
``flush_interval`` (50 ms), formats the rows and hands them to the kernel
with one ``os.write`` per file.  Data handed to the kernel survives the death
of the process (SIGKILL included): a killed run loses at most the last
``flush_interval`` plus the formatting time.  ``fsync=True`` additionally
forces the data to the disk after every write (surviving a power loss, at
a cost in I/O); it is off by default.

Files of a run ``<run_id>`` in the log directory:

``<run_id>.dat``
    The ten signals of Sec. 7.1 in the thesis's order
    (:data:`frictionlab.simulation.LOGGED`), ASCII columns, one tick a line.
``<run_id>.csv``
    Header ``t,tick,flags,<the ten signals>,y,x,v,u_da,jitter_us,compute_us,rig_us``;
    ``flags`` as in :mod:`frictionlab.realtime.samples`.
``<run_id>.json``
    Sidecar with the run's metadata (parameters, design, gains, stop reason,
    jitter statistics, dropped samples); written at the start, refreshed
    every second by the writer thread and finally at the stop (atomically:
    write a temporary file, then rename).

A *recording* (the thesis's Save button) writes the same two formats for a
stretch of the run to ``<name>.dat``/``<name>.csv``.
"""

from __future__ import annotations

import json
import math
import os
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path

from ..simulation import LOGGED
from .samples import Sample

__all__ = ["CSV_HEADER", "LogWriter", "read_csv_log", "write_json_atomic"]

CSV_HEADER = ("t,tick,flags," + ",".join(LOGGED)
              + ",y,x,v,u_da,jitter_us,compute_us,rig_us\n")
_DAT_FMT = " ".join(["%.9g"] * 10) + "\n"
_CSV_FMT = "%.6f,%d,%d," + ",".join(["%.9g"] * 14) + ",%.1f,%.1f,%.1f\n"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")


def _json_safe(obj):
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    return obj


def write_json_atomic(path: Path, obj: dict) -> None:
    """Write ``obj`` as JSON to ``path`` via a temporary file and a rename."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "w") as fh:
        json.dump(_json_safe(obj), fh, indent=1, default=str)
        fh.write("\n")
    os.replace(tmp, path)


def read_csv_log(path) -> dict:
    """Read a CSV log back: ``{column: ndarray}`` (a truncated last line is ignored)."""
    import numpy as np

    with open(path) as fh:
        header = fh.readline().strip().split(",")
        rows = []
        for line in fh:
            if not line.endswith("\n"):
                break
            rows.append([float(v) for v in line.split(",")])
    arr = np.array(rows, dtype=float).reshape(-1, len(header))
    return {name: arr[:, i] for i, name in enumerate(header)}


class _Files:
    """A .dat/.csv pair opened for appending with raw file descriptors."""

    def __init__(self, stem: Path):
        self.stem = stem
        self.dat = stem.with_suffix(".dat")
        self.csv = stem.with_suffix(".csv")
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_TRUNC
        self.fd_dat = os.open(self.dat, flags, 0o644)
        self.fd_csv = os.open(self.csv, flags, 0o644)
        _write_all(self.fd_csv, CSV_HEADER.encode())

    def write(self, dat: str, csv: str, fsync: bool) -> None:
        _write_all(self.fd_dat, dat.encode())
        _write_all(self.fd_csv, csv.encode())
        if fsync:
            os.fsync(self.fd_dat)
            os.fsync(self.fd_csv)

    def close(self) -> None:
        os.close(self.fd_dat)
        os.close(self.fd_csv)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


class _RecStart:
    pass


class _RecStop:
    def __init__(self, name: str | None, future: Future):
        self.name = name
        self.future = future


class LogWriter:
    """Writer thread streaming samples to ``<log_dir>/<run_id>.dat/.csv``.

    Parameters
    ----------
    log_dir : path
        Directory (created if missing).
    run_id : str
        Stem of the run's files.
    flush_interval : float
        Seconds between writes (at most 0.1; default 0.05).
    maxsize : int
        Queue bound in samples (default: 60 s at 200 Hz); overflow is
        dropped and counted.
    fsync : bool
        ``os.fsync`` after every write.
    meta_fn : callable, optional
        Returns the sidecar's content; called every ``meta_interval`` s.
    """

    def __init__(self, log_dir, run_id: str, *, flush_interval: float = 0.05,
                 maxsize: int = 12_000, fsync: bool = False,
                 meta_fn: Callable[[], dict] | None = None, meta_interval: float = 1.0):
        if not 0 < flush_interval <= 0.1:
            raise ValueError(f"flush_interval must be in (0, 0.1] s, got {flush_interval}")
        self.dir = Path(log_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.run_id = run_id
        self.flush_interval = flush_interval
        self.maxsize = maxsize
        self.fsync = fsync
        self.meta_fn = meta_fn
        self.meta_interval = meta_interval
        self.dropped = 0
        self.written = 0
        self.error: str | None = None
        self.json_path = self.dir / f"{run_id}.json"
        self._q: deque = deque()
        self._files = _Files(self.dir / run_id)
        self._rec: _Files | None = None
        self._rec_count = 0
        self._wake = threading.Event()
        self._closing = False
        self._thread = threading.Thread(target=self._run, name="frictionlab-log", daemon=True)
        self.recording = False
        self.last_recording: dict | None = None

    @property
    def paths(self) -> dict:
        return {"dat": str(self._files.dat), "csv": str(self._files.csv),
                "json": str(self.json_path)}

    def start(self, on_thread_start: Callable[[], None] | None = None) -> None:
        self._on_start = on_thread_start
        self._thread.start()

    # --- tick side (never blocks) -------------------------------------------------

    def put(self, sample: Sample) -> None:
        if len(self._q) >= self.maxsize:
            self.dropped += 1
            return
        self._q.append(sample)

    # --- control (any thread) -----------------------------------------------------

    def record_start(self) -> None:
        """Start a recording (Save Data) with the next sample."""
        if self.recording:
            raise RuntimeError("a recording is already running")
        self.recording = True
        self._q.append(_RecStart())

    def record_stop(self, name: str | None = None, timeout: float = 2.0) -> dict:
        """End the recording; ``name`` (no extension) renames its files.

        Returns ``{"dat": path, "csv": path, "rows": n}``.
        """
        if not self.recording:
            raise RuntimeError("no recording is running")
        if name is not None:
            name = re.sub(r"\.(dat|csv)$", "", name)
            if not _NAME.match(name):
                raise ValueError(f"recording name {name!r}: use letters, digits, '.', '_', "
                                 "'-' (no path)")
            for ext in (".dat", ".csv"):
                if (self.dir / (name + ext)).exists():
                    raise FileExistsError(f"{self.dir / (name + ext)} exists")
        fut: Future = Future()
        self.recording = False
        self._q.append(_RecStop(name, fut))
        self._wake.set()
        if not self._thread.is_alive():
            self._drain()
        return fut.result(timeout=timeout)

    def close(self, meta: dict | None = None) -> None:
        """Write everything queued, the final sidecar, and stop the thread."""
        self._closing = True
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)
        else:
            self._drain()
        if self.recording:
            self.recording = False
            fut: Future = Future()
            self._q.append(_RecStop(None, fut))
            self._drain()
            if fut.done() and fut.exception() is None:
                self.last_recording = fut.result()
        self._files.close()
        if meta is not None:
            self.write_meta(meta)

    def write_meta(self, meta: dict) -> None:
        try:
            write_json_atomic(self.json_path, meta)
        except OSError as exc:
            self.error = f"cannot write {self.json_path}: {exc}"

    # --- writer thread ----------------------------------------------------------------

    def _run(self) -> None:
        if self._on_start is not None:
            self._on_start()
        next_meta = time.monotonic() + self.meta_interval
        while True:
            self._wake.wait(self.flush_interval)
            self._wake.clear()
            self._drain()
            if self._closing:
                return
            if self.meta_fn is not None and time.monotonic() >= next_meta:
                next_meta = time.monotonic() + self.meta_interval
                try:
                    self.write_meta(self.meta_fn())
                except Exception as exc:
                    self.error = f"sidecar: {exc!r}"

    def _drain(self) -> None:
        q = self._q
        dat: list[str] = []
        csv: list[str] = []
        while q:
            item = q.popleft()
            if isinstance(item, Sample):
                dat.append(_DAT_FMT % item[3:13])
                csv.append(_CSV_FMT % (item[1], item[0], item[2], *item[3:]))
                continue
            self._flush(dat, csv)
            dat, csv = [], []
            if isinstance(item, _RecStart):
                self._rec_count += 1
                try:
                    self._rec = _Files(self.dir / f"{self.run_id}-save{self._rec_count}")
                    self._rec_rows = 0
                except OSError as exc:
                    self.error = f"recording: {exc}"
                    self._rec = None
            elif isinstance(item, _RecStop):
                self._finish_recording(item)
        self._flush(dat, csv)

    def _flush(self, dat: list[str], csv: list[str]) -> None:
        if not dat:
            return
        d, c = "".join(dat), "".join(csv)
        try:
            self._files.write(d, c, self.fsync)
            self.written += len(dat)
        except OSError as exc:
            self.error = f"log write failed: {exc}"
            self.dropped += len(dat)
        if self._rec is not None:
            try:
                self._rec.write(d, c, self.fsync)
                self._rec_rows += len(dat)
            except OSError as exc:
                self.error = f"recording write failed: {exc}"

    def _finish_recording(self, stop: _RecStop) -> None:
        rec = self._rec
        self._rec = None
        if rec is None:
            stop.future.set_exception(RuntimeError(self.error or "the recording failed"))
            return
        rec.close()
        dat, csv = rec.dat, rec.csv
        try:
            if stop.name is not None:
                dat = self.dir / f"{stop.name}.dat"
                csv = self.dir / f"{stop.name}.csv"
                os.replace(rec.dat, dat)
                os.replace(rec.csv, csv)
        except OSError as exc:
            stop.future.set_exception(exc)
            return
        stop.future.set_result({"dat": str(dat), "csv": str(csv), "rows": self._rec_rows})
