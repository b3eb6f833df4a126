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

A campaign's worker may start an episode's processes ahead of its turn (:func:`launch_episode` with
``held``): simbridge builds its world and warms its sensors, then waits with its clock stopped until
the flight before it has ended (:meth:`Launch.go`), so the flight itself is the one it would have been.

This module is one episode's life, from starting the processes to the graded entry, in the order it
happens; its parts live beside it: the processes (starting, stopping, sampling, reading their files, the
alarm tool) in :mod:`landfall_eval.processes`, reading what they wrote into the entry in
:mod:`landfall_eval.episode_grade`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from landfall_eval.episode_grade import (
    LogWatch,
    alarm_sim_time_s,
    grade,
    landing_distance,
    last_state,
    precision_landing_summary,
    record_events,
    recorded,
    touchdown_to_site_m,
)
from landfall_eval.processes import (
    STOPPING,
    JsonlTail,
    LineTail,
    ProcessSample,
    die_with_parent,
    free_port,
    send_alarm,
    sped_up_env,
    stop_process,
    track,
    untrack,
)

__all__ = ["EpisodeSpec", "EpisodeTimes", "Launch", "launch_episode", "run_episode", "simbridge_command"]


@dataclass(frozen=True, slots=True)
class EpisodeSpec:
    """What one episode flies. ``seed`` seeds the world's traffic, the sensors' noise and the wind.

    ``launch`` (north, east, height above ground) overrides the scenario's launch point (the city);
    ``launch_index`` is its index in the Halton sequence, ``run`` the repetition of a curated scenario;
    ``city_seed`` the procedural city's seed (simbridge ``--city-seed``; every episode of a campaign
    flies the same city) and ``place`` its kind (simbridge ``--place``).
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
    place: str = "downtown"  # the kind of place a city episode flies (simbridge.world.places)
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
        town = "city" if self.place == "downtown" else self.place  # downtown keeps the ids of before
        where = (
            f"{town}{self.city_seed}-i{self.launch_index}"
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


SENSORS_UP = "sensors"  # the companion's record: its sensor stream connected
RECOVERY_ENDED = ("outcome", "recovery_failed")  # the companion's record: a recovery ended
RTP_WALL_FPS = 2.0  # an rtp episode's camera frames per wall second (simbridge renders each: ~160 ms)


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
    world_cache: Path | None = None,
) -> list[str]:
    """The ``simbridge`` command line that flies ``spec``: MAVLink to ``udp_port`` on loopback, the
    sensor stream on ``sensors_port``, the episode log at ``episode_log``, ``speed`` x real time;
    ``sitl`` the firmware binary for ``ardupilot-sitl`` or ``px4-sitl`` (None: simbridge's own default).
    With ``spec.camera`` ``rtp``: the camera as H.264 over RTP to ``video_port``, ``RTP_WALL_FPS`` frames a
    wall second, its calibration written to ``camera_info``. ``world_cache``: where a city's place is
    kept between episodes (simbridge ``--world-cache``)."""
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
        cmd += ["--city-seed", str(spec.city_seed), "--place", spec.place]
        if world_cache is not None:
            cmd += ["--world-cache", str(world_cache)]
        if spec.autopilot in ("px4", "ardupilot"):  # the emulation's fence out to the map's edge
            cmd += ["--fence", "map"]
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


@dataclass(eq=False)
class Launch:
    """An episode's processes, started: simbridge (with ``held`` true, built and waiting for its go:
    :func:`launch_episode`) and the companion, their files and ports."""

    spec: EpisodeSpec
    workdir: Path
    times: EpisodeTimes
    udp: int
    sim: subprocess.Popen[bytes]
    comp: subprocess.Popen[bytes]
    sim_err: Any  # simbridge's stderr file, open while it runs
    t_launch: float  # monotonic seconds when the processes started
    held: bool

    @property
    def episode_log(self) -> Path:
        return self.workdir / "episode.jsonl"

    @property
    def comp_log(self) -> Path:
        return self.workdir / "companion.log"

    @property
    def record_dir(self) -> Path:
        return self.workdir / "record"

    def go(self) -> None:
        """Start a held simbridge's clock (its ``--wait-for-go``); nothing when not held or started."""
        if self.held and self.sim.stdin is not None:
            with contextlib.suppress(OSError):  # exited meanwhile: the flight finds it gone
                self.sim.stdin.write(b"go\n")
                self.sim.stdin.close()
            self.held = False

    def stop(self) -> None:
        """Stop both processes (the companion first) and close simbridge's standard input."""
        for proc in (self.comp, self.sim):
            stop_process(proc)
        untrack(self.sim, self.comp)
        if self.sim.stdin is not None:
            with contextlib.suppress(OSError):
                self.sim.stdin.close()

    def discard(self) -> None:
        """Stop both processes and close simbridge's file: an episode launched and never flown."""
        self.stop()
        self.sim_err.close()


