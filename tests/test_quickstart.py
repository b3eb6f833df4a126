"""The README's quick start as written: every command line parses with its tool's parser, the ports of
its commands meet each other and the companion's defaults, and its simulator, companion and alarm,
copied from the README, land the vehicle on scenario1's clear roof."""

from __future__ import annotations

import argparse
import configparser
import itertools
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

import pytest

from companion.alarm_cli import build_parser as alarm_parser
from companion.camera import parse_camera_url
from companion.cli import build_parser as companion_parser
from companion.config_schema import DEFAULTS
from companion.eval_cli import build_parser as eval_parser
from landfall_eval.cli import build_parser as bench_parser
from landfall_eval.processes import sped_up_env, stop_process
from landfall_ground.cli import _parser as ground_parser
from landfall_link.lidar_bridge import build_parser as lidar_bridge_parser
from landfall_link.mavlink import LinkUrl
from landfall_link.sensorstream import parse_endpoint
from simbridge.camera_stream import parse_stream_url
from simbridge.cli import build_parser as simbridge_parser
from simbridge.cli import config_from_args
from simbridge.render_cli import build_parser as render_parser
from tests.conftest import Rig, SimProcess, free_tcp_port, free_udp_port
from tests.test_companion_e2e import _wait_for_companion, _wait_touchdown

ROOT = Path(__file__).resolve().parent.parent
# the first word of a quick-start command -> its parser; simbridge's ``render`` is a parser of its own
PARSERS: dict[str, Callable[[], argparse.ArgumentParser]] = {
    "companion": companion_parser,
    "trigger_alarm.py": alarm_parser,
    "simbridge": simbridge_parser,
    "companion-eval": eval_parser,
    "companion-bench": bench_parser,
    "landfall-ground": ground_parser,
    "landfall-lidar-bridge": lidar_bridge_parser,
}
# how a test runs a console script from this checkout (the installed scripts may point elsewhere)
RUN_AS = {
    "simbridge": [sys.executable, "-m", "simbridge"],
    "companion": [sys.executable, "-m", "companion"],
    "trigger_alarm.py": [sys.executable, str(ROOT / "trigger_alarm.py")],
}


def quick_start(readme: str | None = None) -> str:
    """The first code block under the README's ``## Quick start``."""
    text = (ROOT / "README.md").read_text() if readme is None else readme
    section = text.split("\n## Quick start\n", 1)[1]
    return section.split("```sh\n", 1)[1].split("```", 1)[0]


def command_lines(block: str) -> list[str]:
    """The block's commands, one string each: lines joined across trailing backslashes, comments cut
    off; a comment that starts with a tool's name (``# companion-eval confirm ...``) is a command too."""
    joined = re.sub(r"\s*\\\n\s*", " ", block)
    out = []
    for line in joined.splitlines():
        for text in re.split(r"(?:^|\s)#(?:\s|$)", line, maxsplit=1):
            words = text.split()
            if words and words[0] in PARSERS:
                out.append(text.strip())
    return out


def variants(line: str) -> list[list[str]]:
    """Every command ``line`` stands for: each ``[optional]`` group left out and put in, each ``a|b``
    alternative taken in turn (``...`` in a list, or as a word, stands for more of the same and is
    dropped); ``[--flag A | B]`` is ``--flag A`` or ``--flag B``."""
    tokens = shlex.split(re.sub(r"\s*\|\s*", "|", line))
    items, rest = _group(tokens)
    assert not rest, f"unbalanced ']' in {line!r}"
    return [list(v) for v in _expand(items)]


_Item = str | list["_Item"]


def _group(tokens: list[str]) -> tuple[list[_Item], list[str]]:
    """Tokens into a tree: a word, or a list for an ``[optional]`` group; returns what follows the
    group's closing bracket."""
    items: list[_Item] = []
    while tokens:
        word, tokens = tokens[0], tokens[1:]
        if word.startswith("["):
            inner, tokens = _group([word[1:], *tokens])
            items.append(inner)
        elif word.endswith("]"):
            items.append(word[:-1])
            return items, tokens
        else:
            items.append(word)
    return items, []


def _expand(items: list[_Item]) -> Iterable[tuple[str, ...]]:
    choices: list[list[tuple[str, ...]]] = []
    for item in items:
        if isinstance(item, list):
            choices.append([(), *_expand(item)])
        else:
            alternatives = [a for a in item.split("|") if a not in ("", "...")]
            choices.append([(a,) for a in alternatives] or [()])
    for pick in itertools.product(*choices):
        yield tuple(word for part in pick for word in part)


