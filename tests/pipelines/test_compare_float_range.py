"""`crowdmpc compare` of records whose travel times are finite, as a record's numbers must be, but past what a
float's arithmetic holds (only a hand-edited record has them): Python's statistics ended it in a traceback
("AttributeError: 'float' object has no attribute 'numerator'" from stdev of an overflowed difference,
"ValueError: -inf + inf in fsum", "OverflowError: intermediate overflow in fsum" from fmean). Now one line
naming the episode."""

from __future__ import annotations

import pytest

from pipelines.cli import main
from tests.pipelines.test_compare import _record, _sweep

HUGE = 1.7e308  # finite: check_record takes it


@pytest.mark.parametrize(
    ("base", "other", "what"),
    [
        ([-HUGE, HUGE], [HUGE, -HUGE], "the travel times' paired difference"),  # each difference overflows
        ([-HUGE / 2] * 2, [HUGE / 2] * 2, "the travel times' paired difference"),  # their sum does
        ([10.0, 10.0], [HUGE, HUGE], "the mean travel time"),  # a run's own sum does
    ],
)
def test_travel_times_past_a_floats_range_are_refused_in_one_line(tmp_path, capsys, base, other, what):
    a = _sweep(tmp_path / "a", [_record(i, True, False, t) for i, t in enumerate(base)])
    b = _sweep(tmp_path / "b", [_record(i, True, False, t) for i, t in enumerate(other)])
    assert main(["compare", f"a={a}", f"b={b}", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"crowdmpc compare: error: {what} is past a float's range: episode ")
    assert "which no episode runs (a damaged record)" in err and len(err.splitlines()) == 1
