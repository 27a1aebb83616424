"""Episode metrics compared field by field with NaN equal to NaN, the same on every Python.

``EpisodeMetrics.travel_time`` is NaN unless the episode succeeded (and ``reach_times`` NaN for a robot that
never arrived), so ``a == b`` of two records of one failed episode depended on the Python: up to 3.12 a
dataclass's ``__eq__`` compared its fields as one tuple, whose ``==`` takes the same object (``math.nan``) as
equal to itself; 3.13 compares field by field with ``==``, and NaN is not equal to NaN."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from crowdsim.metrics import EpisodeMetrics


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def same_metrics(a: EpisodeMetrics, b: EpisodeMetrics) -> bool:
    """Whether every field of ``a`` equals ``b``'s, as the dataclass's ``==`` would, with NaN equal to NaN."""
    assert type(a) is EpisodeMetrics and type(b) is EpisodeMetrics
    return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(EpisodeMetrics))
