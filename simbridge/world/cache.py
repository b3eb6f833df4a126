"""Built places kept on disk, so that a campaign builds each city once.

A procedural place is a pure function of its kind, its seed and this package's code, and building one
takes seconds of CPU (2.3 s for a downtown city on this project's machine) that every episode of a
campaign, and its grading, would otherwise pay again. :func:`cached_place` stores the built
:class:`~simbridge.world.world.World` under ``DIR/KIND-SEED-CODE/``: its four rasters as ``.npy``
files and the rest pickled, with what every process would otherwise compute again from the rasters:
the world's digest and the ray caster's max maps (``pyramid.npy``). A later call maps the rasters and
the maps copy-on-write (``numpy.load(mmap_mode="c")``): the actors stamped into them as the episode runs
stay in the process's own pages and never reach the files, so one entry serves every process at once.
``CODE`` fingerprints the source of ``simbridge.world``, so an entry built by other code is never read.

Writers race safely: each builds into a private directory and renames it into place; the loser's copy
is removed. An entry that cannot be read (a disk filled half-way, files removed by hand) is built again
and replaced, with a warning.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
import os
import pickle
import shutil
import tempfile
from pathlib import Path

import numpy as np

from simbridge.world.model import WorldGrid
from simbridge.world.raycast import Pyramid, check_maps
from simbridge.world.world import World

__all__ = ["cached_place", "code_fingerprint", "entry_dir"]

_log = logging.getLogger(__name__)
_RASTERS = ("height", "cls", "mat", "region")
_META = "world.pickle"
_PYRAMID = "pyramid.npy"


@functools.cache
def code_fingerprint() -> str:
    """A digest of every ``.py`` file of ``simbridge.world`` (its builders and what they paint with)."""
    here = Path(__file__).resolve().parent
    h = hashlib.blake2b(digest_size=6)
    for path in sorted(here.rglob("*.py")):
        h.update(str(path.relative_to(here)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def entry_dir(cache_dir: Path, place: str, seed: int) -> Path:
    """Where the place of kind ``place`` and seed ``seed`` is kept under ``cache_dir``."""
    return Path(cache_dir) / f"{place}-{seed}-{code_fingerprint()}"


def cached_place(place: str, seed: int, cache_dir: Path | None) -> World:
    """:func:`~simbridge.world.places.generate_place` through the cache at ``cache_dir`` (None: built
    here, nothing kept). The world returned is the caller's own to stamp actors into.

    A cache that cannot be written (a full disk, a folder another node cannot reach) costs only the
    time: the place is built here and the reason logged.

    Raises:
        ValueError: as ``generate_place`` (an unknown kind, a bad seed).
    """
    from simbridge.world.places import generate_place

    if cache_dir is None:
        return generate_place(place, seed)
    entry = entry_dir(cache_dir, place, seed)
    if entry.is_dir():
        try:
            return _read(entry)
        except (OSError, ValueError, EOFError, pickle.UnpicklingError) as exc:
            _log.warning("world cache %s unreadable (%s): building it again", entry, exc)
            shutil.rmtree(entry, ignore_errors=True)
    world = generate_place(place, seed)
    world = dataclasses.replace(
        world, known_digest=world.digest(), pyramid_maps=Pyramid(world.grid.height).maps
    )
    try:
        _write(entry, world)
    except OSError as exc:
        _log.warning("world cache %s not written (%s): this process built its own", entry, exc)
    return world


def _read(entry: Path) -> World:
    with (entry / _META).open("rb") as f:
        meta = pickle.load(f)
    if not isinstance(meta, dict) or not isinstance(meta.get("world"), World):
        raise ValueError("not a cached world")
    # plain arrays over the mapping (numba's kernels take ndarrays, not the memmap subclass)
    rasters = {name: np.load(entry / f"{name}.npy", mmap_mode="c").view(np.ndarray) for name in _RASTERS}
    grid = WorldGrid(n0=meta["n0"], e0=meta["e0"], res=meta["res"], **rasters)
    shapes = {r.shape for r in rasters.values()}
    if len(shapes) != 1:
        raise ValueError(f"rasters of different shapes {sorted(shapes)}")
    if not isinstance(meta.get("digest"), str):
        raise ValueError("no digest kept")
    maps = np.load(entry / _PYRAMID, mmap_mode="c").view(np.ndarray)
    check_maps(maps, grid.height.shape)
    world: World = dataclasses.replace(
        meta["world"], grid=grid, known_digest=meta["digest"], pyramid_maps=maps
    )
    return world


def _write(entry: Path, world: World) -> None:
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{entry.name}-", dir=entry.parent))
    try:
        g = world.grid
        for name in _RASTERS:
            np.save(tmp / f"{name}.npy", getattr(g, name))
        np.save(tmp / _PYRAMID, world.pyramid_maps)
        empty = WorldGrid(n0=g.n0, e0=g.e0, res=g.res, **{n: np.zeros((0, 0), np.uint8) for n in _RASTERS})
        bare = dataclasses.replace(world, grid=empty, known_digest=None, pyramid_maps=None)
        meta = {"world": bare, "n0": g.n0, "e0": g.e0, "res": g.res, "digest": world.known_digest}
        with (tmp / _META).open("wb") as f:
            pickle.dump(meta, f, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            os.rename(tmp, entry)
        except OSError:  # another process stored it first: theirs stands
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
