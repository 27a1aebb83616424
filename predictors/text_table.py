"""The plain-text tables the commands print (``data stats``, ``evaluate``; ``zoo list``, ``zoo
calibrations``, ``review``'s): a name column aligned left, number columns aligned right (or every column
left, its lines without trailing blanks), a rule of dashes under the header; and the counts their lines and
labels give (``counted``)."""

from __future__ import annotations

from collections.abc import Sequence


def aligned_lines(
    header: Sequence[str], rows: Sequence[Sequence[str]], *, numbers_right: bool = True
) -> list[str]:
    """The header, its rule and every row, each cell padded to its column's widest; two spaces apart. Every
    column but the first aligned right, or, without ``numbers_right``, every one left."""
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        if not numbers_right:
            return "  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)).rstrip()
        return "  ".join(
            c.ljust(w) if k == 0 else c.rjust(w) for k, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    return [line(header), "  ".join("-" * w for w in widths), *map(line, rows)]


def counted(n: int, noun: str) -> str:
    """ "1 human", "3 humans", "0 robots": export's printout said "1 humans, 1 robots", and so did the notes,
    refusals and plot labels that count robots and humans, where a run of one robot or one human is
    allowed."""
    return f"{n} {noun}{'s' * (n != 1)}"
