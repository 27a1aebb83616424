"""Real pedestrians replayed: a recorded crowd (BIWI ETH or Hotel) as the simulator's humans, beside ORCA's.

ORCA's humans are the paper's crowd, and a learned predictor trained on real people meets there a motion it
never saw: a crowd that walks straight at its preferred speed and yields to everyone at once. A replayed
crowd is the other test: the humans are real tracks, played back exactly, at their own speeds, in groups,
stopping and turning as they did. They do not react to the robots (nobody in the recording saw one), so a
robot that cuts in front of a person is not avoided; the metrics say how close it came. The reactive
replays (``REACTIVE``: "eth_reactive", ..., "hotel_test_reactive") play the same episodes with people who
yield to the robots as ORCA's humans do (crowdsim.reaction).

A ``Recording`` is a sequence's tracks on its time grid, NaN where a pedestrian is not tracked. An episode
(``replay_episode``) takes a window of it as long as the episode may last, moved and turned so that the
robots' usual task (``crowdsim.formations.robot_layout``: from y = -5 m to y = +5 m around x = 0) crosses the
recording's centre (the median tracked position) and meets its main flow (the principal axis of the
pedestrians' steps): across it in the "perpendicular" scenario, along it (head-on with half the people,
behind the others) in "circle". Of the pedestrians tracked in the window's first ``SELECT_S`` seconds, the
``n_humans`` whose tracks come closest to the robots' corridor then are the crowd; the others are left out
(they do not react to anyone, so nobody's motion depends on them). People cross BIWI's views in
seconds: ``n_humans`` counts the people who come by, not those there at once (10 people: 2-4 at a time
on average over the first 20 s, docs/replayed_crowds.md). The seed draws the window among those that
hold that many pedestrians and no pedestrian within ``2 radius + START_CLEARANCE`` of a robot's start at
the first step.

A pedestrian is present from the first row of the window where the recording tracks it to the last; before,
it stands at its first tracked position, after at its last, with zero velocity (``ReplayEpisode.present``
says which rows are real). Velocities are the recorded steps, ``(p_k - p_{k-1}) / dt``, zero at the row it
appears. The window starts ``past`` rows early (``history_len - 1``): the people walking at the first step
have their real past in the observed history, as a tracker would have it, not a standstill. The simulator
hands the mask and the track lengths to its caller (``Observation.human_present``, ``human_observed``); the
metrics count only present humans, and the closed loop shows a controller only those
(``pipelines.loop.sensing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Final

import numpy as np

from crowdsim.errors import SimulationError, counted, real_number, whole_number
from crowdsim.formations import Formation, check_robot_spacing, robot_layout
from crowdsim.world import RECORDED_DT, finite_positive

# The BIWI EWAP sequences seq_eth and seq_hotel, whole or their last 20 % of frames alone: the TrajNet++ test
# split, which no shipped net was trained or validated on (pipelines.loop.replay_data)
REPLAYED: Final[tuple[str, ...]] = ("eth", "hotel", "eth_test", "hotel_test")
# The same recordings with people who yield to the robots (crowdsim.reaction), "eth_test_reactive" etc.
REACTIVE_SUFFIX: Final[str] = "_reactive"
REACTIVE: Final[tuple[str, ...]] = tuple(name + REACTIVE_SUFFIX for name in REPLAYED)
CROWDS: Final[tuple[str, ...]] = ("orca", *REPLAYED, *REACTIVE)  # EnvConfig.crowd
START_CLEARANCE: Final[float] = 0.2  # m beyond 2 radius between a robot's start and a present pedestrian
# s of the window in which an episode's people are chosen: twice the 10 s a robot at 1 m/s takes across,
# so that they are about while the robots cross (an episode of the paper's 40 s limit ends in 14-21 s)
SELECT_S: Final[float] = 20.0
WINDOW_TRIES: Final[int] = 200  # windows drawn before an episode is declared impossible
# Grid rows times pedestrians a recording may hold (positions: 16 bytes each, 800 MB): BIWI's ETH is about
# 2,000 x 360; two frames a billion ids apart on a step of 1 filled a grid of a billion rows
MAX_GRID_CELLS: Final[int] = 50_000_000
MAX_KEY: Final[float] = 1e15  # frame and pedestrian ids: whole in float64, far below int64's end


@dataclass(frozen=True)
class Recording:
    """A sequence's tracks: ``positions[k, j]`` is pedestrian ``j`` at ``frames[k]`` (NaN: not tracked)."""

    name: str
    frames: np.ndarray  # (F,) int, sorted: the frame ids of the grid's rows
    frame_step: int  # frame ids between consecutive annotated steps (ETH 6, Hotel 10)
    positions: np.ndarray  # (F, P, 2) m, NaN where a pedestrian is not tracked
    dt: float = RECORDED_DT

    @classmethod
    def from_rows(cls, name: str, rows: np.ndarray, frame_step: int, dt: float = RECORDED_DT) -> Recording:
        """From ``rows (R, 4)`` of frame, pedestrian, x, y (``predictors.data.ewap.read_obsmat``'s). A frame
        of the grid that no row names is a row with nobody tracked (BIWI lists only frames with someone in
        view); frames off the grid (ETH's ids shift by 3 part way) start a grid of their own, and no window
        spans two (``window_starts``)."""
        rows = np.asarray(rows, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != 4 or len(rows) == 0 or not np.isfinite(rows).all():
            raise SimulationError(f"recording {name!r}: rows must be a finite (R, 4) array with R >= 1")
        # numpy's integers too (np.diff(frames).min() is one), as every setting takes them
        frame_step = whole_number(f"recording {name!r}: frame_step", frame_step, "an int >= 1", 1)
        # "0.4" was read as 0.4 and "abc" raised numpy's ValueError naming nothing
        dt = real_number(f"recording {name!r}: dt", dt, "a finite number of seconds > 0", finite_positive)
        if (np.abs(rows[:, :2]) > MAX_KEY).any():  # 1e300 wrapped to an arbitrary int64 frame
            raise SimulationError(
                f"recording {name!r}: frame and pedestrian ids must be within +-{MAX_KEY:.0e}"
            )
        _check_keys(name, rows[:, :2])
        distinct = np.unique(rows[:, 0].astype(np.int64))
        people, person_of = np.unique(rows[:, 1].astype(np.int64), return_inverse=True)
        gaps = np.diff(distinct)
        size = 1 + int(np.where(gaps % frame_step == 0, gaps // frame_step, 1).sum())  # _grid's rows
        if size * len(people) > MAX_GRID_CELLS:
            raise SimulationError(
                f"recording {name!r}: frames {distinct[0]}..{distinct[-1]} on a step of {frame_step} make "
                f"{size} rows for {counted(len(people), 'pedestrian')}, more than the {MAX_GRID_CELLS} cells "
                "a recording may hold (frames far apart on one grid)"
            )
        frames = _grid(distinct, frame_step)
        positions = np.full((len(frames), len(people), 2), np.nan)
        positions[np.searchsorted(frames, rows[:, 0].astype(np.int64)), person_of] = rows[:, 2:4]
        return cls(name, frames, frame_step, positions, dt)

    def window_starts(self, steps: int) -> np.ndarray:
        """Rows ``k`` whose next ``steps`` rows follow each other on the frame grid (one grid, no jump)."""
        if len(self.frames) <= steps:
            return np.zeros(0, dtype=int)
        # jumps off the grid counted up to each row: the span alone let two jumps that add up to whole steps
        # (ids shifted by 3 frames and back, 6 -> 9 -> 18) pass for consecutive rows
        jumps = np.concatenate([[0], np.cumsum(np.diff(self.frames) != self.frame_step)])
        return np.flatnonzero(jumps[steps:] == jumps[: len(jumps) - steps])

    def flow(self) -> tuple[np.ndarray, np.ndarray]:
        """The crowd's centre and main direction (``_flow``), computed once: a whole sequence's take 15 ms,
        and every episode's reset turns the recording by them."""
        return self._flow

    def turned(self, scenario: str) -> np.ndarray:
        """``positions`` moved to the centre and turned so that the main flow runs along x ("perpendicular":
        across the robots' path) or y ("circle": along it); kept per scenario (a whole sequence's take 20 ms,
        an episode's reset needs one)."""
        kept = self.__dict__.setdefault("_turned", {})  # frozen: the cache is no field
        if scenario not in kept:
            centre, direction = self.flow()
            target = math.pi / 2 if scenario == "circle" else 0.0
            angle = target - math.atan2(direction[1], direction[0])
            c, s = math.cos(angle), math.sin(angle)
            kept[scenario] = _read_only((self.positions - centre) @ np.array([[c, -s], [s, c]]).T)
        return kept[scenario]

    def extent(self) -> tuple[float, float]:
        """``(distance, speed)``: the farthest any tracked position lies from the crowd's centre (m; every
        episode's replayed positions lie within it, ``turned`` only moves and turns them) and the fastest
        recorded step on the frame grid (m/s; the largest replayed velocity), bounds for an observation
        space (crowdsim.gym_observation)."""
        return self._extent

    @cached_property
    def _extent(self) -> tuple[float, float]:
        centre, _ = self.flow()
        offsets = np.linalg.norm(self.positions - centre, axis=-1)
        # steps between rows on one grid only: no window spans a jump (window_starts), nor does a velocity
        on_grid = np.diff(self.frames) == self.frame_step
        steps = np.linalg.norm(np.diff(self.positions, axis=0), axis=-1)[on_grid]
        fastest = np.nanmax(steps, initial=0.0) / self.dt
        return float(np.nanmax(offsets)), float(fastest)

    @cached_property
    def _flow(self) -> tuple[np.ndarray, np.ndarray]:
        """The crowd's centre (median tracked position) and main direction (unit principal axis of its
        pedestrians' steps, turned to point along +x, or +y when it is the y axis: an eigenvector's sign is
        the solver's)."""
        tracked = self.positions[np.isfinite(self.positions[..., 0])]
        steps = np.diff(self.positions, axis=0).reshape(-1, 2)
        steps = steps[np.isfinite(steps).all(axis=1)]
        if len(tracked) == 0 or len(steps) == 0:
            raise SimulationError(f"recording {self.name!r} has no pedestrian tracked on two steps")
        _, vectors = np.linalg.eigh(steps.T @ steps)
        direction = vectors[:, -1]
        if direction[0] < 0 or (direction[0] == 0 and direction[1] < 0):
            direction = -direction
        return _read_only(np.median(tracked, axis=0)), _read_only(direction)


@dataclass(frozen=True)
class ReplayEpisode:
    """One episode's robots and replayed humans, in the simulator's frame (module docstring)."""

    robot_starts: np.ndarray  # (M, 2) m
    robot_goals: np.ndarray  # (M, 2) m
    # Rows past + k are the episode's step k; the first ``past`` rows are the observed history before it.
    positions: np.ndarray  # (past+T+1, N, 2) m, held at the first / last tracked position outside the track
    velocities: np.ndarray  # (past+T+1, N, 2) m/s, the recorded steps; zero where absent and where it appears
    present: np.ndarray  # (past+T+1, N) bool, tracked at that row
    observed: np.ndarray  # (past+T+1, N) int, tracked rows in a row up to this one (0 where absent)
    goals: np.ndarray  # (N, 2) m, each pedestrian's last tracked position in the window
    past: int  # rows before the episode's first step
    start_row: int  # the recording's row of the episode's first step
    people: np.ndarray  # (N,) int, the pedestrians' columns in the recording


def replay_episode(
    recording: Recording,
    scenario: str,
    n_humans: int,
    n_robots: int,
    steps: int,
    rng: np.random.Generator,
    *,
    radius: float,
    past: int = 0,
    formation: Formation = "auto",
    spacing: float | None = None,
    crowd: str | None = None,
) -> ReplayEpisode:
    """A window of ``steps + 1`` rows of ``recording``, after ``past`` rows of history, with ``n_humans``
    pedestrians near the robots' path (module docstring); SimulationError when ``WINDOW_TRIES`` draws find
    none. ``crowd``, the crowd the user chose ("hotel_reactive"), is named in that error beside the recording.
    """
    named = f"recording {recording.name!r}"
    if crowd is not None and crowd != recording.name:
        named = f"crowd {crowd!r} (recording {recording.name!r})"
    robot_starts, robot_goals = robot_layout(n_robots, formation, spacing=spacing)
    # as make_layout's ORCA crowds: at radius 0.55 m a replay's row of robots, 1 m apart, ran in contact
    check_robot_spacing(robot_starts, radius, formation, n_robots)
    turned = recording.turned(scenario)
    starts = recording.window_starts(past + steps)
    if len(starts) == 0:
        # "shorten [env] time_limit" was the advice where the history alone left no room for a step
        fits = len(recording.window_starts(past + 1)) > 0
        advice = (
            "shorten [env] time_limit" if fits else "shorten [world] obs_len: the history alone does not fit"
        )
        raise SimulationError(
            f"{named} has no {past + steps + 1} consecutive steps (an episode of "
            f"{steps * recording.dt:g} s after {past} of observed history): {advice}"
        )
    corridor = np.concatenate([robot_starts, robot_goals]) if n_robots else np.zeros((1, 2))
    low, high = corridor.min(axis=0), corridor.max(axis=0)
    chosen_rows = min(steps, round(SELECT_S / recording.dt)) + 1
    most = blocked = 0
    for _ in range(WINDOW_TRIES):
        first = int(starts[rng.integers(len(starts))]) + past
        window = turned[first : first + chosen_rows]
        tracked = np.isfinite(window[..., 0])
        candidates = np.flatnonzero(tracked.any(axis=0))
        most = max(most, len(candidates))
        if len(candidates) < n_humans:
            continue
        # distance of each tracked position to the box the robots' starts and goals span
        gap = np.linalg.norm(np.maximum(np.maximum(low - window, window - high), 0.0), axis=-1)
        closest = np.where(tracked, gap, np.inf)[:, candidates].min(axis=0)
        people = np.sort(candidates[np.argsort(closest, kind="stable")[:n_humans]])
        if _clear_start(window[0, people], robot_starts, radius):
            rows = turned[first - past : first + steps + 1, people]
            return _episode(rows, robot_starts, robot_goals, past, first, people, recording.dt)
        blocked += 1
    # which of the two conditions failed, first: "the most found: 50" after "has 50 pedestrians" read as
    # a contradiction where every draw with 50 had someone on a robot's start
    why = f"the most in one window: {most}"
    if blocked:
        clear = 2.0 * radius + START_CLEARANCE
        draws = counted(blocked, "draw")
        why = f"{draws} with enough had someone within {clear:g} m of a robot's start; {why}"
    raise SimulationError(
        f"{named}: no window in {WINDOW_TRIES} draws has {counted(n_humans, 'pedestrian')} in "
        f"its first {(chosen_rows - 1) * recording.dt:g} s and the robots' starts clear ({why}); use fewer "
        "humans"
    )


def recorded(crowd: str) -> str | None:
    """The recording ``crowd`` (one of ``CROWDS``) plays back, e.g. "eth_test" for "eth_test_reactive";
    None for ORCA's crowd."""
    if crowd not in CROWDS:
        raise SimulationError(f"crowd must be one of {list(CROWDS)}, got {crowd!r}")
    if crowd == "orca":
        return None
    return crowd.removesuffix(REACTIVE_SUFFIX)


def track_lengths(present: np.ndarray) -> np.ndarray:
    """``(F, P)`` int: the rows in a row each person of ``present (F, P)`` has been tracked up to each row,
    0 where not (a track that ends and starts again counts afresh)."""
    lengths = np.zeros(present.shape, dtype=np.int64)
    lengths[0] = present[0]
    for k in range(1, len(present)):
        lengths[k] = np.where(present[k], lengths[k - 1] + 1, 0)
    return lengths


def _check_keys(name: str, keys: np.ndarray) -> None:
    """SimulationError for ``(frame, pedestrian)`` columns that are not whole numbers, or name one person
    twice at one frame: the grid truncated 7.5 to 7 (two people's tracks merged into one) and kept the last
    of two rows of a person at a frame. ``read_obsmat`` refuses both naming the file's line; this is for
    every other caller (the TrajNet++ scene builder's ``_check_tracks`` says the same of its tracks)."""
    bad = np.flatnonzero((keys != np.round(keys)).any(axis=1))
    if bad.size:
        raise SimulationError(
            f"recording {name!r}: frame and pedestrian ids in rows must be integers: rows[{bad[0]}] has "
            f"frame {float(keys[bad[0], 0])!r}, pedestrian {float(keys[bad[0], 1])!r} ({bad.size} of "
            f"{counted(len(keys), 'row')})"
        )
    whole = keys.astype(np.int64)
    _, first, inverse = np.unique(whole, axis=0, return_index=True, return_inverse=True)
    first_of_key = first[inverse.ravel()]  # (R,) the first row with each row's (frame, pedestrian)
    repeats = np.flatnonzero(first_of_key != np.arange(len(whole)))
    if repeats.size:
        row = repeats[0]
        frame, person = whole[row].tolist()
        held = counted(repeats.size, "duplicate (frame, pedestrian) row")
        raise SimulationError(
            f"recording {name!r}: rows hold {held}; the first is rows[{row}]: frame {frame}, pedestrian "
            f"{person}, already at rows[{first_of_key[row]}]"
        )


def _read_only(values: np.ndarray) -> np.ndarray:
    """``values``, which a ``Recording`` keeps for every later episode, locked against in place changes: a
    caller's ``turned("circle") -= ...`` had moved every episode drawn after it."""
    values.flags.writeable = False
    return values


def _grid(frames: np.ndarray, step: int) -> np.ndarray:
    """``frames`` (sorted, distinct) with the frames of their grid that are missing between two of them: a
    gap that is a whole number of steps is filled, one that is not (another grid) is left."""
    filled = [frames[:1]]
    for before, after in zip(frames[:-1], frames[1:], strict=True):
        if (after - before) % step == 0:
            filled.append(np.arange(before + step, after + 1, step))
        else:
            filled.append(np.array([after]))
    return np.concatenate(filled)


def _clear_start(first_row: np.ndarray, robot_starts: np.ndarray, radius: float) -> bool:
    """No pedestrian tracked at the first row within ``2 radius + START_CLEARANCE`` of a robot's start."""
    if len(robot_starts) == 0 or len(first_row) == 0:
        return True
    distance = np.linalg.norm(first_row[:, None] - robot_starts[None], axis=-1)
    return bool(np.all(np.isnan(distance) | (distance >= 2.0 * radius + START_CLEARANCE)))


def _episode(
    window: np.ndarray,
    robot_starts: np.ndarray,
    robot_goals: np.ndarray,
    past: int,
    first: int,
    people: np.ndarray,
    dt: float,
) -> ReplayEpisode:
    """The chosen pedestrians' rows held outside their tracks (and through a gap in one: the last row seen),
    their velocities, presence and track lengths."""
    present = np.isfinite(window[..., 0])
    observed = track_lengths(present)
    rows = np.arange(len(window))[:, None]
    first_row = present.argmax(axis=0)
    # (T+1, N): the tracked row each row shows, the last one seen at or before it, else the first. Clipped
    # to the track alone, a person unseen for rows inside it stood at NaN, which no recording may hold.
    seen = np.maximum.accumulate(np.where(present, rows, -1), axis=0)
    held = np.where(seen >= 0, seen, first_row)
    positions = window[held, np.arange(window.shape[1])]
    velocities = np.zeros_like(positions)
    moving = present[1:] & present[:-1]
    velocities[1:] = np.where(moving[..., None], (positions[1:] - positions[:-1]) / dt, 0.0)
    return ReplayEpisode(
        robot_starts=robot_starts,
        robot_goals=robot_goals,
        positions=positions,
        velocities=velocities,
        present=present,
        observed=observed,
        goals=positions[-1].copy(),
        past=past,
        start_row=first,
        people=people,
    )
