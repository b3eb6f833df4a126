"""The operator's controls from a real ground station program: MAVProxy (the dev extra installs it) on
the companion's link reads and sets its parameters, raises an alarm and cancels the recovery with
``long`` commands, as docs/companion.md shows."""

from __future__ import annotations

import contextlib
import queue
import re
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.conftest import Rig

pytestmark = pytest.mark.slow


class MavProxy:
    """``mavproxy.py`` as a ground station on ``udpout`` to the companion's port, targeting its component
    (191); commands written to its console one at a time, its output read line by line."""

    def __init__(self, port: int, cwd: Path) -> None:
        exe = shutil.which("mavproxy.py") or str(
            Path(__file__).resolve().parent.parent / ".venv/bin/mavproxy.py"
        )
        if not Path(exe).exists():
            pytest.fail("mavproxy.py not found: pip install -e '.[dev]' installs MAVProxy")
        self.proc = subprocess.Popen(
            [exe, f"--master=udpout:127.0.0.1:{port}", "--source-system", "255", "--target-system", "1",
             "--target-component", "191", "--nowait", "--default-modules=param,cmdlong"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd,
        )  # fmt: skip
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def run(self, command: str) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(BrokenPipeError, ValueError):  # it exited (its output says why)
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()

    def expect(self, pattern: str, timeout_s: float = 30.0) -> str:
        """The first line from now on that matches ``pattern`` (a regular expression)."""
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            self.seen.append(line)
            if re.search(pattern, line):
                return line
        raise AssertionError(
            f"MAVProxy never printed {pattern!r}; it printed:\n" + "\n".join(self.seen[-40:])
        )

    def close(self) -> None:
        self.run("exit")
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for pipe in (self.proc.stdin, self.proc.stdout):
            if pipe is not None:
                pipe.close()


@pytest.mark.timeout(300)
def test_mavproxy_reads_and_sets_parameters_raises_an_alarm_and_cancels_it(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """MAVProxy fetches the companion's seven parameters, shows one, sets the cancel mode to land and
    is told why 99 is no RC channel; ``long USER_1 1 1`` (GPS spoofing, high) starts a recovery and
    ``long USER_2`` cancels it: the companion releases the vehicle into PX4's AUTO.LAND."""
    from tests.test_companion_e2e import _wait_for_companion

    rig = start_rig(["--scenario", "scenario1", "--autopilot", "px4", "--speed", "4"])
    mp = MavProxy(rig.port, tmp_path)
    try:
        mp.expect(r"Received 7 parameters")
        mp.run("param show LF_CANCEL_MODE")
        mp.expect(r"LF_CANCEL_MODE\s+0\.0$")
        mp.run("param set LF_CANCEL_MODE 1")
        rig.wait_log("parameter LF_CANCEL_MODE set to 1 by system 255")
        mp.run("param show LF_CANCEL_MODE")
        mp.expect(r"LF_CANCEL_MODE\s+1\.0$")
        mp.run("param set LF_INH_RC_CH 99")
        mp.expect(r"LF_INH_RC_CH: 99 outside 0\.\.18")
        _wait_for_companion(rig)
        for _ in range(20):  # "refused for now" until the telemetry and a frame are fresh
            mp.run("long USER_1 1 1")
            if "ACCEPTED" in mp.expect(r"USER_1: "):
                break
            time.sleep(1.0)
        else:
            raise AssertionError("the alarm was never accepted:\n" + "\n".join(mp.seen[-20:]))
        rig.wait_log("alarm ", timeout_s=30)
        mp.run("long USER_2")
        mp.expect(r"USER_2: ACCEPTED")
        rig.wait_log("recovery cancelled by system 255: vehicle in LAND", timeout_s=30)
        deadline = time.monotonic() + 30
        while "AUTO.LAND" not in [e["mode"] for e in rig.sim.events("mode")]:
            assert time.monotonic() < deadline, rig.sim.events("mode")
            time.sleep(0.5)  # polling a file another process writes
    finally:
        mp.close()
