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
    (:data:`frictionlab.model.simulation.LOGGED`), ASCII columns, one tick a line.
``<run_id>.csv``
    Header ``t,tick,flags,<the ten signals>,y,x,v,u_da,jitter_us,compute_us,rig_us``;
    ``flags`` as in :mod:`frictionlab.realtime.samples`.
``<run_id>.json``
    Sidecar with the run's metadata (parameters, design, gains, stop reason,
    jitter statistics, dropped samples); written at the start, refreshed
    every second by the writer thread and finally at the stop (atomically:
    write a temporary file, then rename).  :func:`read_sidecar` reads it
    back and tells a finished run from one whose process died
    (``"state"``).

``<run_id>.parquet`` (only with ``formats`` holding ``"parquet"``, ``frictionlab run
--log-format parquet``)
    The CSV's columns as an Apache Parquet table (float64; ``tick`` and
    ``flags`` int64), written from the CSV once the run has stopped, with the
    final sidecar in the file's key-value metadata (key ``frictionlab``).
    The .dat/.csv pair stays the crash-safe record: a run that dies leaves
    them and no Parquet file (:func:`write_parquet` converts one later).

A *recording* (the thesis's Save button) writes the same formats for a
stretch of the run to ``<name>.dat``/``<name>.csv`` (and ``<name>.parquet``).

No silent data loss: files are created exclusively (an existing file of the
same name is never overwritten; a recording's automatic name moves on to the
next free number, a rename to an existing name is refused).  When a write
fails (a full disk, a file-size limit, an I/O error) the writer cuts both
files back to their last complete row, stops writing, records the error and
calls ``on_error`` once, with which the controller stops the run (reason
``log_failed``).  So that the final sidecar can still be written on a full
disk, :data:`RESERVE_BYTES` are set aside next to it at the start
(``.<run_id>.reserve``) and released if the last write needs them.
"""

from __future__ import annotations

import errno
import json
import os
import re
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path

from ..io.jsonsafe import json_safe
from ..io.logs import read_log
from ..model.simulation import DAT_LINE, LOGGED
from .samples import Sample

__all__ = [
    "CSV_HEADER",
    "LOG_FORMATS",
    "RESERVE_BYTES",
    "LogWriter",
    "link_no_clobber",
    "read_sidecar",
    "write_json_atomic",
    "write_parquet",
    "writer_identity",
]

CSV_HEADER = ("t,tick,flags," + ",".join(LOGGED)
              + ",y,x,v,u_da,jitter_us,compute_us,rig_us\n")
_CSV_FMT = "%.6f,%d,%d," + ",".join(["%.9g"] * 14) + ",%.1f,%.1f,%.1f\n"
#: The log formats of ``frictionlab run --log-format`` (.dat/.csv are always written).
LOG_FORMATS = ("csv", "parquet")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
#: Disk space set aside at a run's start for its final sidecar (released only if needed).
RESERVE_BYTES = 256 << 10
#: A running run's sidecar is refreshed every second; one older than this, written on
#: another host, counts as interrupted (:func:`read_sidecar`).
STALE_AFTER_S = 10.0
# the raw writes of every log file go through these (tests inject a full disk here)
_write = os.write
_fallocate = os.posix_fallocate


def write_json_atomic(path: Path, obj: dict) -> None:
    """Write ``obj`` as JSON to ``path`` via a temporary file and a rename."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    data = (json.dumps(json_safe(obj), indent=1, default=str) + "\n").encode()
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        _write_all(fd, data)
    except BaseException:
        os.close(fd)
        os.unlink(tmp)
        raise
    os.close(fd)
    os.replace(tmp, path)


def _boot_id() -> str | None:
    try:
        with open("/proc/sys/kernel/random/boot_id") as fh:
            return fh.read().strip()
    except OSError:
        return None


def _process_start(pid) -> str | None:
    """Start time of process ``pid`` (clock ticks since boot), None if it does not exist."""
    try:
        with open(f"/proc/{int(pid)}/stat") as fh:
            return fh.read().rpartition(")")[2].split()[19]
    except (OSError, ValueError, TypeError, IndexError):
        return None


def writer_identity() -> dict:
    """Who writes a sidecar: host, boot, process id and start time (for :func:`read_sidecar`)."""
    pid = os.getpid()
    return {"host": socket.gethostname(), "boot_id": _boot_id(), "pid": pid,
            "process_start": _process_start(pid)}


def read_sidecar(path) -> dict:
    """Read a run's JSON sidecar and say whether the run finished.

    Returns the sidecar's content with ``"state"`` added:

    ``"finished"``
        the run ended and its final sidecar was written (``running`` false;
        ``stop_reason`` says why it ended);
    ``"running"``
        the process writing it is still alive (same host and boot, the same
        process id with the same start time; on another host: refreshed
        within the last :data:`STALE_AFTER_S` seconds);
    ``"interrupted"``
        ``running`` is still true but the process that wrote it is gone (it
        was killed or crashed, or the machine went down): the log files hold
        the run up to its last write, the sidecar its last refresh.
    """
    with open(path) as fh:
        meta = json.load(fh)
    if not meta.get("running"):
        state = "finished"
    else:
        w = meta.get("writer") or {}
        here = writer_identity()
        if w.get("host") == here["host"] and w.get("boot_id") == here["boot_id"] is not None:
            alive = (w.get("process_start") is not None
                     and _process_start(w.get("pid")) == w["process_start"])
        else:
            updated = meta.get("updated")
            alive = (isinstance(updated, int | float)
                     and time.time() - updated < STALE_AFTER_S)
        state = "running" if alive else "interrupted"
    meta["state"] = state
    return meta


def write_parquet(csv_path, meta: dict | None = None) -> Path:
    """Convert a CSV log (a run's or a recording's) to ``<stem>.parquet`` beside it.

    The columns keep their names; ``tick`` and ``flags`` are int64, the rest
    float64.  ``meta`` (the sidecar) goes into the file's key-value metadata
    under ``frictionlab`` as JSON.  An existing ``.parquet`` is never
    overwritten (``FileExistsError``).
    """
    import pyarrow as pa  # a dependency; imported here, off the loop's start-up path
    import pyarrow.parquet as pq

    csv_path = Path(csv_path)
    out = csv_path.with_suffix(".parquet")
    if os.path.lexists(out):
        raise FileExistsError(errno.EEXIST, "File exists", str(out))
    cols = read_log(csv_path, partial=True)
    arrays = {k: (v.astype("int64") if k in ("tick", "flags") else v) for k, v in cols.items()}
    table = pa.table(arrays)
    if meta is not None:
        table = table.replace_schema_metadata(
            {"frictionlab": json.dumps(json_safe(meta), allow_nan=False)})
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        pq.write_table(table, tmp)
        link_no_clobber(tmp, out)
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)
    return out


