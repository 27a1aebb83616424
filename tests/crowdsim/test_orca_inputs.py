"""What orca_velocities, a public function, takes: finite states within crowdsim.world.MOST_COORDINATE, the
largest of which keep its arithmetic finite, and a time step of at least crowdsim.world.MIN_DT; beyond, one
ValueError naming the array or the step."""

import warnings
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest

from crowdsim.orca import OrcaParams, orca_velocities
from crowdsim.world import MIN_DT, MOST_COORDINATE

STILL = np.zeros((2, 2))
APART = np.array([[0.0, 0.0], [1.0, 0.0]])  # two agents 1 m apart, in contact with 0.5 m radii


@pytest.mark.parametrize(
    "positions, velocities, pref, message",
    [
        (np.array([[0.0, 0.0], [1e200, 1.0]]), STILL, STILL, "positions component must be finite and within "
         "±1e+09 m, got 1e+200"),
        (APART, np.array([[-1e200, 0.0], [0.0, 0.0]]), STILL, "velocities component must be finite and "
         "within ±1e+09 m/s, got -1e+200"),
        (np.array([[0.0, 0.0], [np.nan, 1.0]]), STILL, STILL, "positions component must be finite and within "
         "±1e+09 m, got nan"),
        (APART, STILL, np.array([[np.inf, 0.0], [0.0, 0.0]]), "pref_velocities component must be finite and "
         "within ±1e+09 m/s, got inf"),
    ],
)  # fmt: skip
def test_absurd_states_are_refused_in_one_line_naming_the_array(positions, velocities, pref, message):
    """Positions and velocities near 1e200 overflowed ORCA's squares: RuntimeWarnings, inf and NaN out."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as exc:
            orca_velocities(positions, velocities, pref, 0.5, 1.0, OrcaParams(), 0.4)
    assert str(exc.value) == f"orca_velocities: every {message}"


@pytest.mark.parametrize("dt", [1e-6, 0.4, 86_400.0])
def test_the_largest_states_accepted_give_finite_velocities(dt):
    """Agents at the bound, heading at one another at the bound, two of them overlapping, with the least
    time horizon and every agent a neighbour: no warning, finite velocities within the max speed."""
    most = MOST_COORDINATE
    positions = np.array([[most, most], [most - 0.1, most], [-most, -most]])
    velocities = np.array([[-most, -most], [most, most], [most, -most]])
    pref = np.array([[most, -most], [-most, most], [most, most]])
    params = OrcaParams(neighbor_dist=float("inf"), time_horizon=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new, _ = orca_velocities(positions, velocities, pref, 10.0, 100.0, params, dt)
    assert np.isfinite(new).all() and (np.linalg.norm(new, axis=1) <= 100.0 * (1 + 1e-9)).all()


@pytest.mark.parametrize(
    "dt, shown", [(1e-300, "1e-300"), (0.0, "0.0"), (-0.4, "-0.4"), (float("nan"), "nan")]
)
def test_a_step_shorter_than_the_least_is_refused(dt, shown):
    """1 / dt of two overlapping agents overflowed at 1e-300 (a RuntimeWarning, and two agents who preferred
    to stand went at 1 m/s); a NaN step gave zero velocities without a word. EnvConfig's least dt is
    ORCA's too."""
    positions, velocities = np.array([[0.0, 0.0], [0.1, 0.0]]), np.array([[1.0, 0.0], [0.0, 0.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as exc:
            orca_velocities(positions, velocities, STILL, 0.3, 1.0, OrcaParams(), dt)
        assert str(exc.value) == f"orca_velocities: dt must be at least 1e-06 s, got {shown}"
        new, _ = orca_velocities(positions, velocities, STILL, 0.3, 1.0, OrcaParams(), MIN_DT)
    assert np.isfinite(new).all()


@pytest.mark.parametrize(
    "radii, speeds, message",
    [
        (1e300, 1.0, "radii component must be finite and within ±1e+09 m, got 1e+300"),
        (1.0000001e9, 1.0, "radii component must be finite and within ±1e+09 m, got 1000000100.0"),
        (np.array([0.3, np.nan]), 1.0, "radii component must be finite and within ±1e+09 m, got nan"),
        (
            0.3,
            np.array([1.0, -np.inf]),
            "max_speeds component must be finite and within ±1e+09 m/s, got -inf",
        ),
    ],
)
def test_absurd_radii_and_speeds_are_refused_in_one_line(radii, speeds, message):
    """A radius of 1e300 overflowed the combined radius' square (a RuntimeWarning); EnvConfig caps it at
    10 m, the public function took any."""
    moving = np.array([[1.0, 0.0], [0.0, 0.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as exc:
            orca_velocities(APART * 0.1, moving, STILL, radii, speeds, OrcaParams(), 0.4)
    assert str(exc.value) == f"orca_velocities: every {message}"


@pytest.mark.parametrize(
    "radii, max_speeds, dt, name",
    [
        (0.5, 1.0, True, "dt"),
        (True, 1.0, 0.4, "radii"),
        (np.array([True, True]), 1.0, 0.4, "radii"),
        (0.5, np.True_, 0.4, "max_speeds"),
        # numpy turns a list's bools into numbers: [True, 0.3] was a 1 m and a 0.3 m disc
        ([True, 0.3], 1.0, 0.4, "radii"),
        (0.5, (1.0, np.True_), 0.4, "max_speeds"),
        (np.array([0.3, True], dtype=object), 1.0, 0.4, "radii"),
    ],
)
def test_a_bool_is_refused_as_a_step_a_radius_or_a_speed(radii, max_speeds, dt, name):
    """Python takes True for 1: dt=True ran a 1 s step and a radius of True a 1 m disc without a word."""
    with pytest.raises(ValueError) as exc:
        orca_velocities(APART, STILL, STILL, radii, max_speeds, OrcaParams(), dt)
    given = {"radii": radii, "max_speeds": max_speeds, "dt": dt}[name]
    assert str(exc.value) == f"orca_velocities: {name} must be a number, not a bool, got {given!r}"


def test_lists_of_numbers_are_still_taken_as_radii_and_speeds():
    new, _ = orca_velocities(APART, STILL, STILL, [0.3, 0.3], (1.0, 1), OrcaParams(), 0.4)
    assert new.tolist() == [[0.0, 0.0], [0.0, 0.0]]


@pytest.mark.parametrize("dt", [Decimal("0.4"), "0.4", None, 0.4j])
def test_a_step_that_is_no_real_number_is_refused_naming_dt(dt):
    """A Decimal step ended in numpy's "unsupported operand type(s) for /: 'float' and 'decimal.Decimal'",
    a text one in "'>=' not supported between instances of 'str' and 'float'"."""
    with pytest.raises(ValueError) as exc:
        orca_velocities(APART, STILL, STILL, 0.5, 1.0, OrcaParams(), dt)
    assert str(exc.value) == f"orca_velocities: dt must be a real number of seconds, got {dt!r}"


@pytest.mark.parametrize("dt", [Fraction(2, 5), np.float32(0.4), 1])
def test_a_step_of_any_real_type_is_taken_as_its_float(dt):
    """A Fraction ended in numpy's "loop of ufunc does not support argument 0 of type float"; EnvConfig takes
    one as its float, and so does ORCA now."""
    new, _ = orca_velocities(APART * 0.1, STILL, STILL, 0.3, 1.0, OrcaParams(), dt)
    expected, _ = orca_velocities(APART * 0.1, STILL, STILL, 0.3, 1.0, OrcaParams(), float(dt))
    assert new.tolist() == expected.tolist() and np.abs(new).max() > 0  # overlapping: dt is used
