"""The README's main command: the demo lands the vehicle end to end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import free_udp_port

pytestmark = pytest.mark.slow


def test_demo_lands_at_the_site(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "simbridge.demo", "--speed", "16", "--port", str(free_udp_port()),
           "--out", str(tmp_path), "--site", "30,-20"]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "descent step 1: rangefinder" in out.stdout
    assert "handing over to AUTO.LAND" in out.stdout
    summary = out.stdout.split("=== demo summary ===")[1]
    miss_m = float(summary.split("(")[1].split(" m from")[0])
    assert miss_m < 0.5
    assert (tmp_path / "episode.jsonl").exists()