class _Files:
    """A new .dat/.csv pair (created exclusively: an existing file raises
    ``FileExistsError`` and is left alone), written with raw file descriptors."""

    def __init__(self, stem: Path):
        self.stem = stem
        self.dat = stem.with_suffix(".dat")
        self.csv = stem.with_suffix(".csv")
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND
        self.fd_dat = os.open(self.dat, flags, 0o644)
        try:
            self.fd_csv = os.open(self.csv, flags, 0o644)
        except BaseException:
            os.close(self.fd_dat)
            os.unlink(self.dat)
            raise
        self.size_dat = self.size_csv = 0
        try:
            self.write("", CSV_HEADER, False)
        except BaseException:
            self.close()
            raise

    def write(self, dat: str, csv: str, fsync: bool) -> None:
        """Append rows to both files; on failure cut both back to their last complete
        row (so they hold the same rows) and raise."""
        d, c = dat.encode(), csv.encode()
        try:
            _write_all(self.fd_dat, d)
            _write_all(self.fd_csv, c)
            if fsync:
                os.fsync(self.fd_dat)
                os.fsync(self.fd_csv)
        except OSError:
            for fd, size in ((self.fd_dat, self.size_dat), (self.fd_csv, self.size_csv)):
                try:
                    os.ftruncate(fd, size)  # needs no space
                except OSError:
                    pass
            raise
        self.size_dat += len(d)
        self.size_csv += len(c)

    def close(self) -> None:
        try:
            os.close(self.fd_dat)
        finally:
            os.close(self.fd_csv)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = _write(fd, view)
        view = view[n:]


