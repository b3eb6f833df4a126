"""A small blocking pymavlink ground-station client for tests (its own process side of the wire)."""

from __future__ import annotations

import math
import os
import time
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil

MAV_RESULT_ACCEPTED = 0
PX4_MAIN = {"POSCTL": (3, 0), "AUTO.TAKEOFF": (4, 2), "AUTO.LOITER": (4, 3), "AUTO.RTL": (4, 5),
            "AUTO.LAND": (4, 6), "OFFBOARD": (6, 0)}  # fmt: skip
AP_MODES = {"STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9,
            "POSHOLD": 16, "BRAKE": 17}  # fmt: skip


class MavClient:
    """Listens on a loopback UDP port that simbridge sends to (``udpin``)."""

    def __init__(self, port: int, source_system: int = 255, source_component: int = 190,
                 signing_key: bytes | None = None) -> None:  # fmt: skip
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=source_system, source_component=source_component
        )
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True)
        self.mav = self.conn.mav
        self.texts: list[Any] = []  # every STATUSTEXT seen, in order

    def close(self) -> None:
        self.conn.close()

    def wait_heartbeat(self, timeout_s: float = 30.0, ask: bool = True) -> Any:
        """The first heartbeat; then (``ask``) ask for every stream, as a ground station does
        (ArduPilot sends nothing else unasked)."""
        hb = self.conn.wait_heartbeat(timeout=timeout_s)
        if hb is None:
            raise TimeoutError("no HEARTBEAT from simbridge")
        if ask and hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
            self.request_streams(hb.get_srcSystem())
        return hb

    def request_streams(self, target_system: int = 1, hz: int = 20) -> None:
        """REQUEST_DATA_STREAM for all groups (MAV_DATA_STREAM_ALL) at ``hz``, the legacy way MAVProxy
        asks ArduPilot (PX4 streams unasked and ignores it)."""
        self.mav.request_data_stream_send(target_system, 1, 0, hz, 1)

    def recv(self, msg_type: str | list[str], timeout_s: float = 10.0, cond: Any = None) -> Any:
        types = [msg_type] if isinstance(msg_type, str) else msg_type
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            m = self.conn.recv_match(blocking=True, timeout=max(0.05, deadline - time.monotonic()))
            if m is None:
                continue
            if m.get_type() == "STATUSTEXT":
                self.texts.append(m)
            if m.get_type() in types and (cond is None or cond(m)):
                return m
        raise TimeoutError(f"no {msg_type} within {timeout_s} s")

    def drop_backlog(self) -> int:
        """Drop every datagram waiting in the socket unread; returns how many. A client that has not read
        for minutes has a full receive buffer of old telemetry (the kernel then drops what arrives next,
        an answer included), and parsing that backlog can take longer than the answer is worth waiting."""
        sock = self.conn.port  # pymavlink's UDP socket, non-blocking
        dropped = 0
        try:
            while True:
                sock.recv(65536)
                dropped += 1
        except (BlockingIOError, InterruptedError):
            pass
        return dropped

    def command(self, command: int, *params: float, timeout_s: float = 5.0, target_system: int = 1,
                target_component: int = 1, attempts: int = 3) -> int:  # fmt: skip
        """COMMAND_LONG; returns the COMMAND_ACK result. As the MAVLink command protocol has it, a command
        that gets no ACK is sent again with ``confirmation`` one higher (``attempts`` in all, ``timeout_s``
        each); before a second try the backlog is drained, so the answer is among the next things read."""
        p = list(params) + [0.0] * (7 - len(params))
        for confirmation in range(attempts):
            if confirmation:
                self.drop_backlog()
            self.mav.command_long_send(target_system, target_component, command, confirmation, *p)
            try:
                ack = self.recv("COMMAND_ACK", timeout_s, cond=lambda m: m.command == command)
            except TimeoutError:
                continue
            return int(ack.result)
        raise TimeoutError(f"no COMMAND_ACK for command {command} after {attempts} tries of {timeout_s} s")

    def set_mode_px4(self, name: str) -> int:
        main, sub = PX4_MAIN[name]
        return self.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, main, sub)

    def set_mode_ap(self, name: str) -> int:
        return self.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, AP_MODES[name])

    def arm(self, arm: bool = True) -> int:
        return self.command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if arm else 0.0)

    def send_position(self, n: float, e: float, d: float, yaw: float | None = None) -> None:
        mask = 2552 if yaw is not None else 3576
        self.mav.set_position_target_local_ned_send(
            0, 1, 1, 1, mask, n, e, d, 0, 0, 0, 0, 0, 0, yaw or 0.0, 0.0
        )

    def position(self, timeout_s: float = 5.0) -> Any:
        return self.recv("LOCAL_POSITION_NED", timeout_s)

    def wait_position(self, n: float, e: float, d: float, tol_m: float, timeout_s: float,
                      stream: bool = False) -> Any:  # fmt: skip
        """Wait until LOCAL_POSITION_NED is within ``tol_m`` of the point (streaming it if asked)."""
        deadline = time.monotonic() + timeout_s
        last_sent = 0.0
        while time.monotonic() < deadline:
            if stream and time.monotonic() - last_sent > 0.1:
                self.send_position(n, e, d)
                last_sent = time.monotonic()
            m = self.recv("LOCAL_POSITION_NED", 2.0)
            if math.dist((m.x, m.y, m.z), (n, e, d)) < tol_m:
                return m
        raise TimeoutError(f"vehicle did not reach {(n, e, d)} within {timeout_s} s")

    def heartbeat(self, timeout_s: float = 5.0) -> Any:
        return self.recv("HEARTBEAT", timeout_s, cond=lambda m: m.get_srcComponent() == 1)

    def wait_disarmed(self, timeout_s: float) -> Any:
        return self.recv(
            "HEARTBEAT", timeout_s,
            cond=lambda m: m.get_srcComponent() == 1 and not m.base_mode & 128,
        )  # fmt: skip

    # ---------------------------------------------------------------- extra helpers
    def stream_position(self, n: float, e: float, d: float, wall_s: float, period_s: float = 0.02) -> None:
        """Send the same position setpoint every ``period_s`` of wall time for ``wall_s``."""
        end = time.monotonic() + wall_s
        while time.monotonic() < end:
            self.send_position(n, e, d)
            self.conn.recv_match(blocking=True, timeout=period_s)
            time.sleep(0)

    def heartbeat_streaming(self, n: float, e: float, d: float, timeout_s: float = 5.0) -> Any:
        """The autopilot's next HEARTBEAT, the same position setpoint sent every 20 ms meanwhile (as
        a client in OFFBOARD keeps doing: without it, PX4 leaves OFFBOARD after COM_OF_LOSS_T)."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.send_position(n, e, d)
            m = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.02)
            if m is not None and m.get_srcComponent() == 1:
                return m
        raise AssertionError(f"no HEARTBEAT within {timeout_s} s")

    def drain(self, wall_s: float) -> None:
        """Read (and drop, keeping STATUSTEXTs) whatever arrives for ``wall_s``."""
        end = time.monotonic() + wall_s
        while time.monotonic() < end:
            m = self.conn.recv_match(blocking=True, timeout=max(0.01, end - time.monotonic()))
            if m is not None and m.get_type() == "STATUSTEXT":
                self.texts.append(m)

    def statustext(self, contains: str, timeout_s: float = 10.0) -> Any:
        """The first STATUSTEXT containing ``contains``, already seen or still to come."""
        for m in self.texts:
            if contains in m.text:
                return m
        return self.recv("STATUSTEXT", timeout_s, cond=lambda m: contains in m.text)

    def param_read(self, name: str, timeout_s: float = 5.0) -> Any:
        self.mav.param_request_read_send(1, 1, name.encode(), -1)
        return self.recv("PARAM_VALUE", timeout_s, cond=lambda m: m.param_id == name)

    def param_set(self, name: str, value: float, ptype: int, timeout_s: float = 5.0) -> Any:
        self.mav.param_set_send(1, 1, name.encode(), value, ptype)
        return self.recv("PARAM_VALUE", timeout_s, cond=lambda m: m.param_id == name)

    def takeoff_px4(self, climb_m: float) -> None:
        """Arm on the ground and climb ``climb_m`` (via MIS_TAKEOFF_ALT), waiting until there."""
        self.param_set("MIS_TAKEOFF_ALT", climb_m, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
        assert self.arm() == MAV_RESULT_ACCEPTED
        nan = float("nan")
        result = self.command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, nan, nan, nan, nan, nan, nan, nan)
        assert result == MAV_RESULT_ACCEPTED
        self.wait_position(0.0, 0.0, -climb_m, tol_m=0.5, timeout_s=30)  # local z from the resting CG
