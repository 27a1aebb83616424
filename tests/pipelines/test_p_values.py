"""The paired comparison's p-value as table.md and `crowdmpc compare` print it: two significant digits, but
never rounded across a level it is read against (a p of 0.0498 printed as 0.05 read as not significant)."""

from __future__ import annotations

import pytest

from pipelines.experiments.cells import get_experiment
from pipelines.experiments.paired import Paired, mcnemar_exact
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import markdown_table
from tests.pipelines.test_small_fixes import _records

SUCCEEDED, FAILED = (
    (True, False, False, False),
    (False, False, False, False),
)  # (success, collision, contact, discomfort)


def test_table_prints_a_p_below_005_below_it():
    """DMPC succeeded on 42 crowds CMPC failed, CMPC on 25 DMPC failed: exact McNemar p = 0.0498."""
    table2 = get_experiment("table2")
    cmpc = [FAILED] * 42 + [SUCCEEDED] * 25 + [SUCCEEDED] * 9
    dmpc = [SUCCEEDED] * 42 + [FAILED] * 25 + [SUCCEEDED] * 9
    summaries = summarize(table2, table2.cells(), _records(table2, {("CMPC", 5): cmpc, ("DMPC", 5): dmpc}))
    assert mcnemar_exact(42, 25) == pytest.approx(0.0498, abs=5e-5)
    table = markdown_table(table2, summaries)
    assert "| Success, paired with the group's first method | reference | +42 / −25 (p = 0.0498) |" in table


@pytest.mark.parametrize(
    ("gained", "lost", "text"),
    [(42, 25, "+42 / −25 (p = 0.0498)"), (74, 45, "+74 / −45 (p = 0.00997)"), (3, 1, "+3 / −1 (p = 0.62)"),
     (0, 0, "+0 / −0 (p = 1)"), (6, 0, "+6 / −0 (p = 0.031)"), (5, 0, "+5 / −0 (p = 0.062)")],
)  # fmt: skip
def test_compare_prints_p_as_the_table(gained, lost, text):
    assert Paired(gained, lost).text() == text


def test_no_printed_p_reads_otherwise_than_p_at_005_or_001():
    """Every split of up to 400 discordant pairs: the printed p on the same side of 0.05 and 0.01 as p."""
    for n in range(1, 401):
        for b in range(n // 2 + 1):
            p = mcnemar_exact(b, n - b)
            printed = float(Paired(b, n - b).text().rsplit("p = ", 1)[1].rstrip(")"))
            assert (printed < 0.05, printed < 0.01) == (p < 0.05, p < 0.01), (b, n - b, p)
