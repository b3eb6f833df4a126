"""Coverage-guided fuzzing (atheris, libFuzzer) of every reader of outside input, each target in its
own process for a fixed number of runs from its seed corpus (tests/fuzz_atheris.py). Atheris ships
wheels for Linux x86-64 only: elsewhere these are skipped and tests/test_fuzz.py (hypothesis) still
covers the same readers."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris", reason="atheris installs on Linux x86-64 only (the dev extra's marker)")

ROOT = Path(__file__).resolve().parent.parent
RUNS = {"rank": 50000, "confirm": 50000, "config": 20000, "sensor": 50000, "mavlink": 50000, "mqtt": 50000}


@pytest.mark.parametrize("target", sorted(RUNS))
def test_atheris_finds_no_crash(target: str, tmp_path: Path) -> None:
    runs = RUNS[target]
    # libFuzzer's RSS limit reads the process's peak RSS (ru_maxrss), which a child inherits from its
    # parent at fork: run under a test worker that has rendered frames (2 GB and more), the fuzzer would
    # report out-of-memory before its first input. The limit on one allocation stays. The harness's
    # corpus and scratch directories (tempfile) go under tmp_path, which pytest clears, not /tmp.
    res = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "fuzz_atheris.py"), target, f"-runs={runs}", "-seed=1",
         f"-artifact_prefix={tmp_path}/", "-rss_limit_mb=0", "-malloc_limit_mb=2048"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env={**os.environ, "TMPDIR": str(tmp_path)},
    )  # fmt: skip
    assert list(tmp_path.glob(f"landfall-fuzz-{target}-*")), "the corpus went elsewhere than tmp_path"
    crashes = list(tmp_path.glob("crash-*"))
    assert res.returncode == 0, res.stderr[-4000:]
    assert not crashes
    done = re.search(r"Done (\d+) runs", res.stderr)
    assert done is not None, res.stderr[-2000:]
    assert int(done.group(1)) == runs
    cov = re.findall(r"cov: (\d+)", res.stderr)
    assert cov
    assert int(cov[-1]) > 10  # the instrumented readers were reached, not just the harness
