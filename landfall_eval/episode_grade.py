"""What an episode's processes wrote, read back into its results entry (``episodes[]`` in docs/bench.md):
simbridge's episode log as it comes (:class:`LogWatch`), the companion's flight record
(:func:`record_events`), the ground-truth grade with times, trajectory and reasoner calls (:func:`grade`),
the landing's distance to the site aimed at, the precision landing, and where the episode stood at its
end (:func:`last_state`). Pure functions of those files' rows: :mod:`landfall_eval.episode` runs the
processes and calls them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from landfall_eval.grading import kinematic_lower_bound_s, surface_class
from landfall_eval.landing import landing_distance_m

__all__ = [
    "LogWatch",
    "alarm_sim_time_s",
    "describe_last_state",
    "grade",
    "landing_distance",
    "last_state",
    "match_video_frames",
    "precision_landing_summary",
    "record_events",
    "recorded",
    "touchdown_to_site_m",
    "video_frames_by_stamp",
]

TRAJECTORY_STEP_S = 1.0  # one trajectory point per simulated second
CONTROL_MODES = ("OFFBOARD", "GUIDED")


def record_events(record_dir: Path) -> list[dict[str, Any]]:
    """Every event of the companion's flight record under ``record_dir`` (its sessions in order)."""
    events: list[dict[str, Any]] = []
    for path in sorted(record_dir.glob("*/events.jsonl")):
        events += [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    return events


def recorded(record_dir: Path, *kinds: str) -> bool:
    """Whether the companion's flight record holds an event of one of ``kinds`` yet (it replaces
    ``events.jsonl`` whole and atomically with each event: what is read is always complete)."""
    return any(e.get("kind") in kinds for e in record_events(record_dir))


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


def landing_distance(
    log: LogWatch,
    events: list[dict[str, Any]],
    launch: tuple[float, float, float] | None,
    camera: str,
    *,
    world_cache: Path | None = None,
) -> dict[str, Any]:
    """``landing_distance_m`` and ``landing_target_ned_m`` of an entry (:mod:`landfall_eval.landing`):
    both None when the episode does not say (no touchdown, nothing confirmed) or the world built to
    cast the pixel is not the one flown (then ``landing_error`` says so; else it is None). ``launch`` and
    ``camera`` are the episode's (:class:`~landfall_eval.episode.EpisodeSpec`)."""
    at = tuple(round(v, 2) for v in launch) if launch is not None else None
    out: dict[str, Any] = {"landing_distance_m": None, "landing_target_ned_m": None, "landing_error": None}
    frames = log.frames if camera == "socket" else video_frames_by_stamp(log.camera_frames, events)
    try:
        got = landing_distance_m(
            log.touchdown, log.header, frames, events, launch=at, world_cache=world_cache
        )
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


def grade(
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
        "nearest_person_m": None,
        "nearest_person_last_10m_m": None,
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
            nearest_person_m=touchdown.get("nearest_person_m"),
            nearest_person_last_10m_m=touchdown.get("nearest_person_last_10m_m"),
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


def last_state(events: list[dict[str, Any]], vehicle: dict[str, Any] | None) -> dict[str, Any] | None:
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
