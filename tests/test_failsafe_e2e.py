"""The fail-safe for the companion's own defects, end to end: every stage of a recovery made
to raise (the test-only fault hook, companion/faults.py, turned on through ``LANDFALL_TEST_FAULT``).
Every time, the defect is announced to the ground station as a critical STATUSTEXT, recorded with its
traceback, and the vehicle still comes down: a touchdown that simbridge grades, never a hover in the
autopilot's hold until the battery decides. One flight per stage (the behaviour), the stages taking
PX4's and ArduPilot's flavours in turn (``FLAVOUR_OF``), so both land through each kind of stage: before
a site is measured and after."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil

from companion.faults import STAGES
from tests.conftest import Rig

pytestmark = pytest.mark.slow

MAV_SEVERITY_CRITICAL = 2
# stages reached only after a site was measured: the vehicle lands at the best of them, a roof
AFTER_A_SITE = ("ipm", "move", "confirm", "descend", "land")


class GroundPeer:
    """A ground station on the companion's UDP endpoint: it says hello (heartbeats), so the
    companion counts it as a peer, and keeps every STATUSTEXT the companion sends it."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.texts: list[Any] = []
        self.heard = False  # the companion's own heartbeat reached us: it counts us as a peer
        self._last_hb = 0.0

    def pump(self) -> None:
        if time.monotonic() - self._last_hb > 0.5:
            self.conn.mav.heartbeat_send(6, 8, 0, 0, 4)  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID
            self._last_hb = time.monotonic()
        while (m := self.conn.recv_match(blocking=False)) is not None:
            if m.get_type() == "STATUSTEXT":
                self.texts.append(m)
            elif m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 191:
                self.heard = True

    def join(self, timeout_s: float = 20.0) -> None:
        """Say hello until the companion answers with its heartbeat."""
        deadline = time.monotonic() + timeout_s
        while not self.heard:
            assert time.monotonic() < deadline, "the companion never sent its heartbeat to the ground peer"
            self.pump()
            time.sleep(0.05)

    def close(self) -> None:
        self.conn.close()


def _events(record: Path) -> list[dict[str, Any]]:
    (events,) = record.glob("*/events.jsonl")
    return [json.loads(line) for line in events.read_text().splitlines() if line.strip()]


def _fly_with_fault(
    start_rig: Callable[..., Rig], tmp_path: Path, autopilot: str, stage: str
) -> tuple[dict[str, Any], Rig, GroundPeer, list[dict[str, Any]]]:
    record = tmp_path / "record"
    rig = start_rig(
        ["--scenario", "scenario1", "--autopilot", autopilot, "--speed", "10"],
        ["--record", str(record)],
        env={"LANDFALL_TEST_FAULT": stage},
    )
    gcs = GroundPeer(rig.port)
    try:
        rig.wait_log("sensor stream connected", timeout_s=60)
        gcs.join()  # a ground station on the link before anything goes wrong
        out = rig.alarm_accepted("--reason", "GPS spoofing detected", "--criticality", "high")
        assert out.returncode == 0, out.stdout + out.stderr
        deadline = time.monotonic() + 240
        touchdown: list[dict[str, Any]] = []
        while not touchdown or "recovery ended" not in rig.log_text():
            gcs.pump()
            assert time.monotonic() < deadline, f"no touchdown and end\n{rig.log_text()[-3000:]}"
            assert rig.companion.poll() is None, rig.log_text()[-3000:]
            touchdown = rig.sim.events("touchdown")  # type: ignore[assignment]
            time.sleep(0.2)  # polling files and a socket other processes write
        for _ in range(10):  # the last texts may still be in flight
            gcs.pump()
            time.sleep(0.05)
        return touchdown[0], rig, gcs, _events(record)
    finally:
        gcs.close()


FLAVOUR_OF = {stage: ("px4", "ardupilot")[k % 2] for k, stage in enumerate(STAGES)}


def test_the_stages_take_both_flavours_before_and_after_a_site() -> None:
    for flavour in ("px4", "ardupilot"):
        mine = {stage for stage, f in FLAVOUR_OF.items() if f == flavour}
        assert mine & set(AFTER_A_SITE)
        assert mine - set(AFTER_A_SITE)


@pytest.mark.parametrize("stage", STAGES)
def test_a_defect_in_any_stage_still_ends_in_a_graded_touchdown(
    start_rig: Callable[..., Rig], tmp_path: Path, stage: str
) -> None:
    td, rig, gcs, events = _fly_with_fault(start_rig, tmp_path, FLAVOUR_OF[stage], stage)
    log = rig.log_text()
    # graded: simbridge's ground truth says what it landed on and whether that was safe
    assert isinstance(td["safe"], bool), td
    assert td["surface"], td
    assert f"test fault injected in stage {stage!r}" in log
    assert "recovery ended: landed" in log, log[-3000:]
    # announced as critical, to the ground station
    critical = [
        m for m in gcs.texts if m.severity == MAV_SEVERITY_CRITICAL and "internal error, landing" in m.text
    ]
    assert critical, [(m.severity, m.text) for m in gcs.texts]
    assert "InjectedFault" in critical[0].text
    # recorded with its traceback, naming the stage that raised
    (defect,) = [e for e in events if e["kind"] == "defect"]
    assert "InjectedFault" in defect["error"]
    assert "Traceback (most recent call last)" in defect["traceback"]
    assert "faults.py" in defect["traceback"]
    if stage in AFTER_A_SITE:
        # a site was measured before the defect: the vehicle lands there, not where it happened to be
        assert td["surface"] in ("rooftop_clear", "rooftop_cluttered"), (td, log[-3000:])
        assert td["safe"] is True, (td, log[-3000:])