def parse(words: list[str]) -> argparse.Namespace:
    """``words`` (a command, its tool first) through the tool's parser, as its entry point parses them."""
    tool, args = words[0], words[1:]
    if tool == "simbridge" and args[:1] == ["render"]:
        return render_parser().parse_args(args[1:])
    parsed = PARSERS[tool]().parse_args(args)
    if tool == "simbridge":
        config_from_args(parsed)  # what simbridge's main turns into a usage error
    return parsed


def commands_of(tool: str) -> list[str]:
    lines = [line for line in command_lines(quick_start()) if line.split()[0] == tool]
    assert lines, f"the README's quick start has no {tool} command"
    return lines


def flag(words: list[str], name: str) -> str:
    assert name in words, f"{name} not in {words}"
    return words[words.index(name) + 1]


def only(found: Iterable[list[str]]) -> list[str]:
    found = list(found)
    assert len(found) == 1, found
    return found[0]


def test_quick_start_reader_expands_options_alternatives_continuations_and_comments() -> None:
    block = (
        "# a comment\nsimbridge --a x|y \\\n   [--b B] [--c C | none]   # companion-eval rank a.png ...\n"
        "companion --d 'two words'  # a note\n"
    )
    assert command_lines(block) == [
        "simbridge --a x|y [--b B] [--c C | none]",
        "companion-eval rank a.png ...",
        "companion --d 'two words'",
    ]
    assert variants("simbridge --a x|y [--b B] [--c C | none]") == [
        ["simbridge", "--a", s, *b, *c]
        for s in ("x", "y")
        for b in ([], ["--b", "B"])
        for c in ([], ["--c", "C"], ["--c", "none"])
    ]
    assert variants("companion-eval rank a.png ...") == [["companion-eval", "rank", "a.png"]]
    assert variants("companion --reasoner onboard|gpt-5|...") == [
        ["companion", "--reasoner", "onboard"], ["companion", "--reasoner", "gpt-5"]
    ]  # fmt: skip
    with pytest.raises(SystemExit):  # the parse check can fail
        parse(["companion", "--no-such-flag"])


def test_every_quick_start_command_parses() -> None:
    lines = command_lines(quick_start())
    assert {line.split()[0] for line in lines} == set(PARSERS)  # every tool the block shows, read
    for line in lines:
        for words in variants(line):
            try:
                parse(words)
            except SystemExit as exc:
                pytest.fail(f"the README's {shlex.join(words)!r} does not parse (exit {exc.code})")
            except ValueError as exc:
                pytest.fail(f"the README's {shlex.join(words)!r}: {exc}")


def test_quick_start_ports_meet_each_other_and_the_defaults() -> None:
    sims = [v for line in commands_of("simbridge") for v in variants(line) if v[1:2] != ["render"]]
    companions = [v for line in commands_of("companion") for v in variants(line)]
    alarms = variants(commands_of("trigger_alarm.py")[0])
    bridges = variants(commands_of("landfall-lidar-bridge")[0])

    # simbridge serves its sensors where the companion looks by default (its command gives no --sensors)
    sim_sensors = {flag(v, "--sensors") for v in sims}
    assert sim_sensors == {DEFAULTS.sensors.endpoint}, (sim_sensors, DEFAULTS.sensors.endpoint)
    assert all("--sensors" not in v for v in companions if len(v) == 3)  # the plain form relies on it
    # the LiDAR bridge serves the same endpoint, and does by default
    assert {flag(v, "--sensors") for v in bridges} == {DEFAULTS.sensors.endpoint}
    assert lidar_bridge_parser().get_default("sensors") == DEFAULTS.sensors.endpoint
    sensors_host, sensors_port = parse_endpoint(DEFAULTS.sensors.endpoint)
    helps = " ".join(companion_parser().format_help().split())  # --help says what it falls back to
    assert f"default from the config: {DEFAULTS.sensors.endpoint})" in helps
    assert f"default from the config: {DEFAULTS.mavlink.url})" in helps

    # simbridge and trigger_alarm.py send MAVLink to the UDP port the companion listens on by default
    listen = {LinkUrl.parse(flag(v, "--mavlink")) for v in companions}
    assert listen == {LinkUrl.parse(DEFAULTS.mavlink.url)}
    (companion_url,) = listen
    assert (companion_url.mode, companion_url.host) == ("udpin", "0.0.0.0")  # loopback reaches it
    for senders in (sims, alarms):
        to = {LinkUrl.parse(flag(v, "--mavlink")) for v in senders}
        assert to == {LinkUrl("udpout", "127.0.0.1", companion_url.port)}, to
    assert LinkUrl.parse(alarm_parser().get_default("mavlink")).port == companion_url.port

    # the camera's RTP stream: simbridge sends where the companion's camera listens, on a port of its own
    camera = {parse_camera_url(flag(v, "--camera")).port for v in companions if "--camera" in v}
    streamed = {parse_stream_url(flag(v, "--camera-stream"))[1] for v in sims if "--camera-stream" in v}
    assert len(camera) == 1, camera
    assert streamed == camera, (camera, streamed)
    router = configparser.ConfigParser()
    router.read(ROOT / "deploy" / "mavlink-router" / "main.conf")
    router_tcp = int(router["General"]["TcpServerPort"])
    assert sensors_port not in camera | {router_tcp}, (sensors_port, camera, router_tcp)
    assert sensors_host == "127.0.0.1"


