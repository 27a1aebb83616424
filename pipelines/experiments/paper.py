"""The paper's own figures: Tables II and III as printed, per method and number of humans."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

PAPER_HUMANS: Final[tuple[int, ...]] = (5, 6, 7, 8, 9)  # Tables II and III

PAPER_REFERENCE: Final[str] = (
    "Le, Tadiparthi, Chalaki, Mahjoub, D'sa, Moradi-Pari, Malikopoulos, 'Multi-Robot Cooperative Navigation "
    "in Crowds: A Game-Theoretic Learning-Based Model Predictive Control Approach', Section VI"
)


@dataclass(frozen=True)
class PaperFigures:
    """One column of the paper's Table II or III (1000 episodes: 500 circle + 500 perpendicular)."""

    success: float  # success rate, %
    travel_time: float  # average travel time over successful episodes, s
    collision: float  # collision (personal-space violation, < 0.8 m) rate, %
    discomfort: float  # discomfort rate, %


def _figures(rows: Mapping[str, Sequence[Sequence[float]]]) -> Mapping[tuple[str, int], PaperFigures]:
    """Build {(method, n_humans): figures} from per-method rows (success, time, collision, discomfort)
    each listing 5..9 humans, the transposition of how the paper prints them."""
    table: dict[tuple[str, int], PaperFigures] = {}
    for method, (success, time, collision, discomfort) in rows.items():
        for k, n in enumerate(PAPER_HUMANS):
            table[(method, n)] = PaperFigures(success[k], time[k], collision[k], discomfort[k])
    return MappingProxyType(table)


# Table II, "Comparison between centralized MPC (CMPC) and distributed MPC (DMPC)", as the paper prints it.
PAPER_TABLE_II: Final = _figures(
    {
        "CMPC": (
            (94.0, 91.9, 90.0, 86.7, 84.5),
            (17.9, 18.6, 19.1, 19.6, 20.1),
            (0.2, 0.8, 1.3, 1.1, 1.2),
            (0.5, 1.2, 1.3, 1.4, 2.1),
        ),
        "DMPC": (
            (93.4, 91.8, 88.7, 86.9, 83.9),
            (18.1, 18.7, 19.2, 19.8, 20.3),
            (0.3, 0.6, 1.1, 1.1, 1.9),
            (0.6, 1.5, 1.1, 1.3, 1.8),
        ),
    }
)

# Table III, "Comparison between centralized MPC with (F) and without (NF) the flocking objective". Its F
# column is CMPC of Table II, but the paper prints 86.6 / 84.7 % success at 8 / 9 humans where Table II has
# 86.7 / 84.5: both are kept as printed.
PAPER_TABLE_III: Final = _figures(
    {
        "F": (
            (94.0, 91.9, 90.0, 86.6, 84.7),
            (17.9, 18.6, 19.1, 19.6, 20.1),
            (0.2, 0.8, 1.3, 1.1, 1.2),
            (0.5, 1.2, 1.3, 1.4, 2.1),
        ),
        "NF": (
            (96.7, 94.0, 93.8, 88.8, 86.1),
            (17.6, 18.4, 18.8, 19.3, 19.8),
            (0.2, 0.9, 0.4, 1.8, 2.4),
            (1.4, 2.2, 2.0, 2.2, 2.6),
        ),
    }
)
