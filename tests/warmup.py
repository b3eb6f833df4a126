"""Compile simbridge's numba kernels before the suite: ``python -m tests.warmup``.

``make test`` runs this beside the linters, so the kernels are in __pycache__ (``cache=True``) before
pytest starts; pytest's own ``pytest_configure`` (tests/conftest.py) calls it again, which then takes a
few seconds. On a fresh clone the compilation alone takes 1.5-2.5 minutes on one core. The work is
:func:`simbridge.warmup.warm_up`'s.
"""

from __future__ import annotations


def warm_up() -> None:
    from simbridge.warmup import warm_up as compile_kernels

    compile_kernels()


if __name__ == "__main__":
    warm_up()