def link_no_clobber(src: Path, dst: Path) -> None:
    """Rename ``src`` to ``dst`` unless ``dst`` exists (``FileExistsError``), atomically."""
    try:
        os.link(src, dst)
    except FileExistsError:
        raise
    except OSError:  # a file system without hard links
        if os.path.lexists(dst):
            raise FileExistsError(errno.EEXIST, "File exists", str(dst)) from None
        os.rename(src, dst)
        return
    os.unlink(src)


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
        Stem of the run's files.  They must not exist yet
        (``FileExistsError``: nothing is overwritten).
    flush_interval : float
        Seconds between writes (at most 0.1; default 0.05).
    maxsize : int
        Queue bound in samples (default: 60 s at 200 Hz); overflow is
        dropped and counted.
    fsync : bool
        ``os.fsync`` after every write.
    meta_fn : callable, optional
        Returns the sidecar's content; called every ``meta_interval`` s.
    on_error : callable, optional
        ``on_error(message)``, called once from the writer thread when a
        write of the log (or of a recording) fails; nothing more is written
        after that (see the module docstring).
    formats : tuple of str
        :data:`LOG_FORMATS` to write: ``("csv",)`` (default) or with
        ``"parquet"``: the run's and every recording's CSV is also converted
        to Parquet when it ends (off the tick: at :meth:`close` and on the
        writer thread).  A failed conversion is reported in the sidecar
        (``parquet_error``) and does not stop the run; the CSV stays.
    """

    def __init__(self, log_dir, run_id: str, *, flush_interval: float = 0.05,
                 maxsize: int = 12_000, fsync: bool = False,
                 meta_fn: Callable[[], dict] | None = None, meta_interval: float = 1.0,
                 on_error: Callable[[str], None] | None = None,
                 formats: tuple[str, ...] = ("csv",)):
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
        self.on_error = on_error
        bad = [f for f in formats if f not in LOG_FORMATS]
        if bad:
            raise ValueError(f"log formats must be among {LOG_FORMATS}, got {bad}")
        self.parquet = "parquet" in formats
        self.parquet_error: str | None = None
        self.dropped = 0
        self.written = 0
        self.error: str | None = None
        self.failed: str | None = None
        self.json_path = self.dir / f"{run_id}.json"
        if os.path.lexists(self.json_path):
            raise FileExistsError(errno.EEXIST, "File exists", str(self.json_path))
        self._q: deque = deque()
        self._files = _Files(self.dir / run_id)
        self._reserve: Path | None = self._make_reserve(self.dir / f".{run_id}.reserve")
        self._rec: _Files | None = None
        self._rec_count = 0
        self._wake = threading.Event()
        self._closing = False
        self._thread = threading.Thread(target=self._run, name="frictionlab-log", daemon=True)
        self.recording = False
        self.last_recording: dict | None = None

    @property
    def paths(self) -> dict:
        paths = {"dat": str(self._files.dat), "csv": str(self._files.csv),
                 "json": str(self.json_path)}
        if self.parquet:
            paths["parquet"] = str(self._files.csv.with_suffix(".parquet"))
        return paths

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

        Returns ``{"dat": path, "csv": path, "rows": n}``.  A name whose
        ``.dat`` or ``.csv`` exists is refused (``FileExistsError``).
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

    def close(self, meta: dict | Callable[[], dict] | None = None) -> None:
        """Write everything queued, the final sidecar, and stop the thread.

        ``meta`` is the final sidecar, or a function returning it, called once
        everything queued has been written (or has failed to be).
        """
        self._closing = True
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)
        if not self._thread.is_alive():
            self._drain()  # anything left (a thread never started, or one that ended early)
        if self.recording:
            self.recording = False
            fut: Future = Future()
            self._q.append(_RecStop(None, fut))
            self._drain()
            if fut.done() and fut.exception() is None:
                self.last_recording = fut.result()
        try:
            self._files.close()
        except OSError as exc:  # e.g. a deferred write error reported at close
            self._fail(f"log write failed: closing {self._files.csv}: {exc}")
        if meta is not None:
            meta = meta() if callable(meta) else meta
            if self.parquet:
                try:
                    write_parquet(self._files.csv, meta)
                except (OSError, ValueError) as exc:
                    self.parquet_error = f"{self._files.csv.with_suffix('.parquet')}: {exc}"
                    meta = {**meta, "parquet_error": self.parquet_error}
            self.write_meta(meta, final=True)
        elif self.parquet:
            try:
                write_parquet(self._files.csv)
            except (OSError, ValueError) as exc:
                self.parquet_error = f"{self._files.csv.with_suffix('.parquet')}: {exc}"
        self._release_reserve()

    def write_meta(self, meta: dict, final: bool = False) -> None:
        """Write the sidecar (atomically).  ``final``: if that fails, release the space
        set aside for it and try once more."""
        try:
            write_json_atomic(self.json_path, meta)
            return
        except OSError as exc:
            error = f"cannot write {self.json_path}: {exc}"
        if final and self._release_reserve():
            try:
                write_json_atomic(self.json_path, meta)
                return
            except OSError as exc:
                error = f"cannot write {self.json_path}: {exc}"
        self.error = error

    @staticmethod
    def _make_reserve(path: Path) -> Path | None:
        """Set :data:`RESERVE_BYTES` aside in ``path`` (best effort: None if refused, e.g.
        by a file-size limit; a full disk has already failed the files' creation)."""
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError:
            return None
        try:
            _fallocate(fd, 0, RESERVE_BYTES)
        except OSError:
            os.close(fd)
            os.unlink(path)
            return None
        os.close(fd)
        return path

    def _release_reserve(self) -> bool:
        """Free the space set aside for the final sidecar; True if there was any."""
        path, self._reserve = self._reserve, None
        if path is None:
            return False
        try:
            os.unlink(path)
        except OSError:
            return False
        return True

    def _fail(self, message: str) -> None:
        """A write failed: remember it, write nothing more, tell the owner (once)."""
        self.error = message
        if self.failed is None:
            self.failed = message
            if self.on_error is not None:
                try:
                    self.on_error(message)
                except Exception:
                    pass

    # --- writer thread ----------------------------------------------------------------

    def _run(self) -> None:
        if self._on_start is not None:
            self._on_start()
        next_meta = time.monotonic() + self.meta_interval
        while True:
            self._wake.wait(self.flush_interval)
            self._wake.clear()
            # read the flag before draining: whatever was queued before close() set it
            # (the loop's STOP row) is written by this drain, however the threads interleave
            closing = self._closing
            self._drain()
            if closing:
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
                dat.append(DAT_LINE % item[3:13])
                csv.append(_CSV_FMT % (item[1], item[0], item[2], *item[3:]))
                continue
            self._flush(dat, csv)
            dat, csv = [], []
            if isinstance(item, _RecStart):
                self._rec = None
                if self.failed is None:
                    self._rec_open()
            elif isinstance(item, _RecStop):
                self._finish_recording(item)
        self._flush(dat, csv)

    def _rec_open(self) -> None:
        """Open the next recording's files under the first free automatic name."""
        while True:
            self._rec_count += 1
            try:
                self._rec = _Files(self.dir / f"{self.run_id}-save{self._rec_count}")
            except FileExistsError:
                continue  # e.g. an earlier recording was named like this one
            except OSError as exc:
                self._fail(f"recording: cannot create its files: {exc}")
                return
            self._rec_rows = 0
            return

    def _flush(self, dat: list[str], csv: list[str]) -> None:
        if not dat:
            return
        if self.failed is not None:
            self.dropped += len(dat)
            return
        d, c = "".join(dat), "".join(csv)
        try:
            self._files.write(d, c, self.fsync)
            self.written += len(dat)
        except OSError as exc:
            self.dropped += len(dat)
            self._fail(f"log write failed: {self._files.stem}.dat/.csv: {exc}")
            return
        if self._rec is not None:
            try:
                self._rec.write(d, c, self.fsync)
                self._rec_rows += len(dat)
            except OSError as exc:
                self._fail(f"recording write failed: {self._rec.stem}.dat/.csv: {exc}")

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
                link_no_clobber(rec.dat, dat)
                try:
                    link_no_clobber(rec.csv, csv)
                except OSError:
                    link_no_clobber(dat, rec.dat)  # back under the automatic name
                    raise
        except OSError as exc:
            stop.future.set_exception(exc)
            return
        result = {"dat": str(dat), "csv": str(csv), "rows": self._rec_rows}
        if self.parquet:
            try:
                result["parquet"] = str(write_parquet(csv))
            except (OSError, ValueError) as exc:
                result["parquet_error"] = str(exc)
        stop.future.set_result(result)
