"""Peak memory of the onboard judge reading ranks and confirmations with glibc's malloc as it comes, as
the daemon sets it (``companion.memory.limit_malloc_arenas``: one arena; this process's reads run on one
thread, so it should change nothing here) and with a fixed 1 MiB mmap threshold (large freed blocks go
back to the system at once: less memory, more page faults).

Each variant runs in a fresh process on one core: the companion's imports, the default packaged net
(``companion.reasoning.landnet.DEFAULT_MODEL``) loaded, then ``--rounds`` rounds of a rank of five crops
and a confirmation (the site window and the whole-image read of a 960 x 540 close-up), each crop and
close-up of its own random size (a flight's crops differ), read the way the reasoner reads them.
Printed per variant: the process's peak RSS (the kernel's VmHWM) and its anonymous memory at the end,
after the imports and after the load, and the median time of a round (one core; the daemon's goal is
rank <= 50 ms, confirmation <= 20 ms, which benchmarks/bench_onboard.py times on simbridge's frames).
Medians over ``--runs`` processes per variant, variants taking turns.

Usage: python benchmarks/bench_judge_memory.py [--runs 3] [--rounds 20]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = """
import json, os, statistics, sys, time
import numpy as np
from landfall_eval.timing import pin_one_core
pin_one_core()
import companion.cli  # the daemon's imports, companion.memory among them
if sys.argv[1] == "daemon":
    companion.memory.limit_malloc_arenas()
from companion.reasoning.landnet import DEFAULT_MODEL, LandNet
from landfall_eval.processes import ProcessSample

def mem():
    sample = ProcessSample(os.getpid())  # VmHWM, and RssAnon now
    sample.sample()
    return {"VmHWM": sample.peak_rss_mb, "RssAnon": sample.peak_anon_mb}

after_imports = mem()
net = LandNet.load(DEFAULT_MODEL)
after_load = mem()
rng = np.random.default_rng(int(sys.argv[3]))
times = []
for _ in range(int(sys.argv[2])):
    crops = [rng.integers(0, 256, (int(rng.integers(40, 320)), int(rng.integers(40, 320)), 3), np.uint8)
             for _ in range(5)]
    close = rng.integers(0, 256, (540, 960, 3), np.uint8)
    t0 = time.perf_counter()
    for crop in crops:
        net.read_rank(crop)
    window = close[90:450, 160:800]
    net.confirmation(net.read(window, short_side=net.confirm_short_side_px), close)
    times.append(time.perf_counter() - t0)
end = mem()
print(json.dumps({"imports_mb": after_imports["VmHWM"], "load_mb": after_load["VmHWM"],
                  "peak_mb": end["VmHWM"], "anon_end_mb": end["RssAnon"],
                  "round_ms": 1e3 * statistics.median(times)}))
"""

VARIANTS = ("glibc", "daemon", "mmap-1MiB")


def run_child(variant: str, rounds: int, seed: int) -> dict[str, float]:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("MALLOC_ARENA_MAX", "MALLOC_MMAP_THRESHOLD_", "GLIBC_TUNABLES")
    }
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if variant == "mmap-1MiB":
        env["GLIBC_TUNABLES"] = "glibc.malloc.mmap_threshold=1048576"
    out = subprocess.run(
        [sys.executable, "-c", CHILD, variant, str(rounds), str(seed)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        check=True,
    )
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=20)
    a = ap.parse_args(argv)
    got: dict[str, list[dict[str, float]]] = {v: [] for v in VARIANTS}
    for k in range(a.runs):
        for variant in VARIANTS:
            got[variant].append(run_child(variant, a.rounds, seed=k))
            r = got[variant][-1]
            print(f"run {k + 1}/{a.runs} {variant}: peak {r['peak_mb']:.0f} MB, round {r['round_ms']:.1f} ms")
    med = {v: {key: statistics.median(r[key] for r in got[v]) for key in got[v][0]} for v in VARIANTS}
    for v in VARIANTS:
        m = med[v]
        print(
            f"{v}: peak RSS {m['peak_mb']:.0f} MB (after imports {m['imports_mb']:.0f}, after the load "
            f"{m['load_mb']:.0f}; anonymous at the end {m['anon_end_mb']:.0f}), "
            f"a round {m['round_ms']:.1f} ms"
        )
    g = med["glibc"]
    for v in VARIANTS[1:]:
        t = med[v]
        print(
            f"{v} / glibc: peak {t['peak_mb'] / g['peak_mb']:.2f}x ({t['peak_mb'] - g['peak_mb']:+.0f} MB), "
            f"round time {t['round_ms'] / g['round_ms']:.2f}x"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
