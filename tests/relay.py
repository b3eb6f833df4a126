"""A TCP relay the tests put between the companion and simbridge's sensor stream, to cut the stream
the way a failed cable or a crashed camera driver would (a fault at the process boundary)."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


class TcpRelay:
    """Forwards connections from ``port`` (127.0.0.1, chosen by the kernel) to ``target_port``.

    ``cut()`` closes every connection and stops accepting: a client's request then times out or
    fails to connect. ``restore()`` accepts again on the same port.
    """

    def __init__(self, target_port: int) -> None:
        self.target_port = target_port
        self._lock = threading.Lock()
        self._conns: list[socket.socket] = []
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = int(self._listener.getsockname()[1])
        self._cut = threading.Event()
        self._accepting = threading.Thread(target=self._accept, daemon=True)
        self._accepting.start()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:
                return  # closed by cut() or close()
            if self._cut.is_set():
                client.close()
                continue
            try:
                upstream = socket.create_connection(("127.0.0.1", self.target_port), timeout=5)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            with self._lock:
                self._conns += [client, upstream]
            threading.Thread(target=self._pump, args=(client, upstream), daemon=True).start()
            threading.Thread(target=self._downstream, args=(upstream, client), daemon=True).start()

    def _downstream(self, src: socket.socket, dst: socket.socket) -> None:
        """simbridge -> companion; a subclass may rewrite what passes."""
        self._pump(src, dst)

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while data := src.recv(1 << 16):
                dst.sendall(data)
        for s in (src, dst):
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)

    def cut(self) -> None:
        """Drop every connection; new ones are accepted and closed at once."""
        self._cut.set()
        with self._lock:
            conns, self._conns = self._conns, []
        for s in conns:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()

    def restore(self) -> None:
        self._cut.clear()

    def close(self) -> None:
        self.cut()
        self._listener.close()


class FrameEditingRelay(TcpRelay):
    """A sensor-stream relay that edits every frame response on its way to the companion: it takes
    the parts named in ``drop`` out, as simbridge does for a sensor that failed (docs/sensor-stream.md:
    a part asked for but not produced is absent from ``parts``), and sets the header fields in
    ``header`` (``{"rangefinder_m": 150.0}``: a rangefinder that reads long). ``drop={"image"}``: a
    dead camera. ``lidar(points, k)`` replaces the k-th sweep's (N, 4) float32 returns (body FRD +
    intensity) with what it gives back: an empty sweep, a partial one."""

    def __init__(
        self,
        target_port: int,
        drop: set[str] | None = None,
        header: dict[str, object] | None = None,
        lidar: Callable[[np.ndarray, int], np.ndarray] | None = None,
    ) -> None:
        self.drop = drop or set()
        self.header = header or {}
        self.lidar = lidar
        self.dropped = 0
        self.edited = 0
        self.sweeps = 0
        super().__init__(target_port)

    def _edit_lidar(self, part: dict[str, Any], data: bytes) -> bytes:
        assert self.lidar is not None
        assert part["encoding"] == "raw"
        points = np.frombuffer(data, dtype=part["dtype"]).reshape(part["shape"])
        edited = np.ascontiguousarray(self.lidar(points, self.sweeps), dtype=part["dtype"])
        self.sweeps += 1
        part["shape"] = list(edited.shape)
        part["nbytes"] = edited.nbytes
        return edited.tobytes()

    def _downstream(self, src: socket.socket, dst: socket.socket) -> None:
        import json

        reader = src.makefile("rb")
        with contextlib.suppress(OSError, ValueError):
            while line := reader.readline():
                header = json.loads(line)
                kept: list[dict[str, object]] = []
                body = []
                for part in header.get("parts") or []:
                    data = reader.read(int(part["nbytes"]))
                    if part["name"] in self.drop:
                        self.dropped += 1
                        continue
                    if part["name"] == "lidar" and self.lidar is not None:
                        data = self._edit_lidar(part, data)
                    kept.append(part)
                    body.append(data)
                if "parts" in header:
                    header["parts"] = kept
                    if self.header:
                        header.update(self.header)
                        self.edited += 1
                dst.sendall(json.dumps(header).encode() + b"\n" + b"".join(body))
        for s in (src, dst):
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)


class _UdpRelayLoop:
    """The relay itself; it runs in its own process (``LossyUdpRelay`` starts it). In the test's
    process a garbage collection or the test's own polling held it for up to a second on a loaded
    machine: a gap in the companion's setpoints that PX4's offboard-loss failsafe rightly acted on."""

    def __init__(self, target_port: int, rates: tuple[float, float, float, float], seed: int) -> None:
        import random

        self.target = ("127.0.0.1", target_port)
        self.rates = rates
        kinds = ("in", "dropped", "duplicated", "reordered", "corrupted", "blacked_out")
        self.counts = dict.fromkeys(kinds, 0)
        self._rng = random.Random(seed)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.settimeout(0.2)
        self.port = int(self._sock.getsockname()[1])
        self._sim: tuple[str, int] | None = None
        self._held: dict[tuple[str, int], bytes] = {}
        self.stop = threading.Event()
        self.blackout = threading.Event()
        self.uplink_blackout = threading.Event()  # only what goes toward simbridge

    def inject(self, data: bytes) -> None:
        """One datagram to simbridge's side, from the relay's socket: to the autopilot it comes from
        the companion's address, as a second MAVLink system sharing the link would."""
        if self._sim is not None:
            with contextlib.suppress(OSError):
                self._sock.sendto(data, self._sim)

    def run(self) -> None:
        drop, duplicate, reorder, corrupt = self.rates
        while not self.stop.is_set():
            try:
                data, addr = self._sock.recvfrom(65535)
            except TimeoutError:
                continue
            except OSError:
                return
            if addr == self.target:
                dest = self._sim
            else:
                self._sim, dest = addr, self.target
            if dest is None:
                continue
            self.counts["in"] += 1
            if self.blackout.is_set() or (self.uplink_blackout.is_set() and dest != self.target):
                self.counts["blacked_out"] += 1
                continue
            r = self._rng.random
            if r() < drop:
                self.counts["dropped"] += 1
                continue
            if r() < corrupt:
                k = self._rng.randrange(len(data))
                data = data[:k] + bytes([data[k] ^ (1 + self._rng.randrange(255))]) + data[k + 1 :]
                self.counts["corrupted"] += 1
            if r() < reorder and dest not in self._held:
                self._held[dest] = data  # goes out after the next datagram to the same side
                self.counts["reordered"] += 1
                continue
            out = [data]
            if r() < duplicate:
                out.append(data)
                self.counts["duplicated"] += 1
            held = self._held.pop(dest, None)
            if held is not None:
                out.append(held)
            for d in out:
                with contextlib.suppress(OSError):
                    self._sock.sendto(d, dest)
        self._sock.close()


