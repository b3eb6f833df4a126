"""One full-pipeline episode through the real processes: simbridge + companion over MAVLink.

:func:`run_episode` starts ``simbridge`` (the scenario, seed, weather, launch point and speed of the
:class:`EpisodeSpec`) and the ``companion`` daemon (the spec's reasoner and context) as separate
processes wired over loopback UDP and the sensor socket, sends the alarm with ``trigger_alarm.py``,
waits for simbridge's touchdown event (or the time limit), and grades the episode from simbridge's
ground truth (:mod:`landfall_eval.grading`) and the companion's flight record (rounds, every reasoner
call with its tier and latency, the rationales). Everything the processes wrote stays in the episode's
directory: ``episode.jsonl`` (simbridge), ``companion.log``, ``record/``.

The alarm goes out only once simbridge's episode log says ``ready`` (the vehicle holds at its launch
pose): at once with the emulated autopilots, after 80-90 simulated seconds of initialisation and
take-off with real ArduCopter (``--autopilot ardupilot-sitl``), about 40 with real PX4 (``px4-sitl``).

Times are simulated seconds from simbridge's episode log: ``time_to_touchdown_s`` runs from the moment
the companion took control (the vehicle's switch to OFFBOARD or GUIDED after ``ready``, milliseconds
after the alarm; where the vehicle already holds in GUIDED, as real ArduCopter does after its take-off,
the alarm's acceptance, placed on the log's clock through the autopilot's boot clock) to the touchdown.
The companion's peak RSS and CPU time are sampled from ``/proc`` every poll (Linux).

Kept whole: one episode's life, from starting the processes to the graded entry,
in the order it happens.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from landfall_eval.grading import kinematic_lower_bound_s, surface_class
from landfall_eval.landing import landing_distance_m

__all__ = [
    "EpisodeSpec",
    "EpisodeTimes",
    "JsonlTail",
    "LogWatch",
    "ProcessSample",
    "alarm_sim_time_s",
    "describe_last_state",
    "free_port",
    "run_episode",
    "send_alarm",
    "simbridge_command",
    "sped_up_env",
    "stop_process",
    "touchdown_to_site_m",
]

# resolved once here: the child of a fork runs ``_die_with_parent`` with nothing to import or look up
_PRCTL = ctypes.CDLL(None, use_errno=True).prctl if sys.platform == "linux" else None
TRAJECTORY_STEP_S = 1.0  # one trajectory point per simulated second
CONTROL_MODES = ("OFFBOARD", "GUIDED")


@dataclass(frozen=True, slots=True)
class EpisodeSpec:
    """What one episode flies. ``seed`` seeds the world's traffic, the sensors' noise and the wind.

    ``launch`` (north, east, height above ground) overrides the scenario's launch point (the city);
    ``launch_index`` is its index in the Halton sequence, ``run`` the repetition of a curated scenario;
    ``city_seed`` the procedural city's seed (simbridge ``--city-seed``; every episode of a campaign
    flies the same city).
    """

    kind: str  # "curated" or "city"
    scenario: str
    seed: int
    reasoner: str = "onboard"
    context: str = "crop"
    weather: str = "clear"
    autopilot: str = "px4"  # px4 | ardupilot (the emulation) | ardupilot-sitl | px4-sitl (real firmware)
    launch: tuple[float, float, float] | None = None
    launch_index: int | None = None
    run: int | None = None
    city_seed: int | None = None
    criticality: str = "high"
    reason: str = "GPS spoofing detected"
    ekf_error: str = "off"  # the emulation's estimator errors (simbridge --ekf-error)
    gps_fault: tuple[float, float] | None = None  # the GPS's lie during the descent (simbridge --gps-fault)
    gps_fault_ramp_s: float = 0.0  # 0: a jump; else a drift over this many seconds (--gps-fault-ramp)
    camera: str = "socket"  # socket: images on the sensor stream | rtp: H.264 over RTP (LiDAR on the socket)

    @property
    def gps_fault_entry(self) -> dict[str, Any] | None:
        """The results' ``gps_fault``: {offset_ne_m, ramp_s}, or None without one."""
        if self.gps_fault is None:
            return None
        return {"offset_ne_m": list(self.gps_fault), "ramp_s": self.gps_fault_ramp_s}

    @property
    def id(self) -> str:
        """Stable name: what resumption matches episodes by."""
        where = (
            f"city{self.city_seed}-i{self.launch_index}"
            if self.kind == "city"
            else f"{self.scenario}-r{self.run}"
        )
        ekf = f"-ekf-{self.ekf_error}" if self.ekf_error != "off" else ""
        cam = f"-{self.camera}" if self.camera != "socket" else ""
        gps = ""
        if self.gps_fault is not None:
            gps = f"-gps{self.gps_fault[0]:g},{self.gps_fault[1]:g}"
            gps += f"r{self.gps_fault_ramp_s:g}" if self.gps_fault_ramp_s else ""
        return f"{where}-{self.reasoner}-{self.context}-{self.weather}-{self.autopilot}{ekf}{gps}{cam}"


