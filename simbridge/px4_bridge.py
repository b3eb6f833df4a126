"""``simbridge --autopilot px4-sitl``: the same world, sensors, episode log and grading, flown by real PX4
firmware (SITL) instead of the emulation.

simbridge starts PX4 as its child (:class:`simbridge.px4_sitl.Px4Process`: airframe 10016 ``none_iris``,
instance ``-i N``, a working directory of its own) and is the simulator it connects to
(:class:`simbridge.px4_sitl.HilLockStep`, TCP 4560 + N, lock step). The vehicle starts on the ground at
the launch point, where PX4 boots and sets its home from the first GPS fix, so its local frame's origin
is the launch point (a companion gets its local frame from the autopilot, as on a real vehicle).
PX4's own MAVLink instances: the companion's (``--mavlink udpout:HOST:PORT``), the API/offboard link
(MAVSDK on 14540 + N) and the ground-station link, which goes to simbridge's watcher
(:mod:`simbridge.px4_pilot`): modes and arming for the episode log and, with ``--start air``, the flight to
the launch pose before the episode's ``ready`` event. Touchdowns are detected on the world's truth, as
with ArduCopter SITL, and graded the same.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from simbridge.px4_pilot import Px4Pilot
from simbridge.px4_sitl import HilLockStep, Px4Process, claim_px4_instance, find_px4
from simbridge.sitl_bridge import FirmwareBridge
from simbridge.sitl_pilot import SitlPilot

__all__ = ["Px4SitlBridge"]


class Px4SitlBridge(FirmwareBridge):
    """Real PX4 SITL in place of the emulation (module docstring)."""

    firmware = "PX4 SITL"

    def _find_binary(self) -> None:
        self.binary = find_px4(self.config.px4)

    async def _start_firmware(self, stack: contextlib.AsyncExitStack) -> tuple[SitlPilot, HilLockStep]:
        cfg = self.config
        instance, server = claim_px4_instance()
        stack.callback(server.close)
        pilot = await self._open_pilot(stack, Px4Pilot)
        proc = Px4Process(
            self.binary, instance, companion=(self.target.host, self.target.port), pilot_port=pilot.port,
            logger=self.log,
        )  # fmt: skip
        # PX4 sets MAV_SYS_ID to the instance + 1 before these: --sysid wins
        proc.params.update(MAV_SYS_ID=cfg.system_id, MIS_TAKEOFF_ALT=round(self.scenario.launch_height_m, 2))
        pilot.ready = proc.ready_for_takeoff.is_set
        lock = HilLockStep(
            server, self.vehicle, cfg.origin, proc, np.random.default_rng(cfg.seed + 7), speed=cfg.speed,
            on_state=self._on_state,
        )  # fmt: skip
        self._launch(stack, proc, lock, instance)
        return pilot, lock

    def _estimator_ready(self, pilot: SitlPilot) -> bool:
        return pilot.can_start() and pilot.view.heartbeat

    def _gps_offset(self, offset_ne_m: tuple[float, float]) -> None:
        """simbridge is PX4's GPS (HIL_GPS): its next fixes carry the offset."""
        if self.lockstep is not None:
            self.lockstep.gps_offset_ne_m = offset_ne_m

    def _stop_fields(self) -> dict[str, Any]:
        lock = self.lockstep
        pace = lock.lockstep_rate() if lock else None
        return {
            "frames": lock.steps if lock else 0,
            "actuator_msgs": lock.actuator_msgs if lock else 0,
            "lockstep_wall_s": round(pace[0], 3) if pace else None,
            "lockstep_sim_s": round(pace[1], 3) if pace else None,
        }
