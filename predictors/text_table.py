"""The plain-text tables the predictors' commands print (``data stats``, ``evaluate``): a name column
aligned left, number columns aligned right, a rule of dashes under the header."""

from __future__ import annotations

from collections.abc import Sequence


def aligned_lines(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """The header, its rule and every row, each cell padded to its column's widest; two spaces apart."""
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(
            c.ljust(w) if k == 0 else c.rjust(w) for k, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    return [line(header), "  ".join("-" * w for w in widths), *map(line, rows)]
