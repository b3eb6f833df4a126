"""The README's main command: an alarm lands the vehicle on the clear roof, end to end."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

pytestmark = pytest.mark.slow


def test_demo_lands_safely(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "landfall_eval.demo", "--speed", "6", "--out", str(tmp_path)]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=400)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "accepted: recovery started" in out.stdout
    assert "[companion] descending" in out.stdout
    summary = out.stdout.split("=== Landfall demo summary ===")[1]
    assert "surface      rooftop_clear" in summary
    assert "safe         True" in summary
    assert (tmp_path / "episode.jsonl").exists()
    records = list((tmp_path / "record").glob("*/events.jsonl"))
    assert len(records) == 1
    kinds = [json.loads(line)["kind"] for line in records[0].read_text().splitlines()]
    assert "rank" in kinds
    assert "confirm" in kinds
    assert kinds[-1] == "outcome"
    # the report: the round's frame with the candidates boxed, the confirmations, the trajectory
    assert f"report       {tmp_path / 'report.html'}" in summary
    page = (tmp_path / "report.html").read_text()
    assert "<h3>Round 1: ranking</h3>" in page
    assert "(chosen)" in page
    assert "confirmation 1: accepted" in page
    shown = [part.split('"', 1)[0] for part in page.split('src="')[1:]]
    assert "figures/map.png" in shown
    assert "figures/round01.jpg" in shown
    assert all((tmp_path / src).is_file() for src in shown)
    frame = cv2.imread(str(tmp_path / "figures" / "round01.jpg"))
    assert frame.shape == (360, 640, 3)
