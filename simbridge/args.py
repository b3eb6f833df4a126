"""Argument types the simulator's command lines share (``simbridge``, ``simbridge render``, and
``companion-bench``), below all of them."""

from __future__ import annotations

import argparse

__all__ = ["non_negative_seed"]


def non_negative_seed(text: str) -> int:
    """An argparse type: a whole number >= 0 (argparse names the flag in its error)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value
