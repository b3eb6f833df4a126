"""Compile simbridge's numba kernels (a frame rendered, a sweep cast): ``python -m tests.warmup``.

``make test`` runs this beside the linters, so the kernels are in __pycache__ (``cache=True``) before
pytest starts; pytest's own ``pytest_configure`` (tests/conftest.py) calls it again, which then takes a
few seconds. On a fresh clone the compilation alone takes about a minute and a half on one core.
"""

from __future__ import annotations


def warm_up() -> None:
    import numpy as np

    from tests.views import LAUNCH, LEVEL, render, world

    w = world("scenario1")
    render(w, LAUNCH)
    w.lidar_sweep(LAUNCH, LEVEL, 0.0, np.random.default_rng(0))


if __name__ == "__main__":
    warm_up()
