"""Installed like a product (issue 34): the project built as a wheel and installed (not editable) in a
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

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = (
    "companion",
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
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(root / "bin" / "python"), "install", "-q", "--no-deps",
         "--no-index", str(wheel)],
        check=True, capture_output=True, text=True, timeout=300,
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
         "from companion.reasoning.landnet import DEFAULT_MODEL; "
         "print(companion.__file__); print(simbridge.__file__); print(DEFAULT_MODEL)"],
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


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_companion_bench_flies_an_episode_from_the_wheel(venv: Path, tmp_path: Path) -> None:
    """The bug a new user met: from a wheel, ``companion-bench`` could not find ``trigger_alarm.py`` and
    every launch failed. A relative ``--out``, resolved from the user's folder by every process."""
    res = subprocess.run(
        ["companion-bench", "curated", "--scenario", "scenario1", "--runs", "1", "--workers", "1", "--quiet",
         "--out", "bench"],
        cwd=tmp_path, env=_env(venv), capture_output=True, text=True, timeout=540,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    (e,) = json.loads((tmp_path / "bench" / "results.json").read_text())["episodes"]
    assert e["error"] is None, e["error"]
    assert e["outcome"] == "landed"
    assert e["safe"], e["reasons"]
    assert (tmp_path / "bench" / "episodes" / e["id"] / "episode.jsonl").exists()
    assert (
        "recovery ended: landed" in (tmp_path / "bench" / "episodes" / e["id"] / "companion.log").read_text()
    )
