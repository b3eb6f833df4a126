"""trigger_alarm.py's signing key (companion/alarm_cli.py): from a file, the environment or the
command line, in that order; a key file others can read is warned about; a bad key is named by where it
came from and never echoed; and a signed alarm reaches a signed peer on loopback (a stand-in for the
companion at the MAVLink boundary) while one signed with another key gets no answer."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from typing import Any

import pytest

from companion.alarm_cli import KEY_ENV, build_parser, main, signing_key
from companion.alarms import MAV_CMD_USER_1
from landfall_link.mavlink import MavlinkUdpLink

KEY = "0123456789abcdef" * 4
OTHER = "fedcba9876543210" * 4


def _args(*argv: str) -> Any:
    return build_parser().parse_args(["--reason", "test", *argv])


def test_the_key_comes_from_the_file_then_the_environment_then_the_command_line(tmp_path: Path) -> None:
    key_file = tmp_path / "key"
    key_file.write_text(KEY + "\n")
    key_file.chmod(0o600)
    env = {KEY_ENV: OTHER}
    assert signing_key(_args("--signing-key-file", str(key_file)), env) == (bytes.fromhex(KEY), None)
    assert signing_key(_args(), env) == (bytes.fromhex(OTHER), None)
    assert signing_key(_args("--signing-key", KEY), env) == (bytes.fromhex(KEY), None)
    assert signing_key(_args("--signing-key-env", "MY_KEY"), {"MY_KEY": KEY}) == (bytes.fromhex(KEY), None)
    assert signing_key(_args(), {}) == (None, None)
    with pytest.raises(SystemExit):  # one of the two forms, not both
        _args("--signing-key", KEY, "--signing-key-file", str(key_file))


def test_a_key_file_others_can_read_is_warned_about_and_bad_keys_are_not_echoed(tmp_path: Path) -> None:
    key_file = tmp_path / "key"
    key_file.write_text(KEY)
    key_file.chmod(0o644)
    key, warning = signing_key(_args("--signing-key-file", str(key_file)), {})
    assert key == bytes.fromhex(KEY)
    assert warning is not None
    assert "chmod 600" in warning
    secret = "ab" * 20  # 20 bytes: hexadecimal, the wrong length
    with pytest.raises(ValueError, match=rf"^\${KEY_ENV}: signing key must be 32 bytes") as err:
        signing_key(_args(), {KEY_ENV: secret})
    assert secret not in str(err.value)
    with pytest.raises(ValueError, match=r"--signing-key-file .*nothing: cannot read it"):
        signing_key(_args("--signing-key-file", str(tmp_path / "nothing")), {})


def _companion(key: bytes, port: list[int], ready: threading.Event, stop: threading.Event) -> None:
    """A signed MAVLink peer on loopback that acknowledges every alarm command it accepts."""

    async def run() -> None:
        link: MavlinkUdpLink

        def on_message(msg: Any, addr: tuple[str, int]) -> None:
            if msg.get_type() == "COMMAND_LONG" and msg.command == MAV_CMD_USER_1:
                ack = link.mav.command_ack_encode(MAV_CMD_USER_1, 0, 0, 0, msg.get_srcSystem(), 25)
                link.send_to(ack, msg.get_srcSystem(), msg.get_srcComponent())

        link = MavlinkUdpLink("udpin:127.0.0.1:0", 1, 191, on_message, signing_key=key)
        async with link:
            port.append(link.local_port)
            ready.set()
            await asyncio.to_thread(stop.wait)

    asyncio.run(run())


@pytest.mark.parametrize(("ours", "answered"), [(KEY, True), (OTHER, False)])
def test_a_signed_alarm_is_answered_by_a_peer_with_the_same_key_only(
    ours: str,
    answered: bool,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    port: list[int] = []
    ready, stop = threading.Event(), threading.Event()
    peer = threading.Thread(target=_companion, args=(bytes.fromhex(KEY), port, ready, stop), daemon=True)
    peer.start()
    assert ready.wait(5.0)
    monkeypatch.setenv(KEY_ENV, ours)
    try:
        code = main(["--mavlink", f"udpout:127.0.0.1:{port[0]}", "--reason", "test", "--timeout", "1.5"])
    finally:
        stop.set()
        peer.join(5.0)
    out = capsys.readouterr()
    assert code == (0 if answered else 3), out
    assert ours not in out.out + out.err  # the key is never printed
