"""crowdsim.control.ControlOutput: what a controller that fills in only its accelerations reports."""

import dataclasses

import numpy as np
import pytest

from crowdsim.control import ControlOutput


def test_a_bare_output_reports_a_plain_step():
    # A plugin controller may return accelerations alone: the recorders then log a step that took no solver
    # time, solved ("ok"), with no IBR iteration and no fallback; nothing else is claimed.
    out = ControlOutput(accelerations=np.zeros((2, 2)))
    assert (out.solve_time_s, out.status, out.iterations, out.fallback) == (0.0, "ok", 0, None)
    assert out.potential is None and out.plan is None and out.prediction is None
    assert out.iteration_predictions == () and out.extra == {}
    assert out.extra is not ControlOutput(accelerations=np.zeros((2, 2))).extra  # not shared between steps
    # Frozen: an observer handed the output cannot rewrite what the recorder logs.
    with pytest.raises(dataclasses.FrozenInstanceError):
        out.status = "failed"  # type: ignore[misc]