def serve_udp_relay(target_port: int, rates: tuple[float, float, float, float], seed: int) -> None:
    """The relay process: prints its port, then obeys one command per line on stdin (``blackout``,
    ``restore``, ``counts``: answered with the counts as JSON); the end of its input stops it."""
    import json
    import sys

    relay = _UdpRelayLoop(target_port, rates, seed)
    thread = threading.Thread(target=relay.run, daemon=True)
    thread.start()
    print(relay.port, flush=True)
    for line in sys.stdin:
        cmd = line.strip()
        if cmd == "blackout":
            relay.blackout.set()
        elif cmd == "blackout_uplink":
            relay.uplink_blackout.set()
        elif cmd.startswith("inject "):
            relay.inject(bytes.fromhex(cmd.split(" ", 1)[1]))
        elif cmd == "restore":
            relay.blackout.clear()
            relay.uplink_blackout.clear()
        elif cmd == "counts":
            print(json.dumps(relay.counts), flush=True)
    relay.stop.set()
    thread.join(timeout=2)


class LossyUdpRelay:
    """A UDP relay between simbridge and the companion that misbehaves like a bad radio link: it
    drops, duplicates, reorders and corrupts datagrams in both directions, from a seeded generator.

    simbridge sends to ``port``; the relay forwards to ``target_port`` (the companion) from the same
    socket, and forwards what comes back to simbridge's last address. It is a process of its own,
    so that nothing the test's process does (its polling, its garbage collector) can stall the link.
    """

    def __init__(
        self,
        target_port: int,
        *,
        drop: float = 0.2,
        duplicate: float = 0.05,
        reorder: float = 0.05,
        corrupt: float = 0.02,
        seed: int = 0,
    ) -> None:
        import subprocess
        import sys

        code = (
            "from tests.relay import serve_udp_relay; "
            f"serve_udp_relay({target_port}, ({drop}, {duplicate}, {reorder}, {corrupt}), {seed})"
        )
        root = Path(__file__).resolve().parent.parent
        self._proc = subprocess.Popen(
            [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=root
        )
        assert self._proc.stdin is not None
        assert self._proc.stdout is not None
        self._stdin, self._stdout = self._proc.stdin, self._proc.stdout
        line = self._stdout.readline()
        if not line.strip().isdigit():
            self._proc.kill()
            raise RuntimeError(f"the UDP relay did not start (it said {line!r})")
        self.port = int(line)
        self._final: dict[str, int] | None = None

    def _tell(self, cmd: str) -> None:
        self._stdin.write(cmd + "\n")
        self._stdin.flush()

    @property
    def counts(self) -> dict[str, int]:
        """Datagrams seen, dropped, duplicated, reordered, corrupted and blacked out so far."""
        if self._final is not None:
            return self._final
        import json

        self._tell("counts")
        return dict(json.loads(self._stdout.readline()))

    def blackout(self) -> None:
        """Drop everything, both ways, until ``restore()``: a link that is down."""
        self._tell("blackout")

    def blackout_uplink(self) -> None:
        """Drop what the companion sends (setpoints, commands) until ``restore()``; the autopilot's
        telemetry still gets through: a radio whose uplink failed."""
        self._tell("blackout_uplink")

    def restore(self) -> None:
        self._tell("restore")

    def inject(self, data: bytes) -> None:
        """Send ``data`` (a MAVLink frame) up the link to the autopilot: a ground station's PARAM_SET
        on real firmware, whose only MAVLink port is the companion's."""
        self._tell("inject " + data.hex())

    def close(self) -> None:
        """Stop the relay; ``counts`` keeps its last figures."""
        if self._final is not None:
            return
        self._final = self.counts
        self._stdin.close()
        try:
            self._proc.wait(timeout=5)
        except Exception:
            self._proc.kill()
            self._proc.wait()
        self._stdout.close()
