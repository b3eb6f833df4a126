"""deploy/: the example configuration loads, the systemd units pass ``systemd-analyze verify`` (where
it is installed) and carry the hardening they promise, and the pieces point at each other: the
mavlink-router endpoint and simbridge's unit at the companion's default ports, the record inside
the unit's writable paths."""

from __future__ import annotations

import configparser
import enum
import re
import shlex
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

from companion.config import load_config
from companion.config_schema import CompanionConfig

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
ROOT = DEPLOY.parent
PREFIX = "/opt/landfall"  # where the units expect the checkout (README: deploying)


def unit(name: str) -> dict[str, dict[str, list[str]]]:
    """A systemd unit file as section -> key -> values (keys may repeat)."""
    out: dict[str, dict[str, list[str]]] = {}
    section = ""
    for raw in (DEPLOY / name).read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("["):
            section = line.strip("[]")
            out.setdefault(section, {})
            continue
        key, _, value = line.partition("=")
        out[section].setdefault(key.strip(), []).append(value.strip())
    return out


def exec_args(name: str) -> list[str]:
    return shlex.split(unit(name)["Service"]["ExecStart"][0])


def flag(args: list[str], name: str) -> str:
    return args[args.index(name) + 1]


def test_the_example_configuration_loads_and_is_the_defaults() -> None:
    cfg = load_config(DEPLOY / "companion.toml", {}, {})
    assert cfg == CompanionConfig()  # every option at its default, as the file says


@pytest.mark.parametrize("name", ["companion.service", "simbridge.service"])
def test_units_pass_systemd_analyze_verify(name: str, tmp_path: Path) -> None:
    exe = shutil.which("systemd-analyze")
    if exe is None:
        pytest.skip("systemd-analyze is not installed here")
    # the unit names the deployment prefix; verify checks that ExecStart exists, so point it here
    text = (DEPLOY / name).read_text().replace(PREFIX, str(ROOT))
    (tmp_path / name).write_text(text)
    assert Path(exec_args(name)[0].replace(PREFIX, str(ROOT))).exists(), "make .venv first"
    res = subprocess.run([exe, "verify", str(tmp_path / name)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stderr.strip() == "", res.stderr  # not even an ignored key


def test_companion_unit_is_hardened_and_may_write_its_record() -> None:
    s = unit("companion.service")["Service"]
    expected = {
        "Restart": "on-failure", "NoNewPrivileges": "yes", "ProtectSystem": "strict", "ProtectHome": "yes",
        "PrivateTmp": "yes", "PrivateDevices": "yes", "RestrictSUIDSGID": "yes", "CapabilityBoundingSet": "",
        "User": "landfall",
    }  # fmt: skip
    for key, value in expected.items():
        assert s[key] == [value], key
    record = Path(flag(exec_args("companion.service"), "--record"))
    writable = [Path(p) for p in s["ReadWritePaths"][0].split()]
    assert any(record.is_relative_to(w) for w in writable)
    assert unit("companion.service")["Unit"]["StartLimitBurst"] == ["5"]


def test_the_pieces_meet_on_the_companion_defaults() -> None:
    cfg = CompanionConfig()
    companion_port = int(cfg.mavlink.url.rpartition(":")[2])
    router = configparser.ConfigParser()
    router.read(DEPLOY / "mavlink-router" / "main.conf")
    assert router["UartEndpoint flightcontroller"]["Device"].startswith("/dev/")
    ep = router["UdpEndpoint companion"]
    assert (ep["Mode"], ep["Address"], int(ep["Port"])) == ("Normal", "127.0.0.1", companion_port)
    assert router["UdpEndpoint groundstation"]["Mode"] == "Normal"  # binds no port the companion needs
    sim = exec_args("simbridge.service")
    assert flag(sim, "--mavlink") == f"udpout:127.0.0.1:{companion_port}"
    assert flag(sim, "--sensors") == cfg.sensors.endpoint
    assert unit("simbridge.service")["Unit"]["Before"] == ["companion.service"]  # the companion finds it up


def test_the_ground_router_leaves_qgroundcontrol_its_port_and_gives_the_alarm_tools_theirs() -> None:
    """deploy/mavlink-router/ground.conf: the radio to QGroundControl's default UDP 14550, and a server
    endpoint that trigger_alarm.py sends to, on the port docs/deploy.md gives it."""
    router = configparser.ConfigParser()
    router.read(DEPLOY / "mavlink-router" / "ground.conf")
    assert router["UartEndpoint radio"]["Device"].startswith("/dev/")
    qgc = router["UdpEndpoint qgroundcontrol"]
    assert (qgc["Mode"], qgc["Address"], int(qgc["Port"])) == ("Normal", "127.0.0.1", 14550)
    tools = router["UdpEndpoint alarmtools"]
    assert (tools["Mode"], int(tools["Port"])) == ("Server", 14551)
    doc = (DEPLOY.parent / "docs" / "deploy.md").read_text()
    assert f"trigger_alarm.py --mavlink udpout:127.0.0.1:{tools['Port']}" in doc


DEFAULT_WORDS = re.compile(r"Default:? (none|\"[^\"]*\"|\[[^\]]*\]|true|false|-?[0-9][0-9_.e+-]*)")


def _stated_defaults() -> list[tuple[str, str, str, int]]:
    """(section, key, the default its comment states, line number) for each key of deploy/companion.toml
    whose comment block says "Default ..."."""
    out = []
    section, comment = "", ""
    for n, raw in enumerate((DEPLOY / "companion.toml").read_text().splitlines(), 1):
        line = raw.strip()
        if line.startswith("["):
            section, comment = line.strip("[]"), ""
        elif line.startswith("#"):
            comment += " " + line.lstrip("# ")
        elif "=" in line:
            key = line.partition("=")[0].strip()
            found = DEFAULT_WORDS.findall(comment)
            if found:
                out.append((section, key, found[-1].rstrip("."), n))
            comment = ""
        else:
            comment = ""
    return out


def test_the_example_configuration_states_each_default_as_the_schema_has_it() -> None:
    from companion.config_schema import DEFAULTS

    stated = _stated_defaults()
    assert len(stated) > 40  # the file states most of its defaults
    wrong = []
    for section, key, text, n in stated:
        owner: object = DEFAULTS
        for part in section.split("."):
            owner = getattr(owner, part, None)
        if owner is None or not hasattr(owner, key):
            continue  # an example section (a profile, a table entry), not a schema default
        actual = getattr(owner, key)
        expected = None if text == "none" else tomllib.loads(f"v = {text}")["v"]
        if isinstance(actual, tuple):
            actual = list(actual)
        if expected is None:
            ok = actual in (None, "", [], {})
        elif isinstance(actual, enum.Enum):
            ok = actual.value == expected
        else:
            ok = actual == expected or str(actual) == str(expected)
        if not ok:
            wrong.append(f"line {n}: [{section}] {key}: the comment says {text}, the schema {actual!r}")
    assert not wrong, "\n".join(wrong)
