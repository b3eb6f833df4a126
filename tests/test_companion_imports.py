"""The companion runs on a vehicle without the simulator (DESIGN.md section 4: the companion imports no
simulator module): its daemon, its command lines and the alarm tool import neither simbridge, nor the
evaluation harness, nor JSBSim; MAVLink and the sensor stream come from landfall_link."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHECK = """
import sys
for name in ("simbridge", "landfall_eval", "jsbsim", "numba", "tqdm"):
    sys.modules[name] = None  # importing any of them now raises ImportError
import companion.cli, companion.daemon, companion.alarm_cli, companion.eval_cli, companion.recovery
import runpy
runpy.run_path("trigger_alarm.py", run_name="not_main")
from companion.cli import build_parser
build_parser().parse_args(["--mavlink", "udp:14550", "--sensors", "127.0.0.1:5601"])
sim = ("simbridge", "landfall_eval", "jsbsim", "numba", "tqdm")
loaded = sorted(m for m, mod in sys.modules.items() if mod is not None and m.split(".")[0] in sim)
print("LOADED", loaded)
print("SCIPY", "scipy" in sys.modules)  # 37 MB of the vehicle's memory (companion/guidance/ipm.py)
print("HTTPX", "httpx" in sys.modules)  # about 10 MB: imported when an LVLM tier is built
"""


def test_the_companion_imports_no_simulator_module() -> None:
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "LOADED []" in out.stdout
    assert "SCIPY False" in out.stdout
    assert "HTTPX False" in out.stdout


def test_no_companion_module_imports_the_simulator_even_lazily() -> None:
    """Imports inside functions too (the daemon connects its sensor stream lazily). The demo's
    orchestrator, which starts simbridge beside the daemon, lives in landfall_eval."""
    pattern = re.compile(r"^\s*(from|import)\s+(simbridge|landfall_eval)\b", re.MULTILINE)
    offenders = [
        str(p.relative_to(ROOT))
        for p in [*sorted((ROOT / "companion").rglob("*.py")), ROOT / "trigger_alarm.py"]
        if pattern.search(p.read_text())
    ]
    assert offenders == []
