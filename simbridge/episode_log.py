"""The episode log: JSON lines of vehicle state (10 Hz of simulated time) and events.

Every line has ``t_s`` (simulated seconds). State lines have ``"event": "state"``; event lines
name the event: ``armed``, ``disarmed``, ``mode`` (``mode``: the new mode's name), ``failsafe``,
``touchdown`` (``pos_ned_m``, ``surface``, ``safe``, ``reasons``), ``ready`` (``pos_ned_m``,
``autopilot``, ``start``, ``time_boot_ms``: the vehicle holds at its launch pose, or on the ground can
arm; harnesses raise their alarm after it: real firmware takes tens of simulated seconds to get there;
``time_boot_ms`` is the autopilot's boot clock at that ``t_s``, so a time the companion stamped with the
autopilot's clock can be placed on the log's), ``frame`` (``time_boot_ms``, ``pos_ned_m``, ``quat_wxyz``,
``parts``: a sensor frame served, with the true pose it was rendered from, for evaluation only),
``start`` and ``stop``.

The first line, ``start``, says what was flown: ``scenario``, ``autopilot``, ``seed`` (the episode's),
``city_seed`` (the procedural city's; null for other scenarios), ``place`` (the kind of place the
procedural city is, :mod:`simbridge.world.places`; null for other scenarios), ``world_digest`` (16 hex digits
fingerprinting the static world, :meth:`simbridge.world.model.WorldGrid.digest`; null for ``flat``),
``start`` and ``home_ned_m``. Episodes with equal digests flew the same world.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any, TextIO

from simbridge.physics import VehicleState


class EpisodeLog:
    """Append-only JSON-lines writer; events are flushed at once so a crash loses no event."""

    STATE_INTERVAL_S = 0.1

    def __init__(self, path: Path | None) -> None:
        self._fh: TextIO | None = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = path.open("w", encoding="utf-8")
        self._next_state_s = 0.0
        self._lock = threading.Lock()  # real firmware: state from the lock-step thread, events from both

    def event(self, t_s: float, name: str, fields: dict[str, Any]) -> None:
        if self._fh is None:
            return
        line = json.dumps({"t_s": round(t_s, 4), "event": name, **fields}) + "\n"
        with self._lock:
            if self._fh is not None:
                self._fh.write(line)
                self._fh.flush()

    def state(
        self,
        s: VehicleState,
        mode: str,
        armed: bool,
        landed_state: int,
        battery_pct: float,
        est_pos_ned_m: tuple[float, float, float] | None = None,
    ) -> None:
        if self._fh is None or s.t_s + 1e-9 < self._next_state_s:
            return
        self._next_state_s = s.t_s + self.STATE_INTERVAL_S
        est = {"est_pos_ned_m": [round(v, 4) for v in est_pos_ned_m]} if est_pos_ned_m is not None else {}
        line = (
            json.dumps(
                {
                    "t_s": round(s.t_s, 4),
                    "event": "state",
                    "pos_ned_m": [round(v, 4) for v in s.pos_ned_m],
                    "vel_ned_m_s": [round(v, 4) for v in s.vel_ned_m_s],
                    "quat_wxyz": [round(v, 6) for v in s.quat],
                    "agl_m": round(s.height_agl_m, 3),
                    "mode": mode,
                    "armed": armed,
                    "landed_state": landed_state,
                    "battery_pct": round(battery_pct, 2),
                    **est,
                }
            )
            + "\n"
        )
        with self._lock:
            if self._fh is not None:
                self._fh.write(line)

    def close(self) -> None:
        with self._lock:
            if self._fh is not None:
                self._fh.close()
                self._fh = None
