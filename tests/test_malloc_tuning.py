"""The daemon's glibc malloc (companion.cli.tune_malloc): at most two arenas, so that freed memory held
by each worker thread's own arena does not add to the vehicle's peak, counted by glibc's own
malloc_stats in a fresh process whose threads allocate; and a fixed mmap threshold, so that large blocks
are still mapped apart (and given back when freed) after a larger one was freed, counted by mallinfo2.
The operator's MALLOC_ARENA_MAX, MALLOC_MMAP_THRESHOLD_ or GLIBC_TUNABLES win."""

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
from companion.cli import tune_malloc
print(tune_malloc()["arenas"] if sys.argv[1] == "limit" else "unset", flush=True)
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


def _arenas(mode: str, env_max: str | None = None) -> tuple[str, int]:
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    if env_max is not None:
        env["MALLOC_ARENA_MAX"] = env_max
    env["MALLOC_MMAP_THRESHOLD_"] = str(1 << 24)  # every block from an arena, none mapped apart
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, env=env, timeout=60, check=True
    )
    return out.stdout.strip(), sum(line.startswith("Arena ") for line in out.stderr.splitlines())


def test_eight_threads_share_two_arenas_once_limited() -> None:
    said, unlimited = _arenas("unset")
    assert said == "unset"
    assert unlimited > 2, unlimited  # glibc's own way: an arena per thread that allocates
    said, limited = _arenas("limit")
    assert said == "True"
    assert limited <= 2, limited


def test_the_operators_malloc_arena_max_wins() -> None:
    said, arenas = _arenas("limit", env_max="4")
    assert said == "False"  # not overridden
    assert 2 < arenas <= 4, arenas


MAPPED = """
import ctypes, sys
from companion.cli import tune_malloc
print(tune_malloc()["mmap_threshold"] if sys.argv[1] == "tune" else "unset", flush=True)
class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]
libc = ctypes.CDLL(None)
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, (ctypes.c_size_t,)
libc.free.argtypes = (ctypes.c_void_p,)
libc.mallinfo2.restype = MallInfo2
libc.free(libc.malloc(16 << 20))  # glibc's own rule raises its threshold to 16 MiB on this free
before = libc.mallinfo2().hblks
blocks = [libc.malloc(2 << 20) for _ in range(4)]
print(libc.mallinfo2().hblks - before)
"""


def _mapped(mode: str, env: dict[str, str] | None = None) -> tuple[str, int]:
    run_env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_ARENA_MAX", "GLIBC_TUNABLES")
    }
    run_env.update(env or {})
    out = subprocess.run(
        [sys.executable, "-c", MAPPED, mode],
        capture_output=True,
        text=True,
        env=run_env,
        timeout=60,
        check=True,
    )
    said, mapped = out.stdout.split()
    return said, int(mapped)


def test_large_blocks_stay_mapped_apart_after_a_larger_one_is_freed() -> None:
    said, mapped = _mapped("unset")
    assert (said, mapped) == ("unset", 0)  # glibc's own way: the four 2 MiB blocks come from the heap
    said, mapped = _mapped("tune")
    assert (said, mapped) == ("True", 4)  # each mapped apart: given back to the system when freed


@pytest.mark.parametrize(
    "env",
    [{"MALLOC_MMAP_THRESHOLD_": str(8 << 20)}, {"GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=8388608"}],
)
def test_the_operators_mmap_threshold_wins(env: dict[str, str]) -> None:
    said, mapped = _mapped("tune", env)
    assert said == "False"
    assert mapped == 0  # their fixed 8 MiB threshold: the 2 MiB blocks from the heap
