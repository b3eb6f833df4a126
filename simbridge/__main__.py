"""``simbridge`` and ``python -m simbridge``: the command line, or one line saying to install the
``sim`` extra where its dependencies are missing (:mod:`simbridge.extra`)."""

import sys

from simbridge.extra import run_command


def main() -> int:
    return run_command("simbridge", "simbridge.cli")


if __name__ == "__main__":
    sys.exit(main())
