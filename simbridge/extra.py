"""The simulator's own dependencies are an extra: ``pip install 'landfall[sim]'``.

A companion computer installs ``landfall`` without them (the companion imports no simulator module).
Where any is missing, ``simbridge`` and ``companion-bench`` say so in one line and exit 2 before they
start, instead of ending in an ImportError's traceback (or, for companion-bench, after a run whose
episodes all failed). This module imports nothing outside the standard library.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Sequence

__all__ = ["INSTALL_HINT", "SIM_MODULES", "missing_sim_modules", "run_command"]

INSTALL_HINT = "pip install 'landfall[sim]'"
SIM_MODULES = ("jsbsim", "numba", "tqdm", "av")  # the sim extra's top-level modules (pyproject.toml)


def missing_sim_modules() -> list[str]:
    """The modules of the ``sim`` extra that cannot be imported here."""
    return [name for name in SIM_MODULES if importlib.util.find_spec(name) is None]


def run_command(prog: str, module: str, argv: Sequence[str] | None = None) -> int:
    """``module.main(argv)``'s exit status, or 2 with one line on stderr when the ``sim`` extra is
    missing (``module`` is then not imported)."""
    missing = missing_sim_modules()
    if missing:
        print(
            f"{prog}: the simulator's dependencies are not installed ({', '.join(missing)} missing): "
            f"{INSTALL_HINT}",
            file=sys.stderr,
        )
        return 2
    return int(importlib.import_module(module).main(argv))
