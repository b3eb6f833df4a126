"""Installed like a product: the project built as a wheel and installed (not editable) in a
fresh virtual environment, then run from a folder outside the checkout as the README shows it.

The wheel is installed with ``--no-deps``; the fresh environment borrows the third-party packages from
the test's own environment (a ``.pth`` line naming its site-packages, after the fresh one on the path) so
the test needs no network. Landfall's own code, data and commands come from the wheel alone: the test
checks where each import comes from."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.conftest import free_udp_port, stop_process

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = (
    "companion",
    "landfall-lidar-bridge",
    "trigger_alarm.py",
    "trigger-alarm",
    "simbridge",
    "companion-bench",
    "landfall-ground",
)


@pytest.fixture(scope="module")
def venv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with the wheel of this checkout installed; its root."""
    tmp = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(tmp / "dist"), str(ROOT)],
        check=True, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    (wheel,) = (tmp / "dist").glob("landfall-*.whl")
    root = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root)], check=True, timeout=120)
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(root / "bin" / "python"), "install", "-q", "--no-deps",
         "--no-index", str(wheel)],
        check=True, capture_output=True, text=True, timeout=300, env=clean, cwd=tmp,
    )  # fmt: skip
    purelib = subprocess.run(
        [str(root / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    Path(purelib, "_landfall_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return root


def _env(venv: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(venv)
    return env


def test_the_wheel_installs_every_command_and_its_own_code_and_data(venv: Path, tmp_path: Path) -> None:
    for name in COMMANDS:
        assert (venv / "bin" / name).exists(), f"{name} not installed from the wheel"
    where = subprocess.run(
        [str(venv / "bin" / "python"), "-c",
         "import companion, simbridge, landfall_eval, landfall_link, landfall_ground; "
         "from companion.reasoning.landnet import DEFAULT_MODEL, LandNet; "
         "net = LandNet.load(); "  # the default net and its whole read, sha256s checked, from the wheel
         "print(companion.__file__); print(simbridge.__file__); print(DEFAULT_MODEL); "
         "print(DEFAULT_MODEL.with_name(DEFAULT_MODEL.stem + '-whole.onnx'))"],
        cwd=tmp_path, env=_env(venv), capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert where.returncode == 0, where.stderr
    for line in where.stdout.split():
        assert Path(line).resolve().is_relative_to(venv.resolve()), line  # not the checkout's
        assert Path(line).exists()
    for name in COMMANDS:
        res = subprocess.run([name, "--help"], cwd=tmp_path, env=_env(venv), capture_output=True, text=True,
                             timeout=120)  # fmt: skip
        assert res.returncode == 0, (name, res.stderr[-2000:])
        assert "usage:" in res.stdout, name


@pytest.mark.timeout(300)
def test_the_harness_alarm_reaches_a_companion_beside_a_simulator_all_from_the_wheel(
    venv: Path, tmp_path: Path
) -> None:
    """The bug a new user met: from a wheel, ``companion-bench`` looked for ``trigger_alarm.py`` in the
    checkout and every launch failed ("can't open file .../site-packages/trigger_alarm.py"). Here the
    harness's own alarm sender (landfall_eval.processes.send_alarm, what every episode uses) reaches a
    companion started from the wheel, beside simbridge (JSBSim's F450) started from the wheel; the
    companion answers, and refuses for now: there is no sensor stream to land with. (A whole episode
    from a fresh install compiles simbridge's renderer first, minutes of the suite: `make demo` and
    the campaign tests fly the same code from the checkout.)"""
    env = _env(venv)
    port = free_udp_port()
    with (tmp_path / "companion.log").open("wb") as log, (tmp_path / "simbridge.log").open("wb") as err:
        companion = subprocess.Popen(["companion", "--mavlink", f"udp:{port}"], cwd=tmp_path, env=env,
                                     stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
        sim = subprocess.Popen(
            ["simbridge", "--scenario", "flat", "--speed", "2", "--mavlink", f"udpout:127.0.0.1:{port}",
             "--episode-log", "episode.jsonl"],
            cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=err,
        )  # fmt: skip
    try:
        code = (
            "import sys, time; from landfall_eval.processes import send_alarm; "
            f"r = send_alarm({port}, 'wheel check', 'high', time.monotonic() + 20); "
            "print(r.returncode); print(r.stdout); print(r.stderr)"
        )
        res = subprocess.run([str(venv / "bin" / "python"), "-c", code], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=120)  # fmt: skip
        assert res.returncode == 0, res.stderr[-2000:]
        returncode, *rest = res.stdout.splitlines()
        answer = "\n".join(rest)
        assert "can't open file" not in answer
        assert returncode == "1", answer  # answered: refused, not "no acknowledgement" (3) or unusable (2)
        assert "refused for now" in answer, answer
        assert sim.poll() is None, (tmp_path / "simbridge.log").read_text()[-2000:]  # JSBSim found its data
        started = [json.loads(x) for x in (tmp_path / "episode.jsonl").read_text().splitlines()]
        assert started[0]["event"] == "start"
    finally:
        stop_process(sim)
        stop_process(companion)
