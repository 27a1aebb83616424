"""The refusal to extend a cell whose margins changed names what changed: per-class modes plan with their
classes' margins alone and record [] as their common ones, so the refusal had read "planned with margins
[] m, but the cell's margins are now [] m (per motion class)"."""

from pipelines.experiments.resume_checks import _margins_change

NAMES = ["new", "standing", "slow", "walking"]


def _planned(margins_m, quantiles=None):
    classes = None if quantiles is None else {"names": NAMES, "quantiles": quantiles, "standing_speed": 0.1}
    return {"margins_m": margins_m, "classes": classes}


def test_common_margins_are_shown_as_recorded():
    assert _margins_change(_planned([0.18, 0.36]), _planned([0.36, 0.72])) == (
        "margins [0.18, 0.36] m, but the cell's margins are now [0.36, 0.72] m"
    )


def test_per_class_margins_name_the_first_class_that_changed_and_count_the_others():
    was = [[0.04, 0.11], [0.0, 0.0], [0.13584, 0.32], [0.0923061107, 0.23]]
    now = [[0.04, 0.11], [0.0, 0.0], [0.2, 0.4], [0.1, 0.3]]
    assert _margins_change(_planned([], was), _planned([], now)) == (
        "margins per motion class, slow [0.136, 0.320] m, but the cell's are now [0.200, 0.400] m "
        "(and 1 more class)"
    )
    assert _margins_change(_planned([], was), _planned([], [*was[:3], now[3]])).endswith("[0.100, 0.300] m")


def test_classes_that_changed_otherwise_are_said_so():
    quantiles = [[0.1], [0.0], [0.2], [0.3]]
    assert _margins_change(_planned([], quantiles), _planned([], None)) == (
        "margins per motion class, where the cell now plans with none"
    )
    assert _margins_change(_planned([], None), _planned([], quantiles)).startswith("no margins per motion")
    changed = _planned([], quantiles)
    changed["classes"]["standing_speed"] = 0.2
    assert _margins_change(_planned([], quantiles), changed) == "other motion classes than the cell's now"
