"""Fakes at the recovery's boundary, for building one part of it alone (tests/test_recovery_parts.py,
tests/test_chain_properties.py, tests/test_search.py, tests/test_recovery_defects.py): a controller
that arrives at once, frames from a list, a reasoner with set answers and a record that keeps its
events. The telemetry is the real :class:`~companion.telemetry.TelemetryCache`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.alarms import Alarm, Criticality, ReasonCode
from companion.fence import Fence
from companion.flavour import PX4, Flavour, Mode
from companion.guidance.frames import PinholeCamera
from companion.perception.surface_id import Candidate
from companion.precision import PrecisionLanding
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest
from companion.recovery.core import FrameUnavailable, RecoveryContext, RecoveryParams
from companion.telemetry import TelemetryCache
from landfall_link.sensorstream import SensorFrame


class FakeController:
    """Arrives at every target at once (the telemetry's position becomes it) and lands at once; notes
    what it was asked."""

    flavour: Flavour = PX4

    def __init__(self, tm: TelemetryCache) -> None:
        self.tm = tm
        self.gotos: list[tuple[float, float, float]] = []
        self.retargets: list[tuple[float, float]] = []
        self.set_targets: list[tuple[float, float, float]] = []
        self.lands: list[Mode] = []
        self.precision: PrecisionLanding | None = None
        self.fence: Fence | None = None
        self.released = 0
        self.landing_targets: list[tuple[tuple[float, float, float], int]] = []  # body FRD, time_usec

    async def goto(
        self, n: float, e: float, d: float, *, tolerance_m: float, speed_m_s: float, timeout_s: float
    ) -> None:
        self.gotos.append((n, e, d))
        self.tm.state.pos_ned_m = (n, e, d)

    def retarget(self, n: float, e: float) -> None:
        self.retargets.append((n, e))

    @property
    def target(self) -> tuple[float, float, float, float] | None:
        """The last position asked for (a goto's or a set_target's), heading 0."""
        asked = [*self.gotos, *self.set_targets]
        return (*asked[-1], 0.0) if asked else None

    def set_target(self, n: float, e: float, d: float, yaw: float | None = None) -> None:
        self.set_targets.append((n, e, d))

    def check_interruption(self) -> None:
        return None

    def send_landing_target(self, target_frd_m: tuple[float, float, float], time_usec: int) -> None:
        self.landing_targets.append((target_frd_m, time_usec))

    async def land(self, timeout_s: float, mode: Mode = Mode.LAND) -> None:
        self.lands.append(mode)
        self.tm.state.armed = False  # down: disarmed

    async def engage(self) -> None:
        return None

    async def release(self) -> None:
        self.released += 1


class FakeFrames:
    """The frames it was given, one a call, the last one again and again; ``FrameUnavailable`` the
    first ``fails`` times, and always with none. ``calls`` counts the asks."""

    def __init__(self, *frames: Any, fails: int = 0) -> None:
        self.frames = list(frames)
        self.fails = fails
        self.calls = 0

    async def __call__(self) -> Any:
        self.calls += 1
        if self.fails > 0 or not self.frames:
            self.fails -= 1
            raise FrameUnavailable("no frame in this test")
        return self.frames.pop(0) if len(self.frames) > 1 else self.frames[0]


class Said:
    """The announcements (STATUSTEXT), kept: ``texts`` without their severities."""

    def __init__(self) -> None:
        self.said: list[tuple[int, str]] = []

    def __call__(self, severity: int, text: str) -> None:
        self.said.append((severity, text))

    @property
    def texts(self) -> list[str]:
        return [text for _severity, text in self.said]


@dataclass
class FakeReasoner:
    """Ranks in the order given (Surface ID's order by default) and confirms with ``decision``; keeps
    the requests."""

    order: tuple[int, ...] | None = None
    decision: Decision = field(default_factory=lambda: Decision(True, "clear roof", "onboard", 0.0))
    ranks: list[RankRequest] = field(default_factory=list)
    confirms: list[ConfirmRequest] = field(default_factory=list)

    async def rank(self, request: RankRequest) -> Ranking:
        self.ranks.append(request)
        order = self.order if self.order is not None else tuple(range(len(request.crops)))
        return Ranking(order, "as told", "fake", 0.0)

    async def confirm(self, request: ConfirmRequest) -> Decision:
        self.confirms.append(request)
        return self.decision

    async def aclose(self) -> None:
        return None


class KeptRecord:
    """A flight record that keeps its events in memory and saves no image."""

    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, Any]]] = []

    def record_event(self, kind: str, fields: dict[str, Any]) -> None:
        self.events.append((kind, fields))

    def save_image(self, name: str, rgb: Any) -> Any:
        return None

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]

    def of(self, kind: str) -> list[dict[str, Any]]:
        return [f for k, f in self.events if k == kind]


def context(
    *frames: Any,
    fails: int = 0,
    pos_ned_m: tuple[float, float, float] = (0.0, 0.0, -50.0),
    criticality: Criticality = Criticality.HIGH,
    params: RecoveryParams | None = None,
) -> RecoveryContext:
    """A recovery's context on fakes: a vehicle hovering at ``pos_ned_m`` (the rangefinder reads the
    ground at down 0), ``frames`` to be asked for (:class:`FakeFrames`, failing ``fails`` times), a
    :class:`KeptRecord` and the announcements kept (:class:`Said`)."""
    tm = TelemetryCache(1)
    tm.state.pos_ned_m = pos_ned_m
    tm.state.armed = True
    tm.state.rangefinder_m = -pos_ned_m[2]
    alarm = Alarm(ReasonCode.OTHER, criticality, "test", (0, 0), 0.0)
    ctl: Any = FakeController(tm)
    return RecoveryContext(
        alarm,
        ctl,
        tm,
        FakeFrames(*frames, fails=fails),
        Said(),
        params or RecoveryParams(),
        KeptRecord(),
    )


def frame(
    *,
    image: np.ndarray | None = None,
    lidar_frd: np.ndarray | None = None,
    pos_ned_m: tuple[float, float, float] = (0.0, 0.0, -50.0),
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    rangefinder_m: float = 50.0,
    camera: PinholeCamera | None = None,
    time_boot_ms: int = 12_000,
) -> SensorFrame:
    """A sensor frame as the sensor stream brings one (level by default, its camera looking down with
    a 90 degree field of view, 64 x 48 pixels)."""
    cam = camera or PinholeCamera.from_hfov(64, 48, 90.0)
    return SensorFrame(
        t_s=0.0,
        time_boot_ms=time_boot_ms,
        pos_ned_m=pos_ned_m,
        quat_wxyz=quat_wxyz,
        rangefinder_m=rangefinder_m,
        fx=cam.fx,
        fy=cam.fy,
        cx=cam.cx,
        cy=cam.cy,
        width=cam.width,
        height=cam.height,
        weather="clear",
        image_rgb=image,
        lidar_frd=lidar_frd,
    )


def candidate(index: int, site_ned_m: tuple[float, float, float] | None = None, **kw: Any) -> Candidate:
    """A candidate box at the image's top left (its centre at pixel (5, 5)) with a site where given."""
    return Candidate(index, (0, 0, 10, 10), (5.0, 5.0), site_ned_m=site_ned_m, **kw)
