"""The world facts every package shares: time step, observed history, agent size and robot bounds.

One source, so that the simulator, the MPC and the predictors cannot drift apart. ``WorldFacts`` is the
object: ``EnvConfig.from_world`` and ``MPCConfig.from_world`` build the simulator's and the MPC's settings
from one, ``EnvConfig.world()`` reads it back, and the closed loop refuses a controller whose MPC or
predictor disagrees with the simulator it drives in (``pipelines.loop.mpc_setup.check_world``). ``WORLD``
holds the defaults, which the module constants name for the code that only needs a number. The crowd
geometry (circle radius, square width) is the same in every simulation profile (``crowdsim.profiles``) and
lives here too, and so do the two robot-robot distances that the MPC's costs and the robots' formations
(``crowdsim.scenarios``) must agree on: ``MPCConfig`` takes them as its defaults, as it takes Table I's
horizon ``HORIZON``. ``PAPER_ROBOTS`` is the paper's team size, every robot count's default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Final

from crowdsim.errors import SimulationError, got, real_number, whole_number

# The largest sizes of the simulator's work, which WorldFacts and EnvConfig refuse beyond and the CLI's config
# schema reads from here (pipelines.config.keys.MOST): 10**6 history rows took 21 s and 860 MB for three
# steps, far past any predictor's observed length (TrajNet++'s 9).
MOST_OBS_LEN: Final[int] = 1000  # L, rows of observed history
MOST_EPISODE_STEPS: Final[int] = 100_000  # EnvConfig.max_steps: time_limit / dt
# The largest |coordinate| (m) and |velocity component| (m/s) crowdsim.orca takes: a million km, far beyond
# where the simulator moves anyone (MOST_SPEED x MOST_TIME = 8.6e6 m from its scene), yet so far below
# float64's overflow that ORCA's squares of them over a microsecond's time step or horizon stay finite (1e200
# gave inf and NaN velocities).
MOST_COORDINATE: Final[float] = 1e9
# The shortest step (s) EnvConfig and crowdsim.orca take: below, (time_limit - timeout_margin) / dt may
# overflow to inf, and ORCA's 1 / dt of overlapping agents did (1e-300 overflowed, and two agents who
# preferred to stand went at 1 m/s). Here, beside MOST_COORDINATE, since crowdsim.env_config imports
# crowdsim.orca.
MIN_DT: Final[float] = 1e-6
# The least of each world fact, which WorldFacts and EnvConfig refuse below: dt's is MIN_DT, the others a
# millionth of their unit too, far below any body or motion of a crowd (the tests' least radius is 0.01 m)
# and far above float64's subnormals, which passed "> 0": with [world] radius = 5e-324 a straight-line run
# reported "contact (<9.88131e-324 m) 0.0 %" of robots that passed 0.07 m from people.
LEAST: Final[dict[str, tuple[float, str]]] = {
    "dt": (MIN_DT, "s"),
    "radius": (1e-6, "m"),
    "v_pref": (1e-6, "m/s"),
    "v_max": (1e-6, "m/s"),
    "a_max": (1e-6, "m/s^2"),
}


# The step of the recorded crowds, a fact of the data: BIWI EWAP's sequences are annotated at 2.5 fps (their
# info.txt), TrajNet++ keeps that rate in every scene it cuts, and a replayed crowd plays it back row by row.
# Here, the lowest layer, for the simulator's replays (crowdsim.replay, EnvConfig) and the predictors' data
# (predictors.data: the scene files' "fps", the raw files' plausibility checks) alike; predictors.data's
# modules would pull trajnetplusplustools into the replay path, and crowdsim imports no other package.
RECORDED_DT: Final[float] = 0.4  # s
RECORDED_FPS: Final[float] = 1 / RECORDED_DT  # 2.5, what a TrajNet++ scene's "fps" says


@dataclass(frozen=True)
class WorldFacts:
    # s, tau: simulation step = control period (Table I's 0.4 s), the recorded step, so that predictors
    # trained on TrajNet++ scenes step at the control period
    dt: float = RECORDED_DT
    # L: observed steps every zoo predictor reads. TrajNet++ observes 9 steps; the paper's Table I says 8, but
    # our models are trained on 9, so the simulator keeps 9 rows of history and feeds them exactly that.
    obs_len: int = 9
    radius: float = 0.3  # m, every robot and human (not in Table I: the authors' CrowdNav env config)
    v_pref: float = 1.0  # m/s, humans' preferred speed = their ORCA max speed (CrowdNav's env config)
    v_max: float = 1.0  # m/s, robot velocity bound per component, Eq. (6)
    a_max: float = 2.0  # m/s^2, robot acceleration bound per component, Eq. (6)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            where = f"WorldFacts.{f.name}"
            if f.name == "obs_len":
                plain: float = history_rows(where, value)
            else:
                plain = real_number(where, value, "a finite number > 0", finite_positive)
                check_least(where, f.name, plain)
            object.__setattr__(self, f.name, plain)  # frozen: stores numpy's scalars as Python's


def check_least(where: str, name: str, value: float) -> None:
    """SimulationError "``where`` must be at least ..." when world fact ``name`` is below its ``LEAST``."""
    least, unit = LEAST[name]
    if value < least:
        raise SimulationError(f"{where} must be at least {least:g} {unit}, got {got(value)}")


def history_rows(where: str, value: object) -> int:
    """L (``WorldFacts.obs_len``, ``EnvConfig.history_len``) as a plain int in ``1..MOST_OBS_LEN``."""
    rows = whole_number(where, value, f"an int in [1, {MOST_OBS_LEN}]", 1)
    if rows > MOST_OBS_LEN:
        raise SimulationError(f"{where} must be an int in [1, {MOST_OBS_LEN}], got {rows}")
    return rows


def finite_positive(value: float) -> bool:
    """A time, length or speed: finite and > 0 (nan is neither)."""
    return math.isfinite(value) and value > 0


def is_sensor_range(value: object) -> bool:
    """A sensor's range: a finite number of metres > 0 (an endless range is no sensor: leave the controller
    unwrapped), not a bool; what a controller's sensor (pipelines.loop.sensing), the gymnasium wrapper
    ``SensorRange`` and a calibration made behind a sensor accept."""
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < math.inf


# The least and greatest sensor range (m) a run may ask for. Least: the world's least length (LEAST), as
# "> 0" took 5e-324, a sensor that saw nobody, its sweep cells labelled "sensed5e-324m". Greatest: a
# kilometre, as the MPC's lengths (mpc.config.MPC_BOUNDS), far beyond any crowd (the scenes are 10 m across,
# the replayed ones tens of metres), where every human is in view: simulate --plot draws each robot's range
# as a dashed ring whose dashes grow with it, and one ring of 1e6 m took 24 s, of 1e300 m never finished.
# Checked as a run starts and by the sensor itself (pipelines.loop.sensing.RangeLimited), not by
# is_sensor_range, so a sweep folder that ran beyond them still reads back.
SENSOR_RANGE: Final[tuple[float, float]] = (LEAST["radius"][0], 1e3)


def sensor_range_beyond(value: float) -> str | None:
    """Why sensor range ``value`` (already ``is_sensor_range``) is refused as a run starts, "must be at least
    1e-06 m, got 5e-324", or None when within ``SENSOR_RANGE``."""
    least, most = SENSOR_RANGE
    if least <= value <= most:
        return None
    bound, side = (least, "least") if value < least else (most, "most")
    return f"must be at {side} {bound:g} m, got {float(value)!r}"


