"""The daemon's glibc malloc arenas (companion.memory.limit_malloc_arenas): one, so that freed
memory held by each worker thread's own arena does not add to the vehicle's peak; an operator's
MALLOC_ARENA_MAX (or glibc's tunable) wins. Counted by glibc's own malloc_stats in a fresh process whose
threads allocate. And companion.memory.trim_malloc, which the daemon calls after its warm-up: freed
memory that glibc kept goes back to the system."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(
    platform.libc_ver()[0] != "glibc", reason="malloc arenas are glibc's (this C library has none to limit)"
)

SCRIPT = """
import ctypes, sys, threading
from companion.memory import limit_malloc_arenas
print(limit_malloc_arenas() if sys.argv[1] == "limit" else "unset", flush=True)
kept = []
together = threading.Barrier(8)  # every thread alive at once: none hands its arena on to the next
def work():
    kept.append([bytearray(200_000) for _ in range(20)])
    together.wait()
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads:
    t.start()
for t in threads:
    t.join()
ctypes.CDLL(None).malloc_stats()  # one "Arena N:" block per arena, on stderr
"""


def _arenas(mode: str, env_max: str | None = None, tunables: str | None = None) -> tuple[str, int]:
    env = {k: v for k, v in os.environ.items() if k not in ("MALLOC_ARENA_MAX", "GLIBC_TUNABLES")}
    if env_max is not None:
        env["MALLOC_ARENA_MAX"] = env_max
    if tunables is not None:
        env["GLIBC_TUNABLES"] = tunables
    env["MALLOC_MMAP_THRESHOLD_"] = str(1 << 24)  # every block from an arena, none mapped apart
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, env=env, timeout=60, check=True
    )
    return out.stdout.strip(), sum(line.startswith("Arena ") for line in out.stderr.splitlines())


def test_eight_threads_share_one_arena_once_limited() -> None:
    said, unlimited = _arenas("unset")
    assert said == "unset"
    assert unlimited > 2, unlimited  # glibc's own way: an arena per thread that allocates
    said, limited = _arenas("limit")
    assert said == "True"
    assert limited == 1, limited


def test_the_operators_malloc_arena_max_wins() -> None:
    said, arenas = _arenas("limit", env_max="4")
    assert said == "False"  # not overridden
    assert 1 < arenas <= 4, arenas


def test_glibcs_own_tunable_wins_too() -> None:
    said, arenas = _arenas("limit", tunables="glibc.malloc.arena_max=4")
    assert said == "False"
    assert 1 < arenas <= 4, arenas


TRIM = """
import ctypes, threading
from companion.memory import limit_malloc_arenas, trim_malloc
limit_malloc_arenas()

def anon_mb():
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("RssAnon")) / 1024

def work():  # as a reasoner's worker thread: 60 MB in 64 kB blocks, written, then freed but the last
    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    libc.free.argtypes = (ctypes.c_void_p,)
    blocks = [libc.malloc(1 << 16) for _ in range(960)]
    for b in blocks:
        ctypes.memset(b, 1, 1 << 16)
    for b in blocks[:-1]:  # the last keeps the heap's top in use: glibc cannot shrink it by itself
        libc.free(b)

t = threading.Thread(target=work)
t.start()
t.join()
before = anon_mb()
trimmed = trim_malloc()
print(before, anon_mb(), trimmed)
"""


def test_trimming_hands_back_what_a_worker_thread_freed() -> None:
    out = subprocess.run([sys.executable, "-c", TRIM], capture_output=True, text=True, timeout=60, check=True)
    before, after, trimmed = out.stdout.split()
    assert trimmed == "True"
    assert float(before) - float(after) > 40.0, out.stdout  # of the 60 MB freed


BUILD = """
import sys
import companion.cli
from companion.config import load_config
from companion.memory import limit_malloc_arenas
limit_malloc_arenas()
if sys.argv[1] == "keep":
    companion.cli.trim_malloc = lambda: False  # the daemon as it was: what the load freed stays
companion.cli.build_companion(load_config(None, {}, {}))
print(next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("RssAnon")) / 1024)
"""


def test_building_the_daemon_hands_back_what_loading_the_net_freed() -> None:
    """ONNX Runtime's graph optimisation frees some 30 MB while the onboard net loads; the warm-up's
    worker thread then read on top of it, and the daemon's peak began there (205 MB one second after
    its start, in flight). Built, the daemon has handed that back."""

    def anon_mb(mode: str) -> float:
        out = subprocess.run(
            [sys.executable, "-c", BUILD, mode], capture_output=True, text=True, timeout=120, check=True
        )
        return float(out.stdout.split()[-1])

    kept, handed_back = anon_mb("keep"), anon_mb("trim")
    assert kept - handed_back > 15.0, (kept, handed_back)
