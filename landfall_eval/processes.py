"""The processes of an episode, seen from the harness: started so that they die with it
(:func:`die_with_parent`), counted while in flight so that a campaign being interrupted can stop them
all (:func:`stop_running_episodes`), stopped, sampled for memory and CPU time (:class:`ProcessSample`),
their files read as they write them (:class:`LineTail`, :class:`JsonlTail`), and the alarm sent to the
companion (:func:`send_alarm`). :mod:`landfall_eval.episode` runs an episode with these.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

__all__ = [
    "STOPPING",
    "JsonlTail",
    "LineTail",
    "ProcessSample",
    "die_with_parent",
    "free_port",
    "running",
    "send_alarm",
    "sped_up_env",
    "stop_process",
    "stop_running_episodes",
    "track",
    "untrack",
]

# resolved once here: the child of a fork runs ``die_with_parent`` with nothing to import or look up
_PRCTL = ctypes.CDLL(None, use_errno=True).prctl if sys.platform == "linux" else None


@dataclass(slots=True)
class ProcessSample:
    """Peak resident memory and CPU time of a process, sampled from /proc (zeros elsewhere).

    The peak is the kernel's own high-water mark (``VmHWM``), so a peak between two samples counts too;
    ``VmRSS``, the resident memory at the sample, only where a kernel does not report it. Resident memory
    includes the pages of shared libraries mapped from files, and how many of those a process holds
    depends on the page cache (a fresh install's libraries, just written, come in large folios and map
    tens of MB more: OpenCV and ONNX Runtime 44 against 17 MB, same files); ``peak_anon_mb``, the highest
    sampled ``RssAnon``, is the process's own memory alone."""

    pid: int
    peak_rss_mb: float = 0.0
    peak_anon_mb: float = 0.0
    cpu_s: float = 0.0
    _tick: float = field(default_factory=lambda: float(os.sysconf("SC_CLK_TCK")))

    def sample(self) -> None:
        try:
            status = Path(f"/proc/{self.pid}/status").read_text()
            stat = Path(f"/proc/{self.pid}/stat").read_text()
        except OSError:
            return
        for line in status.splitlines():
            if line.startswith(("VmHWM:", "VmRSS:")):
                self.peak_rss_mb = max(self.peak_rss_mb, int(line.split()[1]) / 1024)
            elif line.startswith("RssAnon:"):
                self.peak_anon_mb = max(self.peak_anon_mb, int(line.split()[1]) / 1024)
        fields = stat.rsplit(")", 1)[1].split()
        self.cpu_s = (int(fields[11]) + int(fields[12])) / self._tick  # utime + stime


class LineTail:
    """Reads the lines another process appends to a text file, as they come (no line read twice; a
    line still being written waits for its newline)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fh: TextIO | None = None
        self._partial = ""

    def text_lines(self) -> list[str]:
        if self._fh is None:
            if not self.path.exists():
                return []
            self._fh = self.path.open("r", encoding="utf-8", errors="replace")
        text = self._partial + self._fh.read()
        rows, _, self._partial = text.rpartition("\n")
        return rows.splitlines()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()


class JsonlTail(LineTail):
    """Reads the JSON lines another process appends to a file, as they come (no line read twice)."""

    def lines(self) -> list[dict[str, Any]]:
        out = []
        for line in self.text_lines():
            if line.strip():
                try:
                    out.append(json.loads(line))
                except json.JSONDecodeError:
                    continue  # a torn line from a killed writer: nothing to grade in it
        return out


def sped_up_env(speed: float) -> dict[str, str]:
    """The companion's environment for a simulation at ``speed`` x: a frame's age is counted in
    simulated seconds, so the default 2 s tolerance becomes 2 s of wall clock at any speed."""
    return {"LANDFALL_SENSORS_MAX_FRAME_AGE_S": str(2.0 * speed)}


_RUNNING: set[subprocess.Popen[bytes]] = set()  # every episode process of this harness still running
_RUNNING_LOCK = threading.Lock()
STOPPING = threading.Event()  # set by stop_running_episodes: episodes starting or in flight end at once


def track(*procs: subprocess.Popen[bytes]) -> None:
    """Count ``procs`` as an episode's processes in flight (what :func:`stop_running_episodes` stops);
    terminated at once when the campaign is being stopped already."""
    with _RUNNING_LOCK:
        _RUNNING.update(procs)
        if STOPPING.is_set():  # the campaign was stopped while these started
            for proc in procs:
                proc.terminate()


def untrack(*procs: subprocess.Popen[bytes]) -> None:
    """``procs`` ended (stopped by their episode): no longer in flight."""
    with _RUNNING_LOCK:
        _RUNNING.difference_update(procs)


def running() -> int:
    """How many episode processes are in flight."""
    with _RUNNING_LOCK:
        return len(_RUNNING)


def stop_running_episodes() -> int:
    """SIGTERM to the simbridge and companion processes of every episode in flight (a campaign being
    interrupted): each episode then ends at once as an error, which the caller does not record.
    Returns how many were signalled. Episodes that start later end as soon as they do, until
    ``STOPPING`` is cleared."""
    STOPPING.set()
    with _RUNNING_LOCK:
        procs = [p for p in _RUNNING if p.poll() is None]
    for proc in procs:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
    return len(procs)


def die_with_parent() -> None:
    """In the child, before exec: SIGTERM when the thread that started it ends (Linux
    ``PR_SET_PDEATHSIG``), so a campaign killed outright (``kill -9``, a Ray task cancelled) leaves no
    simbridge or companion behind. Elsewhere, nothing. Passed as ``preexec_fn`` to ``subprocess.Popen``."""
    if _PRCTL is not None:
        _PRCTL(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def stop_process(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def send_alarm(
    udp_port: int, reason: str, criticality: str, deadline: float
) -> subprocess.CompletedProcess[str]:
    """``trigger_alarm.py`` to the companion on ``udp_port``, again every 0.5 s until it is accepted or
    ``deadline`` (monotonic) has passed; the last try's result. Run as ``python -m
    companion.alarm_cli`` (the module behind the ``trigger_alarm.py`` and ``trigger-alarm`` commands):
    the same interpreter, from a checkout or an installed wheel alike."""
    cmd = [
        sys.executable, "-m", "companion.alarm_cli", "--mavlink", f"udpout:127.0.0.1:{udp_port}",
        "--reason", reason, "--criticality", criticality,
    ]  # fmt: skip
    while True:  # the first telemetry may still be on its way: "refused for now" until it is in
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        if res.returncode == 0 or time.monotonic() > deadline or STOPPING.is_set():
            return res
        time.sleep(0.5)
