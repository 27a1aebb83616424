"""Motion classes and class-conditional (Mondrian) conformal margins, against numbers worked by hand."""

import json

import numpy as np
import pytest

from predictors.calibration_store import read_calibration_file, save_calibration
from predictors.conformal_classes import (
    ClassMargins,
    class_coverage,
    class_margins,
    motion_classes,
)
from predictors.errors import PredictorError
from tests.calibration_blocks import class_errors, constant_velocity_block


def test_motion_classes_by_hand():
    """L = 3 positions, tau = 0.5 s: net speed = |x_t - x_{t-2}| / 1 s."""
    history = np.zeros((3, 4, 2))
    history[:, 1, 0] = [0.0, 0.02, 0.05]  # 0.05 m/s: standing
    history[:, 2, 0] = [0.0, 0.3, 0.5]  # 0.5 m/s: slow
    history[:, 3, 1] = [0.0, -0.6, -1.2]  # 1.2 m/s: walking
    assert motion_classes(history, 3, 0.5).tolist() == [1, 1, 2, 3]
    assert motion_classes(history, 2, 0.5).tolist() == [0, 0, 0, 0]  # the window is not full yet
    assert motion_classes(history, np.array([3, 2, 3, 3]), 0.5).tolist() == [1, 0, 2, 3]
    with pytest.raises(PredictorError, match="history must have shape"):
        motion_classes(np.zeros((1, 2, 2)), 1, 0.5)


def test_motion_class_edges_and_the_window_length_by_hand():
    """The edges belong to the faster class: exactly 0.1 m/s is slow, exactly 0.6 m/s walks. The speed is over
    the L - 1 intervals between L positions: L = 3 at tau = 0.5 s is 1 s, so 0.1 m and 0.6 m are those very
    speeds (over L tau = 1.5 s they would read 0.067 and 0.4 m/s: standing and slow). L = 5 at tau = 0.25 s:
    0.5 m in 1 s is slow, 0.6 m walks."""
    history = np.zeros((3, 2, 2))
    history[-1, 0, 0], history[-1, 1, 0] = 0.1, 0.6
    assert motion_classes(history, 3, 0.5).tolist() == [2, 3]
    history = np.zeros((5, 2, 2))
    history[-1, 0, 0], history[-1, 1, 0] = 0.5, 0.6
    assert motion_classes(history, 5, 0.25).tolist() == [2, 3]


def test_per_human_margins_are_the_first_steps_of_each_humans_class():
    """Class c's margin at step k is c + k/10 m (k = 1..3); humans of classes walking, new, standing over a
    2-step horizon: the (H, N) table of the MPC's human_margins."""
    rows = tuple(tuple(c + k / 10 for k in (1, 2, 3)) for c in range(4))
    margins = ClassMargins(n=((10, 10, 10),) * 4, quantiles=rows)
    np.testing.assert_allclose(margins.per_human(np.array([3, 0, 1]), 2), [[3.1, 0.1, 1.1], [3.2, 0.2, 1.2]])
    assert margins.per_human(np.array([2]), 3).tolist() == [[2.1], [2.2], [2.3]]
    with pytest.raises(PredictorError, match="class margins cover 3 steps, the MPC's horizon is 4"):
        margins.per_human(np.array([2]), 4)


def test_class_quantiles_by_hand():
    errors, classes = class_errors(2)
    margins = class_margins(errors, classes, 0.1)
    # rank ceil(20 * 0.9) = 18 of 19: 0.18 * (c + 1) * k
    for c in range(4):
        assert margins.quantiles[c] == pytest.approx((0.18 * (c + 1), 0.36 * (c + 1)))
        assert margins.n[c] == (19, 19)
    per_human = margins.per_human(np.array([3, 0, 1]), 2)
    np.testing.assert_allclose(per_human, [[0.72, 0.18, 0.36], [1.44, 0.36, 0.72]])
    cover = class_coverage(errors, classes, margins)
    assert all(c == pytest.approx((18 / 19, 18 / 19)) for c in cover)
    # A class with too few samples for alpha gets no guaranteed margin: no class margins at all.
    assert class_margins(errors[classes != 2], classes[classes != 2], 0.1) is None
    with pytest.raises(PredictorError, match="classes must index"):
        class_margins(errors, classes + 1, 0.1)
    with pytest.raises(PredictorError, match="one per error row"):
        class_margins(errors, classes[:-1], 0.1)


def test_class_margins_travel_in_the_calibration_block(tmp_path):
    errors, classes = class_errors(2)
    block = constant_velocity_block(errors, classes=classes, shortfall=errors / 2)
    assert block.shortfall.quantiles[3] == pytest.approx((0.36, 0.72))  # half of class 3's 0.72, 1.44
    save_calibration(block, tmp_path)
    (again,) = read_calibration_file(tmp_path / "calibrations.json")
    assert again == block and again.classes is not None
    # Blocks made before class margins existed still read, with none.
    document = json.loads((tmp_path / "calibrations.json").read_text())
    del document["calibrations"][0]["classes"]
    del document["calibrations"][0]["shortfall"]
    (tmp_path / "calibrations.json").write_text(json.dumps(document))
    old = read_calibration_file(tmp_path / "calibrations.json")[0]
    assert old.classes is None and old.shortfall is None


def test_class_margins_refuse_what_they_cannot_mean():
    good = ClassMargins(n=((1,),) * 4, quantiles=((0.1,),) * 4).to_json()
    with pytest.raises(PredictorError, match="speed edges"):
        ClassMargins.from_json(good | {"walking_speed": 0.8})
    with pytest.raises(PredictorError, match="must name the classes"):
        ClassMargins.from_json(good | {"names": ["a", "b", "c", "d"]})
    with pytest.raises(PredictorError, match="one row per class"):
        ClassMargins(n=((1,),) * 3, quantiles=((0.1,),) * 3)
    with pytest.raises(PredictorError, match="finite metres"):
        ClassMargins(n=((1,),) * 4, quantiles=((0.1,), (0.1,), (-1.0,), (0.1,)))
    with pytest.raises(PredictorError, match="horizon is 3"):
        ClassMargins(n=((1,),) * 4, quantiles=((0.1,),) * 4).per_human(np.zeros(2, int), 3)