def launch_episode(
    spec: EpisodeSpec,
    workdir: Path,
    *,
    times: EpisodeTimes,
    config_path: Path | None = None,
    sitl: Path | None = None,
    world_cache: Path | None = None,
    held: bool = False,
) -> Launch:
    """Start ``spec``'s simbridge and companion in ``workdir`` (what a try before this one left there
    removed). ``held``: simbridge builds its world and warms its sensors, then waits for
    :meth:`Launch.go` before its clock starts, and the companion, started beside it, waits for it:
    a worker launches its next episode while it flies this one (:class:`landfall_eval.campaign.
    LocalExecutor`), so the starting costs no flight's wall time, and the flight is the same."""
    workdir.mkdir(parents=True, exist_ok=True)
    episode_log, comp_log, record_dir = (
        workdir / "episode.jsonl",
        workdir / "companion.log",
        workdir / "record",
    )
    for stale in (episode_log, comp_log):
        stale.unlink(missing_ok=True)
    # a try before this one (a retry, a Ray task rerun after its node died) may have left a flight
    # record: its events must not stand for this try's (its companion's "sensors up", its outcome)
    shutil.rmtree(record_dir, ignore_errors=True)
    udp, tcp = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    video = free_port(socket.SOCK_DGRAM) if spec.camera == "rtp" else None
    camera_info = workdir / "camera.yaml"
    camera_info.unlink(missing_ok=True)
    sim_cmd = simbridge_command(
        spec, udp_port=udp, sensors_port=tcp, episode_log=episode_log, speed=times.speed, sitl=sitl,
        video_port=video, camera_info=camera_info, world_cache=world_cache,
    )  # fmt: skip
    if held:
        sim_cmd.append("--wait-for-go")
    comp_cmd = [
        sys.executable, "-m", "companion", "--mavlink", f"udp:{udp}", "--sensors", f"127.0.0.1:{tcp}",
        "--record", str(record_dir), "--reasoner", spec.reasoner,
    ]  # fmt: skip
    if video is not None:
        comp_cmd += ["--camera", f"udp://127.0.0.1:{video}", "--camera-info", str(camera_info)]
    if config_path is not None:
        comp_cmd += ["--config", str(config_path)]
    env = {**os.environ, "LANDFALL_REASONER_CONTEXT": spec.context, **sped_up_env(times.speed)}
    t_launch = time.monotonic()
    sim_err = (workdir / "simbridge.log").open("wb")
    try:
        sim = subprocess.Popen(
            sim_cmd,
            stdin=subprocess.PIPE if held else subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=sim_err,
            preexec_fn=die_with_parent,
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
                and time.monotonic() - t_launch < times.start_wall_s
            ):
                time.sleep(0.1)
        with comp_log.open("wb") as fh:
            comp = subprocess.Popen(
                comp_cmd, env=env, stdout=fh, stderr=subprocess.STDOUT, preexec_fn=die_with_parent
            )
    except BaseException:  # the companion never started: nothing of simbridge's is left behind
        stop_process(sim)
        sim_err.close()
        raise
    track(sim, comp)
    return Launch(spec, workdir, times, udp, sim, comp, sim_err, t_launch, held)


