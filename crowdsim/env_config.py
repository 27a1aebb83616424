"""The simulator's settings: ``EnvConfig`` (time step, time limit, radii, speeds and bounds, the ORCA setup
and the convention choices of a profile), checked when it is made, and the bounds it checks them against.

The simulator that runs with them (``CrowdEnv``) and what a controller sees (``Observation``) are
crowdsim.env, which offers ``EnvConfig`` too, as the settings of its ``CrowdEnv``; crowdsim.profiles names
the convention sets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from crowdsim.conventions import (
    CROSSINGS,
    PAPER_SPAWN_SEPARATION,
    PAPER_TIME_LIMIT,
    PAPER_TIMEOUT_MARGIN,
    SUCCESS_RULES,
    Crossing,
    SuccessRule,
)
from crowdsim.errors import SimulationError, got, real_number
from crowdsim.formations import FORMATIONS, Formation, check_spacing
from crowdsim.orca import OrcaParams
from crowdsim.replay import CROWDS
from crowdsim.slots import GOAL_ASSIGNMENTS, GoalAssignment
from crowdsim.world import (
    A_MAX,
    DT,
    LEAST,
    MOST_ACCEL,
    MOST_EPISODE_STEPS,
    MOST_SPEED,
    MOST_TIME,
    OBS_LEN,
    RADIUS,
    RECORDED_DT,
    V_MAX,
    V_PREF,
    WorldFacts,
    check_least,
    finite_positive,
    history_rows,
)

# Upper bounds of EnvConfig's times, lengths and speeds: far above any crowd a robot navigates, low enough
# that positions, step counts and the controllers' arithmetic stay finite (dt = 1e308 overflowed the
# straight controller's braking distance).
ENV_BOUNDS: Final[dict[str, tuple[float, str]]] = {
    "time_limit": (MOST_TIME, "s"),  # longer runs are more episodes (dt: at most time_limit)
    "radius": (10.0, "m"),  # a robot or a person, not a building
    "v_pref": (MOST_SPEED, "m/s"),
    "v_max": (MOST_SPEED, "m/s"),
    "a_max": (MOST_ACCEL, "m/s^2"),
}
MAX_SPAWN_SEPARATION: Final[float] = 100.0  # m: the scenarios are 10 m across
MAX_ORCA_RADIUS_MARGIN: Final[float] = 10.0  # m: CrowdNav adds 0.01


@dataclass(frozen=True)
class EnvConfig:
    """Simulator settings. The defaults are the "paper" profile with visible robots (``crowdsim.profiles``):
    the paper's Table I, the authors' CrowdNav fork and CrowdNav's ORCA setup."""

    dt: float = DT  # s, tau: simulation step = control period (Table I)
    time_limit: float = PAPER_TIME_LIMIT  # s, the episode's time limit
    radius: float = RADIUS  # m, every robot and human
    v_pref: float = V_PREF  # m/s, humans' preferred speed = their ORCA max speed (CrowdNav)
    v_max: float = V_MAX  # m/s, robot velocity bound per component, Eq. (6)
    a_max: float = A_MAX  # m/s^2, robot acceleration bound per component, Eq. (6)
    history_len: int = OBS_LEN  # L, rows of Observation.history: the predictors' observed length
    orca: OrcaParams = field(default_factory=OrcaParams)  # neighbour distance, max neighbours, time horizon
    orca_radius_margin: float = 0.01  # m added to the radius given to ORCA (CrowdNav's "for safety")
    profile: str = "paper"  # name of the convention set, for records; the fields below are what acts
    timeout_margin: float = PAPER_TIMEOUT_MARGIN  # s, no step starts at or after time_limit - margin
    spawn_separation: float = PAPER_SPAWN_SEPARATION  # m added to the two radii between sampled humans
    crossing: Crossing = "paper"  # the humans' start/goal sampling rules (crowdsim.crossings)
    success_rule: SuccessRule = "simultaneous"  # crowdsim.env's docstring
    robots_visible: bool = True  # the humans' ORCA sees the robots
    goal_assignment: GoalAssignment = "fixed"  # "fixed": robot i to goal i (paper); "slots": crowdsim.slots
    # the robots' starts and goals (crowdsim.formations): "auto" is the paper's row up to 3 robots, a wedge
    # from 4; "row", "wedge", "two_rows" choose one for every team size; "antipodal": robots trading places
    formation: Formation = "auto"
    # m between neighbouring robots (and their goals); None: the formation's own, 1 m in the row, d_ij in
    # the others. Wider where the MPC's d_min leaves robots no room to stand on goals 1 m apart.
    robot_spacing: float | None = None
    # who the humans are: "orca" (the paper's simulated crowd) or a replayed BIWI sequence, "eth" or "hotel",
    # or its test split alone, "eth_test" or "hotel_test" (crowdsim.replay: real tracks played back, not
    # reacting to anyone), or one yielding to the robots, "eth_test_reactive", ... (crowdsim.reaction)
    crowd: str = "orca"

    def __post_init__(self):
        self._check_sizes()
        self._check_dt()
        self._check_margins()
        if self.max_steps > MOST_EPISODE_STEPS:  # the episode's arrays and loop grow with its steps
            raise SimulationError(
                f"EnvConfig.time_limit must be at most {MOST_EPISODE_STEPS} steps of dt = {self.dt:g} s, got "
                f"{self.time_limit:g} s ({float(self.max_steps):.3g} steps)"
            )
        if not isinstance(self.orca, OrcaParams):
            raise SimulationError(f"EnvConfig.orca must be an OrcaParams, got {type(self.orca).__name__}")
        if not (isinstance(self.profile, str) and self.profile):
            raise SimulationError(f"EnvConfig.profile must be a non-empty name, got {self.profile!r}")
        separation = self._store(
            "spawn_separation",
            real_number(
                "EnvConfig.spawn_separation",
                self.spawn_separation,
                "a finite number >= 0 m",
                lambda s: math.isfinite(s) and s >= 0,
            ),
        )
        if separation > MAX_SPAWN_SEPARATION:
            raise SimulationError(
                f"EnvConfig.spawn_separation must be at most {MAX_SPAWN_SEPARATION:g} m, "
                f"got {got(separation)}"
            )
        if self.crossing not in CROSSINGS:
            raise SimulationError(
                f"EnvConfig.crossing must be one of {list(CROSSINGS)}, got {self.crossing!r}"
            )
        if self.success_rule not in SUCCESS_RULES:
            raise SimulationError(
                f"EnvConfig.success_rule must be one of {list(SUCCESS_RULES)}, got {self.success_rule!r}"
            )
        if self.goal_assignment not in GOAL_ASSIGNMENTS:
            raise SimulationError(
                f"EnvConfig.goal_assignment must be one of {list(GOAL_ASSIGNMENTS)}, "
                f"got {self.goal_assignment!r}"
            )
        if self.goal_assignment == "slots" and self.success_rule == "first_reach":
            raise SimulationError(  # the metrics would judge a reach against the goal held at the end
                "EnvConfig.goal_assignment 'slots' needs success_rule 'simultaneous' (the paper profile): "
                "under 'first_reach' a robot may reach a slot it gives up later"
            )
        if self.formation not in FORMATIONS:
            raise SimulationError(
                f"EnvConfig.formation must be one of {list(FORMATIONS)}, got {self.formation!r}"
            )
        check_spacing(self.robot_spacing, "EnvConfig.robot_spacing")
        if self.formation == "antipodal" and self.goal_assignment == "slots":
            raise SimulationError(
                "EnvConfig.formation 'antipodal' sends each robot to the point opposite its start: "
                "goal_assignment 'slots' would deal the goals anew (an even team its own starts)"
            )
        if self.formation == "antipodal" and self.robot_spacing is not None:
            raise SimulationError(
                "EnvConfig.robot_spacing does not apply to formation 'antipodal' (its robots stand on a 3.5 "
                "m circle, 7 sin(pi / M) m apart)"
            )
        if self.robot_spacing is not None:
            self._store("robot_spacing", float(self.robot_spacing))
        if self.crowd not in CROWDS:
            raise SimulationError(f"EnvConfig.crowd must be one of {list(CROWDS)}, got {self.crowd!r}")
        if self.crowd != "orca" and not math.isclose(self.dt, RECORDED_DT, rel_tol=1e-9):
            raise SimulationError(  # the tracks are played back row by row, at their own rate
                f"EnvConfig.crowd {self.crowd!r} replays steps of {RECORDED_DT:g} s, so dt must be "
                f"{RECORDED_DT:g} s, got {got(self.dt)}"  # :g said "got 0.4" of 0.4000001
            )
        if not isinstance(self.robots_visible, bool | np.bool_):
            raise SimulationError(f"EnvConfig.robots_visible must be a bool, got {self.robots_visible!r}")

    def _store(self, name: str, value: float) -> float:
        """Set a checked value (frozen: numpy's scalars are stored as Python's) and return it."""
        object.__setattr__(self, name, value)
        return value

    def _check_sizes(self) -> None:
        """The times, lengths and speeds and L: finite, positive, and within ``ENV_BOUNDS``."""
        for name in ("dt", *ENV_BOUNDS):
            where = f"EnvConfig.{name}"
            self._store(name, real_number(where, getattr(self, name), "a finite number > 0", finite_positive))
        self._store("history_len", history_rows("EnvConfig.history_len", self.history_len))
        for name, (most, unit) in ENV_BOUNDS.items():
            if getattr(self, name) > most:
                raise SimulationError(
                    f"EnvConfig.{name} must be at most {most:g} {unit}, got {got(getattr(self, name))}"
                )
        for name in LEAST:  # the world facts' least values (dt's: max_steps = time_limit / dt stays finite)
            check_least(f"EnvConfig.{name}", name, getattr(self, name))

    def _check_dt(self) -> None:
        """A step within the episode (``dt <= time_limit``); its least value is checked with the sizes."""
        if self.dt > self.time_limit:
            raise SimulationError(
                f"EnvConfig.dt must be at most time_limit = {self.time_limit:g} s, got {got(self.dt)}"
            )

    def _check_margins(self) -> None:
        """ORCA's radius margin, and the timeout margin within the time limit (checked before)."""
        most = MAX_ORCA_RADIUS_MARGIN
        margin = real_number(
            "EnvConfig.orca_radius_margin",
            self.orca_radius_margin,
            f"in [0, {most:g}] m",
            lambda m: 0 <= m <= most,
        )
        self._store("orca_radius_margin", margin)
        limit = self.time_limit
        margin = real_number(
            "EnvConfig.timeout_margin",
            self.timeout_margin,
            f"in [0, time_limit={limit}) s",
            lambda m: 0 <= m < limit,
        )
        self._store("timeout_margin", margin)

    @classmethod
    def from_world(cls, world: WorldFacts, **settings: Any) -> EnvConfig:
        """The simulator for ``world`` (tau, L, radii, speeds, bounds), with ``settings`` for the rest."""
        facts: dict[str, Any] = {"dt": world.dt, "history_len": world.obs_len, "radius": world.radius}
        facts |= {"v_pref": world.v_pref, "v_max": world.v_max, "a_max": world.a_max}
        return cls(**facts, **settings)

    def world(self) -> WorldFacts:
        """The world facts this simulator runs with (what the MPC and the predictors must agree with)."""
        return WorldFacts(self.dt, self.history_len, self.radius, self.v_pref, self.v_max, self.a_max)

    @property
    def max_steps(self) -> int:
        """Steps before the timeout: those starting at ``t = k dt < time_limit - timeout_margin`` and ending
        by ``time_limit``.

        The fork checks ``global_time >= time_limit - 1`` before each step, so with 40 s and 0.4 s steps start
        at t = 0, 0.4, ..., 38.8 and t = 39.2 is a timeout: 98 steps. With no margin (v1) it is
        ``time_limit / dt``: 75 steps of 0.4 s in 30 s. The 1e-9 absorbs rounding such as 30 / 0.4 =
        75.00000000000001. A step may start before ``time_limit - timeout_margin`` and end after the limit
        (no margin, 10.1 s of 0.4 s steps: the 26th from 10.0 s to 10.4 s); it is not run, since a success on
        it would report a travel time past the time limit. At least 1: t = 0 is always before ``time_limit -
        timeout_margin`` (the margin is less than the limit), that step ends by the limit (``dt <=
        time_limit``), and ``CrowdEnv`` runs it whatever the count; the 1e-9 alone made it 0 for a margin
        within 1e-9 steps of the limit.
        """
        started = math.ceil((self.time_limit - self.timeout_margin) / self.dt - 1e-9)
        ended = math.floor(self.time_limit / self.dt + 1e-9)
        return max(1, min(started, ended))
