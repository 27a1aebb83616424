"""The bound on a net's size, one value for every model kind (``predictors.kinds``, plugins included) and the
shipped nets' configs (``predictors.nets``). A leaf module: the kinds stay torch-free, and the nets need not
import the kinds (which import them back, lazily, to build predictors)."""

from __future__ import annotations

from typing import Final

# A config is a file anyone can edit: its size is counted (or built on the meta device) and checked against
# this before memory is taken. Why 10 M: nets.social_lstm.SIZE_BOUNDS.
MAX_PARAMETERS: Final[int] = 10_000_000