@dataclass(frozen=True, slots=True)
class EpisodeTimes:
    """Limits: ``sim_s`` simulated seconds after the alarm; ``wall_s`` a hard stop whatever happens."""

    speed: float = 4.0
    sim_s: float = 600.0
    start_wall_s: float = 90.0  # simbridge and the companion must be up and talking by then
    settle_wall_s: float = 10.0  # after the touchdown, for the companion to close its record
    ready_sim_s: float = 240.0  # for the autopilot to hold at the launch pose (real firmware: 83-87 s)
    wall_limit_s: float | None = None  # wall seconds after the alarm (None: from sim_s and speed)

    @property
    def wall_s(self) -> float:
        """Wall seconds after the alarm before the episode is stopped as a timeout."""
        if self.wall_limit_s is not None:
            return self.wall_limit_s
        return self.start_wall_s + 3.0 * self.sim_s / self.speed + 60.0

    @property
    def ready_wall_s(self) -> float:
        """Wall seconds from the start until the episode log must say ``ready``; at 3x the simulated
        allowance, as for the flight, since lock-stepped firmware can fall behind ``speed``."""
        return self.start_wall_s + 3.0 * self.ready_sim_s / self.speed


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


SENSORS_UP = "sensors"  # the companion's record: its sensor stream connected
RECOVERY_ENDED = ("outcome", "recovery_failed")  # the companion's record: a recovery ended
RTP_WALL_FPS = 2.0  # an rtp episode's camera frames per wall second (simbridge renders each: ~160 ms)


def sped_up_env(speed: float) -> dict[str, str]:
    """The companion's environment for a simulation at ``speed`` x: a frame's age is counted in
    simulated seconds, so the default 2 s tolerance becomes 2 s of wall clock at any speed."""
    return {"LANDFALL_SENSORS_MAX_FRAME_AGE_S": str(2.0 * speed)}


_RUNNING: set[subprocess.Popen[bytes]] = set()  # every episode process of this harness still running
_RUNNING_LOCK = threading.Lock()
STOPPING = threading.Event()  # set by stop_running_episodes: episodes starting or in flight end at once


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


def _die_with_parent() -> None:
    """In the child, before exec: SIGTERM when the thread that started it ends (Linux
    ``PR_SET_PDEATHSIG``), so a campaign killed outright (``kill -9``, a Ray task cancelled) leaves no
    simbridge or companion behind. Elsewhere, nothing."""
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


