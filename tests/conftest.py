"""Shared fixtures: simbridge as a real process on a loopback UDP port, and a pymavlink client."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")

from landfall_eval.processes import sped_up_env, stop_process
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from tests.mavclient import MavClient
from tests.views import LAUNCH, SCENE, WEATHERS, render, world


def pytest_configure(config: pytest.Config) -> None:
    """Compile simbridge's numba kernels once, before any test worker starts (``cache=True`` keeps them
    in __pycache__): on a fresh clone every xdist worker and every simulator process would otherwise
    compile the same kernels at once, two minutes each on two cores. A few seconds once they are cached."""
    if hasattr(config, "workerinput") or os.environ.get("LANDFALL_NO_WARMUP") == "1":
        return  # an xdist worker (the controller warmed them), or asked not to
    from tests.warmup import warm_up

    warm_up()


@pytest.fixture
def arducopter() -> Path:
    """ArduPilot's SITL build, or a skip saying how to get it (a failure where CI requires it)."""
    from simbridge.sitl import SitlNotFound, find_arducopter

    try:
        return find_arducopter()
    except SitlNotFound as exc:
        if os.environ.get("LANDFALL_REQUIRE_SITL") == "1":
            pytest.fail(f"LANDFALL_REQUIRE_SITL=1 but {exc}")
        pytest.skip(f"real ArduCopter SITL not available: {exc}")


@pytest.fixture
def px4() -> Path:
    """PX4's SITL build (px4_sitl_default), or a skip saying how to get it (a failure where CI
    requires it)."""
    from simbridge.px4_sitl import find_px4
    from simbridge.sitl import SitlNotFound

    try:
        return find_px4()
    except SitlNotFound as exc:
        if os.environ.get("LANDFALL_REQUIRE_SITL") == "1":
            pytest.fail(f"LANDFALL_REQUIRE_SITL=1 but {exc}")
        pytest.skip(f"real PX4 SITL not available: {exc}")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class SimProcess:
    """A running ``simbridge`` process and the paths it writes."""

    def __init__(
        self, proc: subprocess.Popen[bytes], port: int, episode_log: Path, stderr_path: Path
    ) -> None:
        self.proc = proc
        self.port = port
        self.episode_log = episode_log
        self.stderr_path = stderr_path
        self._read_to = 0  # bytes of the episode log parsed into _rows
        self._rows: list[dict[str, object]] = []

    def events(self, name: str | None = None) -> list[dict[str, object]]:
        """The episode log's events so far (``name``: of that kind only). Tests poll this while a
        flight runs, so only what was appended since the last call is read and parsed: a real-firmware
        flight writes thousands of state lines, and parsing them all again at every poll cost a test
        seconds of CPU beside the flight it waits on."""
        try:
            with self.episode_log.open("rb") as fh:
                if fh.seek(0, 2) < self._read_to:  # written anew (a test reused the path): start over
                    self._read_to, self._rows = 0, []
                fh.seek(self._read_to)
                data = fh.read()
        except FileNotFoundError:
            return []
        complete = data[: data.rfind(b"\n") + 1]  # simbridge may be writing the last line right now
        self._read_to += len(complete)
        self._rows.extend(json.loads(line) for line in complete.splitlines() if line.strip())
        return [r for r in self._rows if name is None or r.get("event") == name]

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)


@pytest.fixture
def start_sim(tmp_path: Path) -> Iterator[Callable[..., SimProcess]]:
    """Start simbridge sending to a fresh loopback port; stopped (SIGTERM) after the test."""
    with sim_starter(tmp_path) as start:
        yield start


@contextlib.contextmanager
def sim_starter(tmp_path: Path) -> Iterator[Callable[..., SimProcess]]:
    """What ``start_sim`` gives, for any scope: every simbridge started is stopped on leaving."""
    started: list[SimProcess] = []

    def start(*args: str, port: int | None = None) -> SimProcess:
        port = port or free_udp_port()
        log = tmp_path / f"episode-{len(started)}.jsonl"
        err = tmp_path / f"simbridge-{len(started)}.stderr"
        cmd = [
            sys.executable, "-m", "simbridge",
            "--mavlink", f"udpout:127.0.0.1:{port}",
            "--episode-log", str(log),
            *args,
        ]  # fmt: skip
        with err.open("wb") as err_fh:  # the child keeps its own copy of the descriptor
            proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err_fh)
        sim = SimProcess(proc, port, log, err)
        started.append(sim)
        return sim

    try:
        yield start
    finally:
        for sim in started:
            sim.stop()


