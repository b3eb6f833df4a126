"""``trigger_alarm.py`` / ``trigger-alarm``: send an alarm to the companion and print its answer.

``--cancel`` sends the operator's cancel instead (MAV_CMD_USER_2: companion/operator.py): the running
recovery stops and the vehicle is left in the companion's ``alarms.cancel_mode``.

Exit status: 0 when the companion accepted the alarm (a new recovery, or merged into the running
one) or the cancel, 1 when it refused it, 2 on a usage error, 3 when no acknowledgement came back in
time.

The MAVLink 2 signing key (64 hex digits) comes from ``--signing-key-file`` (a file holding it, which
should be readable by its owner only), else from the environment variable ``LANDFALL_SIGNING_KEY``
(``--signing-key-env`` names another: the companion's own default), else from ``--signing-key``: on
the command line a key is visible to every user of the machine (``ps``), so that form is for tests.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import stat
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from companion.alarms import ALARM_TEXT_PREFIX, MAV_CMD_USER_1, Criticality, ReasonCode
from companion.operator import MAV_CMD_USER_2
from landfall_link.mavlink import URL_FORMS, LinkUrl, LinkUrlError, open_link, parse_signing_key

RESULTS = {
    0: "accepted: recovery started",
    5: "accepted: merged into the running recovery",
    1: "refused for now (no fresh telemetry or no sensors yet)",
    2: "refused (denied)",
    3: "refused (unsupported)",
    4: "refused (failed)",
}
CANCEL_RESULTS = {0: "accepted: recovery cancelled", 2: "refused: no recovery to cancel, or not allowed"}


KEY_ENV = "LANDFALL_SIGNING_KEY"  # the companion's default (mavlink.signing_key_env)


def signing_key(args: argparse.Namespace, environ: Mapping[str, str]) -> tuple[bytes | None, str | None]:
    """The signing key by the module docstring's order, and a warning to print (a key file others can
    read), if any.

    Raises:
        ValueError: a key that is not 64 hex digits, or a key file that cannot be read (the message
            names where the key came from and never echoes it).
    """
    warning = None
    if args.signing_key_file is not None:
        path = args.signing_key_file
        try:
            text = path.read_text(encoding="ascii").strip()
            mode = path.stat().st_mode
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"--signing-key-file {path}: cannot read it ({type(exc).__name__})") from None
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            warning = f"{path} can be read by others than its owner: chmod 600 {path}"
        source = f"--signing-key-file {path}"
    elif args.signing_key:
        text, source = args.signing_key, "--signing-key"
    elif environ.get(args.signing_key_env):
        text, source = environ[args.signing_key_env], f"${args.signing_key_env}"
    else:
        return None, None
    try:
        return parse_signing_key(text), warning
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="trigger_alarm.py", description=__doc__.splitlines()[0] if __doc__ else None
    )
    p.add_argument(
        "--mavlink",
        default="udpout:127.0.0.1:14550",
        help=f"where the companion listens (default %(default)s): {URL_FORMS}",
    )
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--reason", help="free-text reason, e.g. 'GPS spoofing detected'")
    what.add_argument("--cancel", action="store_true", help="cancel the running recovery instead")
    p.add_argument("--criticality", default="high", choices=("low", "high", "critical"))
    p.add_argument("--code", default="other", choices=[c.name.lower() for c in ReasonCode])
    keys = p.add_mutually_exclusive_group()
    keys.add_argument(
        "--signing-key-file", type=Path, metavar="PATH", help="a file holding the MAVLink 2 signing key"
    )
    keys.add_argument(
        "--signing-key",
        help="the key itself, 64 hex digits (visible in ps: prefer the file or the environment)",
    )
    p.add_argument(
        "--signing-key-env",
        default=KEY_ENV,
        metavar="NAME",
        help="the environment variable holding the key when no file is given (default %(default)s)",
    )
    p.add_argument(
        "--source-system", type=int, default=255, help="our own MAVLink system id (255: a ground station)"
    )
    p.add_argument("--target-system", type=int, default=1, help="the vehicle's system id")
    p.add_argument("--target-component", type=int, default=191, help="the companion's component id")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the acknowledgement")
    return p


async def send_alarm(args: argparse.Namespace, key: bytes | None) -> int | None:
    acks: asyncio.Queue[Any] = asyncio.Queue()

    def on_message(msg: Any, addr: tuple[str, int]) -> None:
        companion = (args.target_system, args.target_component)
        from_companion = (msg.get_srcSystem(), msg.get_srcComponent()) == companion
        if msg.get_type() == "COMMAND_ACK" and msg.command == command and from_companion:
            acks.put_nowait(msg)

    crit = Criticality.parse(args.criticality)
    code = ReasonCode[args.code.upper()]
    command = MAV_CMD_USER_2 if args.cancel else MAV_CMD_USER_1
    params = (0.0, 0.0) if args.cancel else (float(code), float(crit))
    async with open_link(args.mavlink, args.source_system, 25, on_message, signing_key=key) as link:
        text = (ALARM_TEXT_PREFIX + (args.reason or ""))[:50]
        loop = asyncio.get_running_loop()
        deadline = loop.time() + args.timeout
        attempt = 0
        while loop.time() < deadline:
            if not args.cancel:
                link.send(link.mav.statustext_encode(4, text.encode(), 0, 0))
            link.send(
                link.mav.command_long_encode(
                    args.target_system,
                    args.target_component,
                    command,
                    attempt,
                    *params,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
            )
            attempt += 1
            try:
                async with asyncio.timeout(min(1.0, max(deadline - loop.time(), 0.01))):
                    ack = await acks.get()
                    return int(ack.result)
            except TimeoutError:
                continue
    return None


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        LinkUrl.parse(args.mavlink)
        if not 1 <= args.source_system <= 255:
            raise ValueError(f"--source-system must be 1..255 (got {args.source_system})")
        key, warning = signing_key(args, os.environ)
    except (LinkUrlError, ValueError) as exc:
        parser.error(str(exc))
    if warning is not None:
        print(f"trigger_alarm.py: warning: {warning}", file=sys.stderr)
    result = asyncio.run(send_alarm(args, key))
    if result is None:
        print(
            f"no acknowledgement from the companion at {args.mavlink} within {args.timeout:.0f} s "
            "(is it running? is the signing key right?)",
            file=sys.stderr,
        )
        return 3
    if args.cancel:
        print(f"cancel: {CANCEL_RESULTS.get(result, f'MAV_RESULT {result}')}")
        return 0 if result == 0 else 1
    print(f"alarm '{args.reason}' ({args.criticality}): {RESULTS.get(result, f'MAV_RESULT {result}')}")
    return 0 if result in (0, 5) else 1


if __name__ == "__main__":
    sys.exit(main())