class _ReadmeRig(Rig):
    """A rig whose alarm is the README's trigger_alarm.py command, run in ``cwd``."""

    def __init__(
        self, sim: SimProcess, companion: subprocess.Popen[bytes], log: Path, alarm_cmd: list[str], cwd: Path
    ) -> None:
        super().__init__(sim, companion, sim.port, log)
        self.alarm_cmd = alarm_cmd
        self.cwd = cwd

    def alarm(self, *args: str, timeout_s: float = 10.0) -> subprocess.CompletedProcess[str]:
        cmd = [*self.alarm_cmd, *args]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s + 30, cwd=self.cwd)


def _runnable(words: list[str], ports: dict[int, int]) -> list[str]:
    """``words`` as this checkout runs them, each of the README's ``ports`` moved to a free one."""
    moved = [re.sub(r"(?<=:)(\d+)\b", lambda m: str(ports.get(int(m[1]), m[1])), w) for w in words]
    return [*RUN_AS[words[0]], *moved[1:]]


@pytest.mark.slow
@pytest.mark.timeout(420)
def test_quick_start_commands_as_written_land_on_the_clear_roof(tmp_path: Path) -> None:
    """simbridge (px4, --speed 4, its episode log), the plain companion and the alarm, each as the
    README writes it. Only the ports move, to free ones (the suite runs in parallel): the README's MAVLink
    port in every command, its sensor port in simbridge's, and the companion's default sensor endpoint
    through its environment (its command gives none). That the README's own ports meet is
    test_quick_start_ports_meet_each_other_and_the_defaults."""
    sim_words = only(
        v
        for v in variants(commands_of("simbridge")[0])
        if "px4" in v and "--speed" in v and "--episode-log" in v and "--weather" not in v
        and "--camera-stream" not in v
    )  # fmt: skip
    companion_words = only(v for v in variants(commands_of("companion")[0]) if len(v) == 3)
    alarm_words = only(v for v in variants(commands_of("trigger_alarm.py")[0]) if "high" in v)
    assert float(flag(sim_words, "--speed")) >= 4  # as fast as the other flights: a short test

    mavlink_port = LinkUrl.parse(flag(companion_words, "--mavlink")).port
    sensors_host, sensors_port = parse_endpoint(flag(sim_words, "--sensors"))
    ports = {mavlink_port: free_udp_port(), sensors_port: free_tcp_port()}
    path = [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path)}  # this checkout, run from tmp_path
    companion_env = {
        **env,
        **sped_up_env(float(flag(sim_words, "--speed"))),
        "LANDFALL_SENSORS_ENDPOINT": f"{sensors_host}:{ports[sensors_port]}",
    }
    episode_log = tmp_path / flag(sim_words, "--episode-log")  # relative: simbridge runs in tmp_path
    sim_err, companion_log = tmp_path / "simbridge.stderr", tmp_path / "companion.log"
    procs: list[subprocess.Popen[bytes]] = []
    try:
        with sim_err.open("wb") as err:
            procs.append(
                subprocess.Popen(
                    _runnable(sim_words, ports), cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=err
                )
            )
        sim = SimProcess(procs[0], ports[mavlink_port], episode_log, sim_err)
        with companion_log.open("wb") as log:
            procs.append(
                subprocess.Popen(
                    _runnable(companion_words, ports),
                    cwd=tmp_path,
                    env=companion_env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )
        rig = _ReadmeRig(sim, procs[1], companion_log, _runnable(alarm_words, ports), tmp_path)

        _wait_for_companion(rig)  # the companion found simbridge's sensors
        out = rig.alarm_accepted()
        assert out.returncode == 0, out.stdout + out.stderr
        assert "accepted: recovery started" in out.stdout
        td = _wait_touchdown(rig, timeout_s=240)
        assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-2000:])
        assert td["safe"] is True
        assert "recovery ended: landed" in rig.wait_log("recovery ended", timeout_s=60)
    finally:
        for proc in procs:
            stop_process(proc)