def sensor_range_refused(value: float) -> str | None:
    """``sensor_range_beyond`` naming what it bounds, "the sensor range must be at most 1000 m, got 2000.0":
    the one wording of simulate's, sweep's and calibrate's refusals after the option's name ("--sensor-range:
    ..."), which had calibrate say "--sensor-range must be at most ..." and simulate "--sensor-range: must be
    at most ..." where a sweep said the line above."""
    beyond = sensor_range_beyond(value)
    return None if beyond is None else f"the sensor range {beyond}"


WORLD: Final[WorldFacts] = WorldFacts()
DT: Final[float] = WORLD.dt
OBS_LEN: Final[int] = WORLD.obs_len
RADIUS: Final[float] = WORLD.radius
V_PREF: Final[float] = WORLD.v_pref
V_MAX: Final[float] = WORLD.v_max
A_MAX: Final[float] = WORLD.a_max

# Table I's H: the MPC's control and prediction horizon (MPCConfig.horizon's default) and so the number of
# steps the predictors' margins are made for by default (predictors.real_data.HORIZON). A module constant, not
# a WorldFacts field: the simulator does not use it, and the MPC may override it per run.
HORIZON: Final[int] = 4
# The paper's team of robots: Table I's weights were set for it, each robot's Eq. 15 summing 2 flocking
# terms; every robot count defaults to it (mpc.config.PAPER_ROBOTS names it too).
PAPER_ROBOTS: Final[int] = 3

# The largest time, speed and acceleration a run may ask for, far above any sensible one: the simulator
# (crowdsim.env_config.ENV_BOUNDS) and the MPC (mpc.config.MPC_BOUNDS) both refuse more, so that no setting
# overflows their arithmetic.
MOST_TIME: Final[float] = 86_400.0  # s, a day: an episode's time limit, and so any time step
MOST_SPEED: Final[float] = 100.0  # m/s, 360 km/h
MOST_ACCEL: Final[float] = 1000.0  # m/s^2, 100 g

CIRCLE_RADIUS: Final[float] = 5.0  # m, circle crossing (the paper's fork, env_m.config; CrowdNav's is 4 m)
SQUARE_WIDTH: Final[float] = 10.0  # m, side of the perpendicular-crossing square (env_m.config)

# Robot-robot distances (module constants, not WorldFacts fields: the MPC may override them per run, the
# formations do not follow). MPCConfig's d_min and d_flock default to these; crowdsim.scenarios spaces the
# robots' starts and goals with them.
D_MIN: Final[float] = 0.8  # m, d_min (Table I): the closest a robot may come to another agent, Eqs. 11-12
# m, d_ij (Eq. 15): desired distance between two robots of the flock. Not in the paper; mpc/config.py's
# docstring has why 1.2 m: the tightest spacing at which the Eq. 12 penalty no longer fights the flocking.
D_FLOCK: Final[float] = 1.2
