"""What calibrate prints of its blocks: the margins per step and per motion class, with the coverage held-out
data measured, and the notes on coverage below its target and on blocks without class margins."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pipelines.loop.margins import class_tables
from predictors.conformal import alpha_text


def format_coverage(
    alphas: Sequence[float], quantiles: Sequence[Sequence[float]], coverage: Sequence[Sequence[float]] | None
) -> str:
    """One line per alpha: margins per step and, when measured, held-out coverage against 1 - alpha."""
    lines = []
    for i, alpha in enumerate(alphas):
        margins = ", ".join(f"{q:.3f}" for q in quantiles[i])
        line = f"  alpha {alpha_text(alpha):<5} margins m_k [m]: {margins}"
        if coverage is not None:
            line += f" | held-out coverage (target {coverage_target(alpha)}): " + ", ".join(
                f"{c:.1%}" for c in coverage[i]
            )
        lines.append(line)
    return "\n".join(lines)


def coverage_notes(alphas: Sequence[float], holdout: Any, coverage: Any) -> str:
    """A note line for each alpha whose held-out coverage at a step falls below ``1 - alpha`` by more than a
    binomial 95 % margin over its samples: the block is stored all the same, but may not hold on this data."""
    if holdout is None or coverage is None:
        return ""
    counts, notes = np.sum(~np.isnan(np.asarray(holdout, dtype=float)), axis=0), ""
    for alpha, steps in zip(alphas, coverage, strict=True):
        floor = [1 - alpha - 1.96 * math.sqrt((1 - alpha) * alpha / n) if n else -1.0 for n in counts]
        low = [k for k, c in enumerate(steps) if math.isfinite(c) and c < floor[k]]
        if low:
            k = min(low, key=lambda k: steps[k] - floor[k])
            notes += (
                f"note: alpha {alpha_text(alpha)}: held-out coverage {steps[k]:.1%} at step {k + 1} is below "
                f"the target {coverage_target(alpha)} beyond chance (95 % margin {floor[k]:.1%} over "
                f"{counts[k]} samples; {len(low)} step{'s' * (len(low) != 1)} so): its margins may not hold "
                "on this data\n"
            )
    return notes


def coverage_target(alpha: float) -> str:
    """``1 - alpha`` in percent, exactly as the alpha is written (0.025: 97.5%, 1e-05: 99.999%): a rounded
    target (98%, 100%) would misstate the coverage each margin was made for."""
    from decimal import Decimal

    return f"{(100 * (1 - Decimal(alpha_text(alpha)))).normalize():f}%"


def class_coverage_report(
    blocks: Sequence[Any], holdout: np.ndarray | None, classes: np.ndarray | None, shortfall: bool = False
) -> list[list[list[float]] | None] | None:
    """Print each block's class margins (``predictors.conformal_classes``; ``shortfall``: those of the
    distance-shortfall score) and, given held-out scores with their classes, the coverage within each class;
    returns that coverage (block, class, step), one entry per block in order (None for a block without class
    margins, so entry i stays blocks[i]'s), or None without held-out scores."""
    from predictors.conformal_classes import MOTION_CLASSES, class_coverage

    report: list[list[list[float]] | None] = []
    for block in blocks:
        table = block.shortfall if shortfall else block.classes
        if table is None:
            report.append(None)
            continue
        cover = None
        if holdout is not None and classes is not None:
            cover = class_coverage(holdout, classes, table)
        score = "distance shortfall" if shortfall else "displacement"
        print(f"  alpha {alpha_text(block.alpha)}, {score} margins per motion class (samples at step 1):")
        for c, name in enumerate(MOTION_CLASSES):
            margins = ", ".join(f"{q:.3f}" for q in table.quantiles[c])
            line = f"    {name:<9} n={table.n[c][0]:<6} m_k [m]: {margins}"
            if cover is not None and all(math.isnan(v) for v in cover[c]):
                line += " | held-out coverage: no held-out samples in this class"
            elif cover is not None:
                line += " | held-out coverage: " + ", ".join(
                    "-" if math.isnan(v) else f"{v:.1%}" for v in cover[c]
                )
            print(line)
        if cover is not None:
            report.append([list(row) for row in cover])
    return report if holdout is not None and classes is not None else None


def missing_class_margins(blocks: Sequence[Any]) -> list[str]:
    """A line for each closed-loop block without margins per motion class: ``conformal-motion`` and
    ``conformal-shortfall`` will refuse it (once stored, it takes the place of the shipped block of its
    predictor, alpha and view of the humans), so the user learns it now rather than at the first episode
    that asks."""
    from predictors.conformal import min_samples

    lines = []
    for block in blocks:
        missing = [mode for mode, table in class_tables(block).items() if table is None]
        if missing:
            lines.append(
                f"  alpha {alpha_text(block.alpha)}: no margins per motion class, so {' and '.join(missing)} "
                f"will refuse this calibration: a class had fewer than {min_samples(block.alpha)} samples at "
                "some step (more --episodes give them)"
            )
    return lines
