"""``python -m simbridge.demo``: one simulated descent-and-landing through real MAVLink.

It starts simbridge (PX4 flavour, airborne 100 m above the origin), then acts as the companion
will: streams offboard setpoints, switches to OFFBOARD, flies to a landing site, descends in stages
to 80 % of the rangefinder distance each time, hands over to AUTO.LAND at 5 m and waits for the
touchdown. The summary comes from simbridge's ground truth (its episode log).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from simbridge.link import MavlinkUdpLink

POSITION_YAW_MASK = 2552
DESCENT_FRACTION = 0.8
FINAL_LAND_M = 5.0


class Ground:
    """Latest telemetry from the vehicle, filled by the link's message handler."""

    def __init__(self) -> None:
        self.pos: tuple[float, float, float] | None = None
        self.range_m: float | None = None
        self.custom_mode = 0
        self.armed = True
        self.acks: asyncio.Queue[Any] = asyncio.Queue()
        self.texts: list[str] = []

    def on_message(self, msg: Any, addr: tuple[str, int]) -> None:
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED":
            self.pos = (msg.x, msg.y, msg.z)
        elif kind == "DISTANCE_SENSOR":
            self.range_m = msg.current_distance / 100
        elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
            self.custom_mode = msg.custom_mode
            self.armed = bool(msg.base_mode & 128)
        elif kind == "COMMAND_ACK":
            self.acks.put_nowait(msg)
        elif kind == "STATUSTEXT":
            self.texts.append(msg.text)


async def _wait(cond: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise TimeoutError(f"demo: timed out waiting for {what}")
        await asyncio.sleep(0.05)


async def _command(link: MavlinkUdpLink, g: Ground, command: int, *params: float) -> int:
    p = [*params, *([0.0] * (7 - len(params)))]
    link.send(link.mav.command_long_encode(1, 1, command, 0, *p))
    async with asyncio.timeout(5):
        while True:
            ack = await g.acks.get()
            if ack.command == command:
                return int(ack.result)


async def fly(port: int, site_ne: tuple[float, float], speed: float) -> None:
    g = Ground()
    async with MavlinkUdpLink(f"udpin:127.0.0.1:{port}", 255, 190, g.on_message) as link:
        await _wait(lambda: g.pos is not None and g.range_m is not None, 30, "telemetry")
        assert g.pos is not None
        target = [g.pos[0], g.pos[1], g.pos[2]]

        async def stream() -> None:
            while True:
                link.send(link.mav.set_position_target_local_ned_encode(
                    0, 1, 1, 1, POSITION_YAW_MASK, *target, 0, 0, 0, 0, 0, 0, 0.0, 0.0))  # fmt: skip
                await asyncio.sleep(0.05 / speed)

        streamer = asyncio.create_task(stream())
        try:
            print(f"[demo] vehicle at {g.range_m:.0f} m above ground; streaming setpoints", flush=True)
            await asyncio.sleep(1.5 / speed)
            result = await _command(link, g, mavlink2.MAV_CMD_DO_SET_MODE, 1, 6, 0)
            if result != 0:
                raise RuntimeError(f"OFFBOARD refused (MAV_RESULT {result})")
            print(f"[demo] OFFBOARD; flying to site N {site_ne[0]:.0f} m, E {site_ne[1]:.0f} m", flush=True)
            target[0], target[1] = site_ne

            def arrived() -> bool:
                p = g.pos
                return p is not None and math.dist(p, target) < 0.5

            await _wait(arrived, 120 / speed + 30, "arrival over the site")
            step = 0
            while g.range_m is not None and g.range_m > FINAL_LAND_M:
                step += 1
                keep = max(DESCENT_FRACTION * g.range_m, FINAL_LAND_M - 0.5)  # height left for a look
                target[2] += g.range_m - keep
                print(
                    f"[demo] descent step {step}: rangefinder {g.range_m:5.1f} m -> {keep:5.1f} m", flush=True
                )
                await _wait(arrived, 120 / speed + 30, "descent step")
            print(f"[demo] rangefinder {g.range_m:.1f} m <= {FINAL_LAND_M:.0f} m: handing over to AUTO.LAND",
                  flush=True)  # fmt: skip
            if await _command(link, g, mavlink2.MAV_CMD_NAV_LAND) != 0:
                raise RuntimeError("AUTO.LAND refused")
        finally:
            streamer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await streamer
        await _wait(lambda: not g.armed, 120 / speed + 30, "touchdown and disarm")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--speed", type=float, default=4.0, help="simulation speed (simulated s per wall s)")
    ap.add_argument("--site", default="40,25", help="landing site N,E in metres from the origin")
    ap.add_argument("--out", type=Path, default=Path("runs/demo"), help="where the episode log goes")
    ap.add_argument("--port", type=int, default=14551, help="loopback UDP port between the two processes")
    args = ap.parse_args(argv)
    site = tuple(float(v) for v in args.site.split(","))
    if len(site) != 2:
        ap.error("--site: expected N,E")
    args.out.mkdir(parents=True, exist_ok=True)
    log = args.out / "episode.jsonl"
    cmd = [sys.executable, "-m", "simbridge", "--mavlink", f"udpout:127.0.0.1:{args.port}",
           "--speed", str(args.speed), "--episode-log", str(log), "--log-level", "WARNING"]  # fmt: skip
    print(f"[demo] starting simbridge: {' '.join(cmd[1:])}", flush=True)
    sim = subprocess.Popen(cmd)
    t0 = time.monotonic()
    try:
        asyncio.run(fly(args.port, (site[0], site[1]), args.speed))
    finally:
        sim.terminate()
        sim.wait(timeout=10)
    rows = [json.loads(line) for line in log.read_text().splitlines()]
    touch = [r for r in rows if r["event"] == "touchdown"]
    if not touch:
        print("[demo] FAILED: no touchdown recorded", file=sys.stderr)
        return 1
    td = touch[0]
    n, e, _ = td["pos_ned_m"]
    miss = math.hypot(n - site[0], e - site[1])
    print("\n=== demo summary ===")
    print(f"touchdown   N {n:.2f} m, E {e:.2f} m ({miss:.2f} m from the chosen site)")
    print(f"surface     {td['surface']} (safe: {td['safe']})")
    print(f"sim time    {td['t_s']:.1f} s to touchdown; wall {time.monotonic() - t0:.1f} s")
    print(f"episode log {log}")
    return 0 if td["safe"] else 1


if __name__ == "__main__":
    sys.exit(main())
