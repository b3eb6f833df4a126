"""The companion installs without the simulator: JSBSim, numba and tqdm are the ``sim`` extra, and
``simbridge`` / ``companion-bench`` without it say in one line how to install it."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from simbridge.extra import INSTALL_HINT, SIM_MODULES, missing_sim_modules

ROOT = Path(__file__).resolve().parent.parent

# Runs a console script's module as ``python -m`` does, with one module made unimportable.
BLOCKED = """
import runpy, sys
sys.modules[sys.argv[1]] = None  # importing it now fails, as where it was never installed
package, sys.argv = sys.argv[2], sys.argv[3:]
runpy.run_module(package, run_name="__main__", alter_sys=True)
"""


def _names(requirements: list[str]) -> set[str]:
    return {re.split(r"[<>=!~ ;\[]", r, maxsplit=1)[0].lower() for r in requirements}


def test_the_base_install_leaves_the_simulator_out() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    base, sim = _names(project["dependencies"]), _names(project["optional-dependencies"]["sim"])
    assert base.isdisjoint(SIM_MODULES)
    assert sim == set(SIM_MODULES)
    makefile = (ROOT / "Makefile").read_text()
    installs = re.findall(r"pip install --quiet -e '\.\[([a-z,]+)\]'", makefile)
    assert installs  # make demo / make test / make model: each flies or builds on simbridge
    assert all("sim" in extras.split(",") for extras in installs), installs


def test_nothing_is_missing_where_the_extra_is_installed() -> None:
    assert missing_sim_modules() == []


@pytest.mark.parametrize(
    ("prog", "package", "blocked", "args"),
    [
        ("simbridge", "simbridge", "jsbsim", ["--scenario", "flat", "--duration", "1"]),
        ("simbridge", "simbridge", "numba", ["render", "--scenario", "scenario1", "--pose", "0,0,110,0"]),
        ("companion-bench", "landfall_eval", "jsbsim", ["curated", "--scenario", "scenario1", "--runs", "1"]),
        ("companion-bench", "landfall_eval", "tqdm", ["city", "--seeds", "1"]),
    ],
)
def test_a_command_without_the_sim_extra_says_how_to_install_it(
    prog: str, package: str, blocked: str, args: list[str], tmp_path: Path
) -> None:
    out_dir = tmp_path / "out"
    argv = [*args, "--out", str(out_dir if prog == "companion-bench" else tmp_path / "frame.png")]
    res = subprocess.run(
        [sys.executable, "-c", BLOCKED, blocked, package, *argv],
        capture_output=True, text=True, timeout=120, cwd=ROOT,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr[-2000:]
    assert res.stderr.splitlines() == [
        f"{prog}: the simulator's dependencies are not installed ({blocked} missing): {INSTALL_HINT}"
    ]
    assert not out_dir.exists()  # nothing was started
