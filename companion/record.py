"""The flight record (``--record DIR``): every recovery round's events, frames and crops, kept on disk.

Layout::

    DIR/<session>/events.jsonl      one JSON object a line: time_unix_s, time_mono_s, seq, kind, fields...
    DIR/<session>/<name>.jpg        images the reasoner saw (frames, crops), RGB in, JPEG on disk
    DIR/<session>/<name>.npy        arrays (depth maps, LiDAR points), ``np.save`` without pickles

Durability: every file is written whole to a temporary file in the same directory, flushed with
``fsync``, then renamed over its final name with ``os.replace`` (atomic on POSIX), and the directory is
fsynced. ``events.jsonl`` is rewritten whole for every event (its content is kept in memory), so a crash
at any instant leaves either the previous complete file or the new complete file: a line is never torn.
The cost is O(file size) per event, fine for the tens to hundreds of events a flight produces.

Size bound: when the whole ``DIR`` exceeds ``max_mb`` MiB, whole entries of ``DIR`` other than the
current session go first, least recently modified first; if the current session alone is still too
big, its oldest images and arrays go; its ``events.jsonl`` is never deleted.

Secrets: ``record_event`` replaces the value of any key containing "key", "token", "secret",
"authorization" or "password" (any case, at any depth) with ``"<redacted>"``, and never writes raw
bytes or secret objects (anything with ``get_secret_value``).

A recording failure must not break a landing: ``OSError`` from the disk is logged and counted in
``FlightRecord.failures`` and the call returns (``save_*`` then return ``None``). Bad arguments (a name
with a path separator, an image of the wrong shape) raise ``ValueError``. The methods are synchronous
and thread-safe; the daemon may call them through ``asyncio.to_thread``.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import re
import shutil
import threading
import time
import uuid
from collections.abc import Mapping
from dataclasses import fields as dataclass_fields
from dataclasses import is_dataclass
from datetime import date, datetime
from enum import Enum
from pathlib import Path, PurePath
from types import TracebackType
from typing import Any, Self

import cv2
import numpy as np
import numpy.typing as npt

__all__ = ["EVENTS_FILE", "REDACTED", "FlightRecord", "NullRecord", "open_record", "read_events"]

EVENTS_FILE = "events.jsonl"
REDACTED = "<redacted>"
_SECRET_KEY_RE = re.compile(r"key|token|secret|authorization|password", re.IGNORECASE)
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")
_RESERVED = frozenset({"time_unix_s", "time_mono_s", "seq", "kind"})
_MAX_DEPTH = 32
_MAX_ARRAY_ITEMS = 4096  # larger arrays in an event are summarised; use save_array for data

_log = logging.getLogger(__name__)


def _clean(value: Any, depth: int = 0) -> Any:
    """A JSON-ready copy of ``value`` with secrets masked and non-finite floats as ``null``."""
    if depth > _MAX_DEPTH:
        return "<too deep>"
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if hasattr(value, "get_secret_value"):  # pydantic SecretStr / SecretBytes
        return REDACTED
    if isinstance(value, Enum):
        return _clean(value.value, depth + 1)
    if isinstance(value, np.generic):
        return _clean(value.item(), depth + 1)
    if isinstance(value, np.ndarray):
        if value.size > _MAX_ARRAY_ITEMS:
            return {"shape": list(value.shape), "dtype": str(value.dtype)}
        return _clean(value.tolist(), depth + 1)
    if isinstance(value, bytes | bytearray | memoryview):
        return f"<{len(value)} bytes>"
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, datetime | date):
        return value.isoformat()
    if isinstance(value, Mapping):
        return {
            str(k): REDACTED if _SECRET_KEY_RE.search(str(k)) else _clean(v, depth + 1)
            for k, v in value.items()
        }
    if is_dataclass(value) and not isinstance(value, type):
        return _clean({f.name: getattr(value, f.name) for f in dataclass_fields(value)}, depth + 1)
    if hasattr(value, "model_dump"):  # pydantic models
        return _clean(value.model_dump(), depth + 1)
    if isinstance(value, list | tuple | set | frozenset):
        return [_clean(v, depth + 1) for v in value]
    return str(value)


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a fsynced temporary file in the same directory and ``os.replace``."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _fsync_dir(path.parent)


def _tree_size(path: Path) -> int:
    """Bytes of the regular files at or under ``path`` (links not followed); vanished files count 0."""
    try:
        st = path.lstat()
    except FileNotFoundError:
        return 0
    if not path.is_dir() or path.is_symlink():
        return st.st_size
    total = 0
    with contextlib.suppress(FileNotFoundError), os.scandir(path) as it:
        for entry in it:
            total += _tree_size(Path(entry.path))
    return total


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _mtime_ns(path: Path) -> int:
    try:
        return path.lstat().st_mtime_ns
    except FileNotFoundError:
        return 0


def read_events(session_dir: Path) -> list[dict[str, Any]]:
    """A session's events in order; a torn last line (a killed writer) and lines that are not JSON
    objects are skipped."""
    events = []
    for line in (session_dir / EVENTS_FILE).read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(row, dict):
            events.append(row)
    return events


class FlightRecord:
    """One session's flight record under ``root/<session>/``, bounded to ``max_mb`` MiB for all of ``root``.

    Args:
        root: the record directory (``--record DIR``); created if missing.
        max_mb: size bound of everything under ``root``, MiB, >= 1.
        session: the session directory name; default ``<UTC time>-<pid>``. An existing session is
            continued: new events are appended after its existing lines.
        jpeg_quality: JPEG quality for ``save_image``, 1..100.
        logger: where write failures and pruning are reported.
    """

    def __init__(
        self,
        root: Path,
        max_mb: int,
        session: str | None = None,
        *,
        jpeg_quality: int = 90,
        logger: logging.Logger | None = None,
    ) -> None:
        if max_mb < 1:
            raise ValueError(f"max_mb must be >= 1, got {max_mb}")
        if not 1 <= jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in 1..100, got {jpeg_quality}")
        if session is not None and _NAME_RE.fullmatch(session) is None:
            raise ValueError(f"session must be a plain name ({_NAME_RE.pattern}), got {session!r}")
        self.root = Path(root)
        self.max_bytes = max_mb * 1024 * 1024
        self.jpeg_quality = jpeg_quality
        self.log = logger or _log
        self.failures = 0
        self._lock = threading.Lock()
        self._closed = False
        self._events: bytes | None = None  # events.jsonl as on disk; loaded on the first event
        self._seq = 0
        self._total_bytes: int | None = None  # running size of root; measured on the first write
        self._warned_own_session = False
        self.root.mkdir(parents=True, exist_ok=True)
        if session is not None:
            self.session = session
            self.session_dir = self.root / session
            self.session_dir.mkdir(exist_ok=True)
        else:
            self.session, self.session_dir = self._new_session_dir()
        self.events_path = self.session_dir / EVENTS_FILE

    def _new_session_dir(self) -> tuple[str, Path]:
        base = f"{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{os.getpid()}"
        for n in range(1, 1000):
            name = base if n == 1 else f"{base}-{n}"
            try:
                (self.root / name).mkdir()
            except FileExistsError:
                continue
            return name, self.root / name
        raise FileExistsError(f"no free session name under {self.root} for {base}")

    def interrupted_alarm(self) -> dict[str, Any] | None:
        """The alarm of the previous session's recovery when that session ended without its outcome
        (the daemon was killed mid-recovery), else ``None``. The previous session is the newest other
        one under ``root`` that recorded anything (session names start with their UTC start time);
        torn lines are skipped."""
        others = sorted(
            p for p in self.root.iterdir() if p.name != self.session and (p / EVENTS_FILE).is_file()
        )
        if not others:
            return None
        pending: dict[str, Any] | None = None
        for row in read_events(others[-1]):
            if row.get("kind") == "alarm":
                pending = row
            elif row.get("kind") == "outcome":
                pending = None
        return pending

    # --- public API ------------------------------------------------------------------------------

    def record_event(self, kind: str, fields: Mapping[str, Any]) -> None:
        """Append one event line ``{"time_unix_s", "time_mono_s", "seq", "kind", **fields}``.

        Raises:
            ValueError: a field uses a reserved name (time_unix_s, time_mono_s, seq, kind).
        """
        clash = _RESERVED.intersection(fields)
        if clash:
            raise ValueError(f"record_event({kind!r}): reserved field names {sorted(clash)}")
        with self._lock:
            self._check_open()
            try:
                if self._events is None:
                    self._events = self._load_events()
                row = {
                    "time_unix_s": time.time(),
                    "time_mono_s": time.monotonic(),
                    "seq": self._seq,
                    "kind": kind,
                    **_clean(dict(fields)),
                }
                line = json.dumps(row, ensure_ascii=False, allow_nan=False, separators=(",", ":")) + "\n"
                content = self._events + line.encode()
                _atomic_write(self.events_path, content)
            except OSError as exc:
                self._failed(f"event {kind!r}", exc)
                return
            self._grow(len(content) - len(self._events))
            self._events = content
            self._seq += 1
            self._enforce_bound()

    def save_image(self, name: str, rgb: npt.NDArray[np.uint8]) -> Path | None:
        """Save an (H, W, 3) uint8 RGB image as ``<name>.jpg``; its path, or ``None`` if the disk failed."""
        path = self._path_for(name, ".jpg", (".jpg", ".jpeg"))
        if not (
            isinstance(rgb, np.ndarray)
            and rgb.dtype == np.uint8
            and rgb.ndim == 3
            and rgb.shape[2] == 3
            and rgb.size > 0
        ):
            shape = getattr(rgb, "shape", None)
            dtype = getattr(rgb, "dtype", type(rgb).__name__)
            raise ValueError(
                f"save_image({name!r}): expected an (H, W, 3) uint8 RGB array, got {shape} {dtype}"
            )
        bgr = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR)
        ok, buf = cv2.imencode(".jpg", bgr, [int(cv2.IMWRITE_JPEG_QUALITY), self.jpeg_quality])
        if not ok:
            raise ValueError(f"save_image({name!r}): JPEG encoding failed for shape {rgb.shape}")
        return self._write(path, bytes(buf))

    def save_array(self, name: str, arr: npt.NDArray[Any]) -> Path | None:
        """Save an array as ``<name>.npy`` (no pickles); returns its path (``None`` if the disk failed)."""
        path = self._path_for(name, ".npy", (".npy",))
        if not isinstance(arr, np.ndarray) or arr.dtype.hasobject:
            raise ValueError(
                f"save_array({name!r}): expected a numeric ndarray, got {getattr(arr, 'dtype', arr)!r}"
            )
        out = io.BytesIO()
        np.save(out, arr, allow_pickle=False)
        return self._write(path, out.getvalue())

    def close(self) -> None:
        """Stop recording; every write is already durable, so nothing is flushed. Idempotent."""
        with self._lock:
            self._closed = True

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"FlightRecord(root={str(self.root)!r}, session={self.session!r}, max_bytes={self.max_bytes})"

    # --- internals -------------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"{self!r} is closed")

    def _failed(self, what: str, exc: OSError) -> None:
        self.failures += 1
        self.log.warning("flight record: could not write %s in %s: %s", what, self.session_dir, exc)

    def _path_for(self, name: str, suffix: str, accepted: tuple[str, ...]) -> Path:
        if _NAME_RE.fullmatch(name) is None:
            raise ValueError(
                f"record file name must match {_NAME_RE.pattern} (no path separators), got {name!r}"
            )
        if not name.lower().endswith(accepted):
            name += suffix
        if name == EVENTS_FILE:
            raise ValueError(f"{EVENTS_FILE!r} is reserved for events")
        return self.session_dir / name

    def _write(self, path: Path, data: bytes) -> Path | None:
        with self._lock:
            self._check_open()
            old = path.stat().st_size if path.exists() else 0
            try:
                _atomic_write(path, data)
            except OSError as exc:
                self._failed(path.name, exc)
                return None
            self._grow(len(data) - old)
            self._enforce_bound()
            return path

    def _load_events(self) -> bytes:
        try:
            data = self.events_path.read_bytes()
        except FileNotFoundError:
            return b""
        # Writes are whole-file replaces, so a partial last line cannot occur; drop one anyway if found.
        if data and not data.endswith(b"\n"):
            data = data[: data.rfind(b"\n") + 1]
        self._seq = data.count(b"\n")
        return data

    def _grow(self, delta: int) -> None:
        if self._total_bytes is not None:
            self._total_bytes += delta

    def _enforce_bound(self) -> None:
        if self._total_bytes is None:
            self._total_bytes = _tree_size(self.root)
        if self._total_bytes <= self.max_bytes:
            return
        # Re-measure before deleting anything: other processes and crash leftovers change the total.
        self._total_bytes = _tree_size(self.root)
        others = [p for p in self.root.iterdir() if p.name != self.session]
        own = [p for p in self.session_dir.iterdir() if p.name != EVENTS_FILE]
        for group in (others, own):
            for path in sorted(group, key=lambda p: (_mtime_ns(p), p.name)):
                if self._total_bytes <= self.max_bytes:
                    return
                if group is own and not self._warned_own_session:
                    self._warned_own_session = True
                    self.log.warning(
                        "flight record: session %s alone exceeds the bound; pruning it", self.session
                    )
                size = _tree_size(path)
                try:
                    _remove(path)
                except OSError as exc:
                    self._failed(f"(pruning {path})", exc)
                    continue
                self._total_bytes -= size
                self.log.info(
                    "flight record: pruned %s (%d bytes) to stay under %d bytes", path, size, self.max_bytes
                )


class NullRecord:
    """The flight record when none is configured: every method does nothing."""

    failures = 0

    def record_event(self, kind: str, fields: Mapping[str, Any]) -> None:
        return None

    def save_image(self, name: str, rgb: npt.NDArray[np.uint8]) -> Path | None:
        return None

    def save_array(self, name: str, arr: npt.NDArray[Any]) -> Path | None:
        return None

    def close(self) -> None:
        return None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def open_record(
    root: Path | None, max_mb: int, session: str | None = None, *, logger: logging.Logger | None = None
) -> FlightRecord | NullRecord:
    """A :class:`FlightRecord` under ``root``, or a :class:`NullRecord` when ``root`` is ``None``."""
    if root is None:
        return NullRecord()
    return FlightRecord(root, max_mb, session, logger=logger)