def _record_events(record_dir: Path) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    for path in sorted(record_dir.glob("*/events.jsonl")):
        events += [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    return events


def _recorded(record_dir: Path, *kinds: str) -> bool:
    """Whether the companion's flight record holds an event of one of ``kinds`` yet (it replaces
    ``events.jsonl`` whole and atomically with each event: what is read is always complete)."""
    return any(e.get("kind") in kinds for e in _record_events(record_dir))


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


def simbridge_command(
    spec: EpisodeSpec,
    *,
    udp_port: int,
    sensors_port: int,
    episode_log: Path,
    speed: float,
    sitl: Path | None = None,
    video_port: int | None = None,
    camera_info: Path | None = None,
) -> list[str]:
    """The ``simbridge`` command line that flies ``spec``: MAVLink to ``udp_port`` on loopback, the
    sensor stream on ``sensors_port``, the episode log at ``episode_log``, ``speed`` x real time;
    ``sitl`` the firmware binary for ``ardupilot-sitl`` or ``px4-sitl`` (None: simbridge's own default).
    With ``spec.camera`` ``rtp``: the camera as H.264 over RTP to ``video_port``, ``RTP_WALL_FPS`` frames a
    wall second, its calibration written to ``camera_info``."""
    cmd = [
        sys.executable, "-m", "simbridge", "--scenario", spec.scenario, "--seed", str(spec.seed),
        "--autopilot", spec.autopilot, "--weather", spec.weather, "--speed", f"{speed:g}",
        "--mavlink", f"udpout:127.0.0.1:{udp_port}", "--sensors", f"127.0.0.1:{sensors_port}",
        "--episode-log", str(episode_log), "--log-level", "WARNING",
    ]  # fmt: skip
    if spec.autopilot == "ardupilot-sitl" and sitl is not None:
        cmd += ["--sitl", str(sitl)]
    if spec.autopilot == "px4-sitl" and sitl is not None:
        cmd += ["--px4", str(sitl)]
    if spec.city_seed is not None:
        cmd += ["--city-seed", str(spec.city_seed)]
    if spec.ekf_error != "off":
        cmd += ["--ekf-error", spec.ekf_error]
    if spec.gps_fault is not None:
        cmd.append("--gps-fault=" + ",".join(f"{v:g}" for v in spec.gps_fault))  # "=": it may start with "-"
        cmd += ["--gps-fault-ramp", f"{spec.gps_fault_ramp_s:g}"]
    if spec.launch is not None:
        cmd.append("--launch=" + ",".join(f"{v:.2f}" for v in spec.launch))  # "=": it may start with "-"
    if spec.camera == "rtp":
        if video_port is None or camera_info is None:
            raise ValueError("an rtp camera needs a video port and a calibration path")
        fps = min(max(RTP_WALL_FPS / speed, 0.2), 30.0)
        cmd += ["--camera-stream", f"udp://127.0.0.1:{video_port}", "--camera-fps", f"{fps:g}",
                "--camera-info-out", str(camera_info)]  # fmt: skip
    return cmd


class LogWatch:
    """What an episode keeps of simbridge's episode log as it is written: the state lines, the ``start``
    line (the world flown), ``ready``, the first switch to a control mode after ``ready`` (the
    companion taking over), the touchdown, and the true pose of every sensor frame served (``frames``,
    by the autopilot's ``time_boot_ms`` at capture)."""

    def __init__(self) -> None:
        self.states: list[dict[str, Any]] = []
        self.header: dict[str, Any] | None = None
        self.ready: dict[str, Any] | None = None
        self.takeover: dict[str, Any] | None = None
        self.touchdown: dict[str, Any] | None = None
        self.last_vehicle: dict[str, Any] | None = None  # the latest state line, read to the very end
        self.frames: dict[int, dict[str, Any]] = {}
        self.camera_frames: list[dict[str, Any]] = []  # what the RTP camera sent (rtp episodes)

    def take(self, rows: list[dict[str, Any]], *, final: bool = False) -> None:
        """Sort ``rows`` in; ``final``: read after the processes were stopped, so only the last
        state and the header count (a touchdown then came too late to grade)."""
        for row in rows:
            kind = row.get("event")
            if kind == "state":
                self.last_vehicle = row
                if not final:
                    self.states.append(row)
            elif kind == "start" and self.header is None:
                self.header = row
            elif kind == "frame" and isinstance(row.get("time_boot_ms"), int):
                self.frames[row["time_boot_ms"]] = row
            elif kind == "camera_frame" and isinstance(row.get("pts_s"), int | float):
                self.camera_frames.append(row)
            elif final:
                continue
            elif kind == "ready" and self.ready is None:
                self.ready = row
            elif (
                kind == "mode"
                and self.ready is not None  # real firmware flies GUIDED to the launch pose before it
                and self.takeover is None
                and row.get("mode") in CONTROL_MODES
            ):
                self.takeover = row
            elif kind == "touchdown" and self.touchdown is None:
                self.touchdown = row


def alarm_sim_time_s(ready: Mapping[str, Any] | None, events: list[dict[str, Any]]) -> float | None:
    """The simulated time at which the companion accepted the alarm: its flight record's ``alarm``
    event carries the autopilot's boot clock then (``vehicle_time_boot_ms``), and simbridge's ``ready``
    event ties that clock to the episode log's ``t_s``. None when either is missing."""
    alarm = next((e for e in reversed(events) if e.get("kind") == "alarm"), None)
    if ready is None or alarm is None:
        return None
    boot_ms, ready_boot_ms = alarm.get("vehicle_time_boot_ms"), ready.get("time_boot_ms")
    if not isinstance(boot_ms, int | float) or not isinstance(ready_boot_ms, int | float):
        return None
    return float(ready["t_s"]) + (boot_ms - ready_boot_ms) / 1000.0


def run_episode(
    spec: EpisodeSpec,
    workdir: Path,
    *,
    times: EpisodeTimes | None = None,
    config_path: Path | None = None,
    on_line: Callable[[str, str], None] | None = None,
    sitl: Path | None = None,
) -> dict[str, Any]:
    """Fly one episode; returns its results.json entry (``episodes[]`` in docs/bench.md).

    ``on_line(source, text)`` sees the alarm tool's answer (source ``alarm``) and every line of the
    companion's log (``companion``) as they come. Never raises for what happens in the episode: a
    process that dies, an alarm that is refused or a landing that never comes is an ``outcome`` of
    ``error`` or ``timeout`` with the ``error`` text, and ``last_state`` says where the companion and
    the vehicle stood at the end. ``city_seed`` and ``world_digest`` come from simbridge's episode log:
    the world it flew. ``sitl``: the firmware binary when ``spec.autopilot`` is ``ardupilot-sitl`` or
    ``px4-sitl``.
    """
    times = times or EpisodeTimes()
    workdir.mkdir(parents=True, exist_ok=True)
    episode_log, comp_log, record_dir = (
        workdir / "episode.jsonl",
        workdir / "companion.log",
        workdir / "record",
    )
    for stale in (episode_log, comp_log):
        stale.unlink(missing_ok=True)
    udp, tcp = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    video = free_port(socket.SOCK_DGRAM) if spec.camera == "rtp" else None
    camera_info = workdir / "camera.yaml"
    camera_info.unlink(missing_ok=True)
    sim_cmd = simbridge_command(
        spec, udp_port=udp, sensors_port=tcp, episode_log=episode_log, speed=times.speed, sitl=sitl,
        video_port=video, camera_info=camera_info,
    )  # fmt: skip
    comp_cmd = [
        sys.executable, "-m", "companion", "--mavlink", f"udp:{udp}", "--sensors", f"127.0.0.1:{tcp}",
        "--record", str(record_dir), "--reasoner", spec.reasoner,
    ]  # fmt: skip
    if video is not None:
        comp_cmd += ["--camera", f"udp://127.0.0.1:{video}", "--camera-info", str(camera_info)]
    if config_path is not None:
        comp_cmd += ["--config", str(config_path)]
    env = {**os.environ, "LANDFALL_REASONER_CONTEXT": spec.context, **sped_up_env(times.speed)}
    entry: dict[str, Any] = {
        "id": spec.id,
        "kind": spec.kind,
        "scenario": spec.scenario,
        "seed": spec.seed,
        "city_seed": spec.city_seed,
        "world_digest": None,
        "launch_index": spec.launch_index,
        "run": spec.run,
        "reasoner": spec.reasoner,
        "context": spec.context,
        "weather": spec.weather,
        "autopilot": spec.autopilot,
        "ekf_error": spec.ekf_error,
        "gps_fault": spec.gps_fault_entry,
        "camera": spec.camera,
        "criticality": spec.criticality,
        "launch_height_m": spec.launch[2] if spec.launch is not None else None,
    }
    t_wall = time.monotonic()
    sim_err = (workdir / "simbridge.log").open("wb")
    try:
        sim = subprocess.Popen(
            sim_cmd, stdout=subprocess.DEVNULL, stderr=sim_err, preexec_fn=_die_with_parent
        )
    except BaseException:
        sim_err.close()
        raise
    try:
        if video is not None:
            # the companion reads the camera's calibration at start: simbridge writes it as it starts
            while (
                not camera_info.exists()
                and sim.poll() is None
                and time.monotonic() - t_wall < times.start_wall_s
            ):
                time.sleep(0.1)
        with comp_log.open("wb") as fh:
            comp = subprocess.Popen(
                comp_cmd, env=env, stdout=fh, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent
            )
    except BaseException:  # the companion never started: nothing of simbridge's is left behind
        stop_process(sim)
        sim_err.close()
        raise
    comp_lines = LineTail(comp_log)
    with _RUNNING_LOCK:
        _RUNNING.update((sim, comp))
        if STOPPING.is_set():  # the campaign was stopped while these started
            for proc in (sim, comp):
                proc.terminate()
    usage = ProcessSample(comp.pid)
    tail = JsonlTail(episode_log)
    log = LogWatch()
    alarm_t_s: float | None = None  # the takeover where the vehicle already holds in GUIDED
    outcome, error, infrastructure = "landed", None, False
    try:
        while log.ready is None or not _recorded(record_dir, SENSORS_UP):
            log.take(tail.lines())
            if comp.poll() is not None or sim.poll() is not None:
                who = "simbridge" if sim.poll() is not None else "the companion"
                raise _EpisodeError(
                    f"{who} exited before the vehicle was ready and the sensor stream up", infrastructure=True
                )
            waited = time.monotonic() - t_wall
            if log.ready is None and waited > times.ready_wall_s:
                raise _EpisodeError(
                    f"simbridge's autopilot not ready after {times.ready_wall_s:.0f} s", infrastructure=True
                )
            if log.ready is not None and waited > times.ready_wall_s + times.start_wall_s:
                raise _EpisodeError(f"no sensor stream after {waited:.0f} s", infrastructure=True)
            if STOPPING.is_set():
                raise _EpisodeError("stopped: the campaign was interrupted")
            time.sleep(0.2)
        res = send_alarm(udp, spec.reason, spec.criticality, time.monotonic() + 30.0)
        if on_line is not None:
            on_line("alarm", (res.stdout or res.stderr).strip())
        if res.returncode != 0:
            raise _EpisodeError(f"alarm not accepted: {(res.stdout or res.stderr).strip()[:200]}")
        t_alarm = time.monotonic()
        alarm_t_s = alarm_sim_time_s(log.ready, _record_events(record_dir))
        ended = None
        while True:
            usage.sample()
            log.take(tail.lines())
            if on_line is not None:
                for line in comp_lines.text_lines():
                    on_line("companion", line)
            if log.touchdown is not None:
                if ended is None:
                    ended = time.monotonic()
                if _recorded(record_dir, *RECOVERY_ENDED):
                    break
                if time.monotonic() - ended > times.settle_wall_s:
                    break
            t0 = float(log.takeover["t_s"]) if log.takeover is not None else alarm_t_s
            if t0 is not None and log.states and float(log.states[-1]["t_s"]) - t0 > times.sim_s:
                outcome, error = "timeout", f"no touchdown within {times.sim_s:.0f} simulated seconds"
                break
            if time.monotonic() - t_alarm > times.wall_s:
                outcome, error = "timeout", f"no touchdown within {times.wall_s:.0f} wall seconds"
                break
            if STOPPING.is_set():
                outcome, error = "error", "stopped: the campaign was interrupted"
                break
            if sim.poll() is not None or comp.poll() is not None:
                who = "simbridge" if sim.poll() is not None else "the companion"
                outcome, error = "error", f"{who} exited during the episode"
                break
            time.sleep(0.25)
    except _EpisodeError as exc:
        outcome, error, infrastructure = "error", str(exc), exc.infrastructure
    finally:
        usage.sample()
        for proc in (comp, sim):
            stop_process(proc)
        with _RUNNING_LOCK:
            _RUNNING.difference_update((sim, comp))
        if on_line is not None:
            for line in comp_lines.text_lines():
                on_line("companion", line)
        comp_lines.close()
        sim_err.close()
        log.take(tail.lines(), final=True)  # what simbridge wrote since the last look
        tail.close()
    if log.header is not None:
        entry["city_seed"] = log.header.get("city_seed", entry["city_seed"])
        entry["world_digest"] = log.header.get("world_digest")
    takeover = log.takeover
    if takeover is None and alarm_t_s is not None:
        takeover = {"t_s": alarm_t_s}
    events = _record_events(record_dir)
    entry.update(_grade(log.states, takeover, log.touchdown, events))
    entry["touchdown_to_site_m"] = touchdown_to_site_m(log.touchdown, log.header, events)
    entry.update(_landing_distance(log, events, spec))
    entry["precision_landing"] = precision_landing_summary(events)
    entry["outcome"] = outcome if log.touchdown is None or outcome != "timeout" else "landed"
    entry["error"] = error if log.touchdown is None else None
    entry["error_kind"] = "infrastructure" if infrastructure and log.touchdown is None else None
    entry["defects"] = sum(e.get("kind") == "defect" for e in events)
    entry["last_state"] = _last_state(events, log.last_vehicle)
    entry["companion"] = {
        "peak_rss_mb": round(usage.peak_rss_mb, 1),
        "peak_anon_mb": round(usage.peak_anon_mb, 1),
        "cpu_s": round(usage.cpu_s, 2),
    }
    entry["wall_s"] = round(time.monotonic() - t_wall, 2)
    return entry


def touchdown_to_site_m(
    touchdown: Mapping[str, Any] | None, header: Mapping[str, Any] | None, events: list[dict[str, Any]]
) -> float | None:
    """Horizontal distance (m) from the touchdown to the site the companion last confirmed for descent.

    The site is in the autopilot's local frame (its EKF origin, which simbridge puts at ``home_ned_m``
    for every autopilot), the touchdown in the scenario's: so this is how far from its aim the
    autopilot put the vehicle, the estimator's error at touchdown included; it is not the distance to
    what the chosen pixel truly shows (``companion-bench modules`` measures that). None without a
    touchdown, a home or a confirmed site.
    """
    site = next(
        (e.get("site_ned_m") for e in reversed(events) if e.get("kind") == "confirm" and e.get("accept")),
        None,
    )
    home = header.get("home_ned_m") if header is not None else None
    if touchdown is None or not isinstance(site, list) or not isinstance(home, list):
        return None
    td = touchdown["pos_ned_m"]
    return round(math.hypot(td[0] - home[0] - site[0], td[1] - home[1] - site[1]), 2)


def precision_landing_summary(events: list[dict[str, Any]]) -> dict[str, Any] | None:
    """What the companion's record says of its precision landing: whether the autopilot's was used
    (and why, or why not), how many LANDING_TARGET it sent, and how often the site was found again
    in a frame before each descent step (``site_track``). None when the recovery never landed on a
    site through the companion (no ``precision_landing`` event)."""
    last = next((e for e in reversed(events) if e.get("kind") == "precision_landing"), None)
    if last is None:
        return None
    tracks = [e for e in events if e.get("kind") == "site_track"]
    return {
        "used": bool(last.get("used")),
        "why": str(last.get("why", "")),
        "mode": last.get("mode"),
        "targets_sent": int(last.get("targets_sent", 0)),
        "looks_found": int(last.get("looks_found", 0)),
        "tracks_found": sum(bool(e.get("found")) for e in tracks),
        "tracks_lost": sum(not e.get("found") for e in tracks),
    }


def _landing_distance(log: LogWatch, events: list[dict[str, Any]], spec: EpisodeSpec) -> dict[str, Any]:
    """``landing_distance_m`` and ``landing_target_ned_m`` of an entry (:mod:`landfall_eval.landing`):
    both None when the episode does not say (no touchdown, nothing confirmed) or the world built to
    cast the pixel is not the one flown (then ``landing_error`` says so; else it is None)."""
    launch = tuple(round(v, 2) for v in spec.launch) if spec.launch is not None else None
    out: dict[str, Any] = {"landing_distance_m": None, "landing_target_ned_m": None, "landing_error": None}
    frames = log.frames if spec.camera == "socket" else video_frames_by_stamp(log.camera_frames, events)
    try:
        got = landing_distance_m(log.touchdown, log.header, frames, events, launch=launch)
    except ValueError as exc:
        return {**out, "landing_error": str(exc)}
    if got is not None:
        out["landing_distance_m"], out["landing_target_ned_m"] = got
    return out


def match_video_frames(
    sent: list[dict[str, Any]], used: list[dict[str, Any]], tolerance_s: float = 0.02
) -> list[dict[str, Any] | None]:
    """For each frame the companion used (its record's ``camera_frame`` events: ``pts_s`` and the
    monotonic ``decoded_s``), the frame simbridge sent (its episode log's ``camera_frame``: ``pts_s`` and
    ``sent_monotonic_s``), or None.

    The decoder's presentation times start at the first packet it received (FFmpeg's RTP demuxer counts
    from there), simbridge's at its first frame: they differ by a base that depends on when the companion
    started reading. The base is found from the frames themselves: every used frame must meet a sent
    one at its presentation time plus the base, and none may have been decoded before the frame after
    it was sent (the H.264 parser holds a frame until the next one begins: a frame paired one too late
    would look decoded the moment it was sent); of the bases that allow that, the largest (a smaller
    one pairs each frame with an earlier one)."""
    if not sent or not used:
        return [None] * len(used)
    by_pts = sorted(sent, key=lambda r: float(r["pts_s"]))
    pts = np.array([float(r["pts_s"]) for r in by_pts])
    sent_s = [float(r["sent_monotonic_s"]) for r in by_pts]
    used_pts = [float(u["pts_s"]) for u in used]
    decoded = [float(u["decoded_s"]) for u in used]

    def pair(p: float, base: float) -> int | None:
        k = int(np.argmin(np.abs(pts - (p + base))))
        return k if abs(pts[k] - (p + base)) < tolerance_s else None

    best: list[int | None] | None = None
    best_base = -math.inf
    for q in pts:
        base = float(q) - used_pts[0]
        found = [pair(p, base) for p in used_pts]
        if any(k is None for k in found):
            continue
        # the frame after each one (the last one itself) was sent before it was decoded
        causal = all(
            sent_s[min(k + 1, len(by_pts) - 1)] <= d + 0.01
            for k, d in zip(found, decoded, strict=True)
            if k is not None
        )
        if causal and base > best_base:
            best, best_base = found, base
    if best is None:
        return [None] * len(used)
    return [by_pts[k] if k is not None else None for k in best]


def video_frames_by_stamp(
    sent: list[dict[str, Any]], events: list[dict[str, Any]]
) -> dict[int, dict[str, Any]]:
    """The true pose of each video frame the companion used, by the capture time it gave the frame
    (``frame_time_boot_ms`` of its rank events): its record's ``camera_frame`` events matched to the
    frames simbridge sent (:func:`match_video_frames`), whose rows hold the pose each was rendered with."""
    used = [e for e in events if e.get("kind") == "camera_frame"]
    out: dict[int, dict[str, Any]] = {}
    for e, row in zip(used, match_video_frames(sent, used), strict=True):
        if row is not None:
            out[max(0, round(float(e["capture_boot_s"]) * 1000))] = row
    return out


class _EpisodeError(Exception):
    """An episode that could not be flown; ``infrastructure``: its processes never got as far as the
    alarm (a port taken meanwhile, a process that did not start): worth another try, unlike anything
    that happens once the alarm is in."""

    def __init__(self, text: str, *, infrastructure: bool = False) -> None:
        super().__init__(text)
        self.infrastructure = infrastructure


def _grade(
    states: list[dict[str, Any]],
    takeover: Mapping[str, Any] | None,
    touchdown: Mapping[str, Any] | None,
    events: list[dict[str, Any]],
) -> dict[str, Any]:
    """Ground-truth grade, times, trajectory and the reasoner's calls for one episode."""
    t0 = float(takeover["t_s"]) if takeover is not None else None
    flown = [s for s in states if t0 is None or float(s["t_s"]) >= t0 - 1e-6]
    start = flown[0]["pos_ned_m"] if flown else (states[0]["pos_ned_m"] if states else None)
    trajectory: list[list[float]] = []
    next_t = -1.0
    for s in flown:
        if float(s["t_s"]) >= next_t:
            trajectory.append([round(s["pos_ned_m"][0], 2), round(s["pos_ned_m"][1], 2)])
            next_t = float(s["t_s"]) + TRAJECTORY_STEP_S
    out: dict[str, Any] = {
        "launch_ned_m": [round(v, 2) for v in start] if start is not None else None,
        "touchdown_ned_m": None,
        "surface": surface_class(touchdown),
        "sim_surface": None,
        "safe": False,
        "reasons": ["no touchdown"],
        "time_to_touchdown_s": None,
        "kinematic_lower_bound_s": None,
        "kinematic_ratio": None,
        "trajectory_ne_m": trajectory,
    }
    if touchdown is not None:
        td = [float(v) for v in touchdown["pos_ned_m"]]
        trajectory.append([round(td[0], 2), round(td[1], 2)])
        out.update(
            touchdown_ned_m=[round(v, 2) for v in td],
            sim_surface=touchdown.get("surface"),
            safe=bool(touchdown.get("safe")),
            reasons=list(touchdown.get("reasons", [])),
        )
        if t0 is not None and start is not None:
            took = float(touchdown["t_s"]) - t0
            bound = kinematic_lower_bound_s(start, td)
            out.update(
                time_to_touchdown_s=round(took, 2),
                kinematic_lower_bound_s=round(bound, 2),
                kinematic_ratio=round(took / bound, 3) if bound > 0 else None,
            )
    calls, rationales, rounds = [], [], 0
    for ev in events:
        kind = ev.get("kind")
        if kind in ("rank", "confirm"):
            rnd = int(ev.get("round", 0))
            calls.append(
                {"stage": kind, "tier": ev.get("tier"), "latency_s": ev.get("latency_s"), "round": rnd}
            )
            rationales.append(
                {"stage": kind, "round": rnd, "tier": ev.get("tier"), "text": ev.get("rationale", "")}
            )
        if kind == "outcome":
            rounds = int(ev.get("rounds", rounds))
        elif kind in ("state", "rank", "confirm"):
            rounds = max(rounds, int(ev.get("round", 0)))
    out.update(calls=calls, rationales=rationales, rounds=rounds)
    return out


def _last_state(events: list[dict[str, Any]], vehicle: dict[str, Any] | None) -> dict[str, Any] | None:
    """Where an episode stood at its end (``last_state`` in docs/bench.md): the companion's last
    recovery state and round (its flight record's ``state`` events), how its recovery ended (the
    ``outcome`` event) and the vehicle's last mode, arming, position and height above ground (the
    episode log's last ``state`` line). None when neither process wrote anything."""
    state = next((e for e in reversed(events) if e.get("kind") == "state"), None)
    outcome = next((e for e in reversed(events) if e.get("kind") == "outcome"), None)
    if state is None and outcome is None and vehicle is None:
        return None
    return {
        "recovery_state": state.get("state") if state is not None else None,
        "round": state.get("round") if state is not None else None,
        "outcome_state": outcome.get("state") if outcome is not None else None,
        "outcome_reason": outcome.get("reason") if outcome is not None else None,
        "vehicle_t_s": vehicle.get("t_s") if vehicle is not None else None,
        "vehicle_mode": vehicle.get("mode") if vehicle is not None else None,
        "vehicle_armed": vehicle.get("armed") if vehicle is not None else None,
        "vehicle_pos_ned_m": vehicle.get("pos_ned_m") if vehicle is not None else None,
        "vehicle_agl_m": vehicle.get("agl_m") if vehicle is not None else None,
    }


def describe_last_state(last: object) -> str:
    """An entry's ``last_state`` in a few words ('' when it has none): the companion's recovery state
    and round, how its recovery ended, the vehicle's mode and height above ground."""
    if not isinstance(last, Mapping):
        return ""
    parts = []
    if last.get("recovery_state") is not None:
        parts.append(f"companion in {last['recovery_state']}, round {last.get('round')}")
    if last.get("outcome_reason"):
        parts.append(f"recovery ended: {last['outcome_reason']}")
    if last.get("vehicle_mode") is not None:
        agl = last.get("vehicle_agl_m")
        up = f" {agl:.0f} m above ground" if isinstance(agl, int | float) else ""
        parts.append(f"vehicle {last['vehicle_mode']}{up}")
    return "; ".join(parts)