@pytest.fixture
def client_for() -> Iterator[Callable[..., MavClient]]:
    clients: list[MavClient] = []

    def make(port: int, **kwargs: object) -> MavClient:
        c = MavClient(port, **kwargs)  # type: ignore[arg-type]
        clients.append(c)
        return c

    yield make
    for c in clients:
        c.close()


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Rig:
    """simbridge + companion as real processes wired over loopback UDP and the sensor socket."""

    def __init__(
        self,
        sim: SimProcess,
        companion: subprocess.Popen[bytes],
        port: int,
        log: Path,
        launch: Callable[[], tuple[subprocess.Popen[bytes], Path]] | None = None,
    ) -> None:
        self.sim = sim
        self.companion = companion
        self.port = port
        self.companion_log = log
        self._launch = launch

    def kill_and_restart_companion(self) -> None:
        """SIGKILL the companion (no clean-up of any kind) and start it again with the same
        arguments, as systemd's Restart=on-failure would; its new log replaces ``companion_log``."""
        assert self._launch is not None
        self.companion.kill()
        self.companion.wait()
        self.companion, self.companion_log = self._launch()

    def alarm(self, *args: str, timeout_s: float = 10.0) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "trigger_alarm.py", "--mavlink", f"udpout:127.0.0.1:{self.port}",
               "--timeout", str(timeout_s), *args]  # fmt: skip
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s + 30)

    def log_text(self) -> str:
        return self.companion_log.read_text() if self.companion_log.exists() else ""

    def alarm_accepted(self, *args: str, tries: int = 20) -> subprocess.CompletedProcess[str]:
        """Send an alarm until the companion accepts it: right after start-up it answers 'refused for
        now' while the first heartbeats and telemetry are still on their way. Returns the last try."""
        out = self.alarm(*args)
        for _ in range(tries):
            if out.returncode == 0:
                break
            time.sleep(0.5)
            out = self.alarm(*args)
        return out

    def wait_log(self, text: str, timeout_s: float = 30.0) -> str:
        """Poll the companion's log (another process writes it) until ``text`` appears."""
        deadline = time.monotonic() + timeout_s
        while text not in self.log_text():
            assert time.monotonic() < deadline, (
                f"no {text!r} in the companion log:\n{self.log_text()[-3000:]}"
            )
            time.sleep(0.2)
        return self.log_text()


@pytest.fixture
def start_rig(start_sim: Callable[..., SimProcess], tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """simbridge (``sim_args``) sending to a companion (``companion_args``) on a fresh port."""
    with rig_starter(start_sim, tmp_path) as start:
        yield start


@contextlib.contextmanager
def rig_starter(start_sim: Callable[..., SimProcess], tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """What ``start_rig`` gives, for any scope: every companion started is stopped on leaving."""
    procs: list[subprocess.Popen[bytes]] = []

    def start(
        sim_args: list[str],
        companion_args: list[str] | None = None,
        env: dict[str, str] | None = None,
        sensors_via: Callable[[int], int] | None = None,
        mavlink_via: Callable[[int], int] | None = None,
    ) -> Rig:
        """``sensors_via(port)``: the port the companion should use for simbridge's sensor ``port``
        (a relay's); ``mavlink_via(port)``: the port simbridge should send to for the companion's
        MAVLink ``port`` (a relay's)."""
        port = free_udp_port()
        sensors = free_tcp_port()
        sim_to = mavlink_via(port) if mavlink_via is not None else port
        sim = start_sim(*sim_args, "--sensors", f"127.0.0.1:{sensors}", port=sim_to)
        to = sensors_via(sensors) if sensors_via is not None else sensors
        cmd = [sys.executable, "-m", "companion", "--mavlink", f"udp:{port}", "--sensors",
               f"127.0.0.1:{to}", *(companion_args or [])]  # fmt: skip
        speed = float(sim_args[sim_args.index("--speed") + 1]) if "--speed" in sim_args else 1.0
        env = {**sped_up_env(speed), **(env or {})}

        def launch() -> tuple[subprocess.Popen[bytes], Path]:
            log = tmp_path / f"companion-{len(procs)}.log"
            with log.open("wb") as fh:
                proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env={**os.environ, **env})
            procs.append(proc)
            return proc, log

        proc, log = launch()
        return Rig(sim, proc, port, log, launch)

    try:
        yield start
    finally:
        for p in procs:
            stop_process(p)


# Scenes for the onboard-reasoner tests (tests/views.py).
@pytest.fixture(scope="module")
def city() -> LiveWorld:
    return world("scenario1")


@pytest.fixture(scope="module")
def scene() -> LiveWorld:
    return world(str(SCENE))


@pytest.fixture(scope="module")
def launch(city: LiveWorld) -> dict[str, Frame]:
    return {weather: render(city, LAUNCH, weather) for weather in WEATHERS}


# A real MQTT broker (mosquitto, from Debian's packages; .ci/run installs it when missing).
class Broker:
    def __init__(self, tmp: Path, port: int | None = None) -> None:
        exe = shutil.which("mosquitto") or next(
            (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()), None
        )
        if exe is None:
            pytest.fail("mosquitto is not installed: apt-get install mosquitto (.ci/run does it)")
        self.port = port or free_tcp_port()
        conf = tmp / f"mosquitto-{self.port}.conf"
        conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
        self.log = tmp / f"mosquitto-{self.port}.log"
        with self.log.open("wb") as fh:
            self.proc = subprocess.Popen([exe, "-c", str(conf)], stdout=fh, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 10
        while True:  # until it accepts connections
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", self.port), 0.5):
                break
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"mosquitto did not start: {self.log.read_text()}")
            time.sleep(0.05)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=10)


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Callable[..., Broker]]:
    """Start mosquitto brokers on loopback (a fresh port, or the one given); stopped after the test."""
    started: list[Broker] = []

    def start(port: int | None = None) -> Broker:
        started.append(Broker(tmp_path, port))
        return started[-1]

    yield start
    for b in started:
        b.stop()
