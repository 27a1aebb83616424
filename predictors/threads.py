"""torch on one thread for the tiny tensors of a prediction (used by the predictors and their checks)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


@contextmanager
def single_threaded() -> Iterator[None]:
    """Run torch on one thread: these tensors are tiny, and on a shared CPU torch's thread pool spin-waits
    (a 64x40 linear layer took 1-1.7 ms on 2 threads against 0.1 ms on one, measured on the 2-core box)."""
    before = torch.get_num_threads()
    if before != 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if before != 1:
            torch.set_num_threads(before)
