"""One module per CLI subcommand. Each defines ``register(subparsers)``; heavy imports happen inside ``run``
so that ``crowdmpc --help`` stays fast."""

from __future__ import annotations

import argparse


def humans_list(text: str) -> tuple[int, ...]:
    """An argparse type: ``5,6,7`` -> (5, 6, 7), positive integers (``--humans`` of sweep and calibrate)."""
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--humans takes integers like 5,6,7, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"--humans needs positive numbers, got {text!r}")
    return values