def run_episode(
    spec: EpisodeSpec,
    workdir: Path,
    *,
    times: EpisodeTimes | None = None,
    config_path: Path | None = None,
    on_line: Callable[[str, str], None] | None = None,
    sitl: Path | None = None,
    world_cache: Path | None = None,
    launched: Launch | None = None,
    in_flight: Callable[[], None] | None = None,
    on_stopped: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """Fly one episode; returns its results.json entry (``episodes[]`` in docs/bench.md).

    ``on_line(source, text)`` sees the alarm tool's answer (source ``alarm``) and every line of the
    companion's log (``companion``) as they come. Never raises for what happens in the episode: a
    process that dies, an alarm that is refused or a landing that never comes is an ``outcome`` of
    ``error`` or ``timeout`` with the ``error`` text, and ``last_state`` says where the companion and
    the vehicle stood at the end. ``city_seed`` and ``world_digest`` come from simbridge's episode log:
    the world it flew. ``sitl``: the firmware binary when ``spec.autopilot`` is ``ardupilot-sitl`` or
    ``px4-sitl``. ``world_cache``: where built places are kept, for simbridge and the grading
    (:mod:`simbridge.world.cache`; None: each builds its own). ``launched``: this episode's processes
    started ahead (:func:`launch_episode`), told to go now; None: started here. ``in_flight()`` is
    called at every look while the vehicle flies (after the alarm, until the touchdown), and
    ``on_stopped()`` once its processes are stopped, before the grading.
    """
    times = times or EpisodeTimes()
    t_wall = time.monotonic()
    ahead_s = 0.0
    if launched is None:
        launched = launch_episode(
            spec, workdir, times=times, config_path=config_path, sitl=sitl, world_cache=world_cache
        )
    else:
        ahead_s = t_wall - launched.t_launch
        launched.go()
    sim, comp, udp, sim_err = launched.sim, launched.comp, launched.udp, launched.sim_err
    episode_log, comp_log, record_dir = launched.episode_log, launched.comp_log, launched.record_dir
    entry: dict[str, Any] = {
        "id": spec.id,
        "kind": spec.kind,
        "scenario": spec.scenario,
        "seed": spec.seed,
        "city_seed": spec.city_seed,
        "place": spec.place if spec.kind == "city" else None,
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
    comp_lines = LineTail(comp_log)
    usage, sim_usage = ProcessSample(comp.pid), ProcessSample(sim.pid)
    marks: dict[str, float] = {"start": t_wall}  # wall clock at each phase's end (wall_phases_s)
    tail = JsonlTail(episode_log)
    log = LogWatch()
    alarm_t_s: float | None = None  # the takeover where the vehicle already holds in GUIDED
    outcome, error, infrastructure = "landed", None, False
    try:
        while log.ready is None or not recorded(record_dir, SENSORS_UP):
            log.take(tail.lines())
            if comp.poll() is not None or sim.poll() is not None:
                who = "simbridge" if sim.poll() is not None else "the companion"
                raise _EpisodeError(
                    f"{who} exited before the vehicle was ready and the sensor stream up", infrastructure=True
                )
            waited = time.monotonic() - launched.t_launch  # a held launch: its build went on meanwhile
            if log.ready is None and waited > times.ready_wall_s:
                raise _EpisodeError(
                    f"simbridge's autopilot not ready after {times.ready_wall_s:.0f} s", infrastructure=True
                )
            if log.ready is not None and waited > times.ready_wall_s + times.start_wall_s:
                raise _EpisodeError(f"no sensor stream after {waited:.0f} s", infrastructure=True)
            if STOPPING.is_set():
                raise _EpisodeError("stopped: the campaign was interrupted")
            time.sleep(0.2)
        marks["ready"] = time.monotonic()
        res = send_alarm(udp, spec.reason, spec.criticality, time.monotonic() + 30.0)
        if on_line is not None:
            on_line("alarm", (res.stdout or res.stderr).strip())
        if res.returncode != 0:
            raise _EpisodeError(f"alarm not accepted: {(res.stdout or res.stderr).strip()[:200]}")
        t_alarm = marks["alarm"] = time.monotonic()
        alarm_t_s = alarm_sim_time_s(log.ready, record_events(record_dir))
        ended = None
        while True:
            usage.sample()
            sim_usage.sample()
            log.take(tail.lines())
            if in_flight is not None and log.touchdown is None:
                in_flight()
            if on_line is not None:
                for line in comp_lines.text_lines():
                    on_line("companion", line)
            if log.touchdown is not None:
                if ended is None:
                    ended = marks["touchdown"] = time.monotonic()
                if recorded(record_dir, *RECOVERY_ENDED):
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
        sim_usage.sample()
        launched.stop()
        if on_line is not None:
            for line in comp_lines.text_lines():
                on_line("companion", line)
        comp_lines.close()
        sim_err.close()
        log.take(tail.lines(), final=True)  # what simbridge wrote since the last look
        tail.close()
        marks["stopped"] = time.monotonic()
    if on_stopped is not None:
        on_stopped()
    if log.header is not None:
        entry["city_seed"] = log.header.get("city_seed", entry["city_seed"])
        entry["world_digest"] = log.header.get("world_digest")
    takeover = log.takeover
    if takeover is None and alarm_t_s is not None:
        takeover = {"t_s": alarm_t_s}
    events = record_events(record_dir)
    entry.update(grade(log.states, takeover, log.touchdown, events))
    entry["touchdown_to_site_m"] = touchdown_to_site_m(log.touchdown, log.header, events)
    entry.update(landing_distance(log, events, spec.launch, spec.camera, world_cache=world_cache))
    entry["precision_landing"] = precision_landing_summary(events)
    entry["outcome"] = outcome if log.touchdown is None or outcome != "timeout" else "landed"
    entry["error"] = error if log.touchdown is None else None
    entry["error_kind"] = "infrastructure" if infrastructure and log.touchdown is None else None
    entry["defects"] = sum(e.get("kind") == "defect" for e in events)
    entry["last_state"] = last_state(events, log.last_vehicle)
    entry["companion"] = {
        "peak_rss_mb": round(usage.peak_rss_mb, 1),
        "peak_anon_mb": round(usage.peak_anon_mb, 1),
        "cpu_s": round(usage.cpu_s, 2),
    }
    entry["simbridge"] = {"cpu_s": round(sim_usage.cpu_s, 2)}
    marks["graded"] = time.monotonic()
    entry["wall_phases_s"] = wall_phases(marks)
    entry["wall_s"] = round(marks["graded"] - t_wall, 2)
    entry["launched_ahead_s"] = round(ahead_s, 2)
    return entry


PHASES = ("ready", "alarm", "touchdown", "stopped", "graded")  # the phases of wall_phases_s, in order


def wall_phases(marks: Mapping[str, float]) -> dict[str, float | None]:
    """Wall seconds each phase of an episode took, from ``marks`` (the wall clock as each ended; the
    ``start`` and the phases reached): ``ready`` from the start until the vehicle held and the sensor
    stream was up, ``alarm`` until the alarm was accepted, ``touchdown`` the flight, ``stopped`` until
    the recovery's end was recorded and the processes stopped, ``graded`` the grading. A phase never
    reached is None, and the next one reached counts from the last mark before it."""
    out: dict[str, float | None] = {}
    last = marks["start"]
    for name in PHASES:
        at = marks.get(name)
        if at is None:
            out[name] = None
            continue
        out[name] = round(at - last, 2)
        last = at
    return out


class _EpisodeError(Exception):
    """An episode that could not be flown; ``infrastructure``: its processes never got as far as the
    alarm (a port taken meanwhile, a process that did not start): worth another try, unlike anything
    that happens once the alarm is in."""

    def __init__(self, text: str, *, infrastructure: bool = False) -> None:
        super().__init__(text)
        self.infrastructure = infrastructure
