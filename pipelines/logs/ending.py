"""What ended a recorded episode, told from its metrics, its config and its last recorded step.

The metrics' ``timeout`` is "not success" (crowdsim.metrics; Table II's timeout rate counts it so), which
``crowdmpc simulate`` and the sweeps make the same as "the time limit ended it": their episodes end only at
success or at the time limit. A gymnasium episode may end otherwise: a robot-human contact with
``end_on_collision=True``, or a loop of its own that stops early (gymnasium's ``TimeLimit`` put around the
environment, a policy that raised and ``ObserveEpisodes`` closed). The review names that end beside the
metric, which stays as recorded.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any, Final

import numpy as np

from crowdsim.distances import min_distance_between_steps
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.outcome import CONTACT, CUT_SHORT, SUCCESS, TIME_LIMIT, outcome_text
from pipelines.errors import PipelineError
from pipelines.logs.identity import differing_settings, shown
from pipelines.logs.reader import Recording


def max_steps(rec: Recording) -> int | None:
    """The steps the recorded environment runs before its time limit; None where its config does not say
    (a file without the "config" metadata's env that no older simulate recorded, or values the simulator
    refuses)."""
    env = rec.config().get("env")
    if not isinstance(env, dict):
        return _older_simulate_steps(rec)
    fields = {k: env.get(k) for k in ("dt", "time_limit", "timeout_margin")}
    # a recorder writes JSON numbers: a bool or a text is no setting, and an integer of 400 digits
    # overflowed float() (OverflowError, a traceback where the review prints one line a file)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in fields.values()):
        return None
    try:
        return EnvConfig(**{k: float(v) for k, v in fields.items()}).max_steps  # type: ignore[arg-type]
    except (OverflowError, TypeError, ValueError, SimulationError):
        return None


def _older_simulate_steps(rec: Recording) -> int | None:
    """The time limit of a file that ``crowdmpc simulate`` recorded before the "config" metadata held the
    env (586091d, crowdmpc-episode/3): its "run" metadata names the profile, whose settings that simulate ran
    unchanged (make_env_config(profile, visibility), 6762d28 on), or, before the profiles, names none, when
    it ran EnvConfig() of then, 30 s of 0.4 s steps, the "v1" profile's. A sweep's or a script's older file
    says neither (its cell or EnvConfig could set the limit): None, not a guess."""
    from crowdsim.profiles import PROFILES

    run = rec.run_meta()
    if run.get("command") != "simulate":
        return None
    profile = run.get("profile", "v1")
    if not isinstance(profile, str) or profile not in PROFILES:
        return None
    config = PROFILES[profile]
    try:  # each of them recorded its dt: a file that says another was not run so
        recorded_dt = float(rec.episode()["dt"])
    except (KeyError, ValueError):
        return None
    return config.max_steps if recorded_dt == config.dt else None


def ended_by(rec: Recording, metrics: dict[str, Any] | None) -> str | None:
    """``SUCCESS``, ``TIME_LIMIT``, ``CONTACT`` or ``CUT_SHORT``; None where the episode did not end in the
    file or what ended it cannot be told (no time limit recorded, no states to look at)."""
    if not isinstance(metrics, dict):
        return None
    if metrics.get("success") is True:
        return SUCCESS
    steps, limit = metrics.get("n_steps"), max_steps(rec)
    # the environment stops at its limit: a file of more steps did not run the limit told
    if not isinstance(steps, int) or limit is None or steps > limit:
        return None
    if steps == limit:
        return TIME_LIMIT
    # the loops record whether a contact could end it: where none could, a loop of its own stopped it (a
    # TimeLimit around ObserveEpisodes), even on a step that touched; in a file older than that record, a
    # contact in the last step is read as what ended it
    if rec.episode().get("end_on_collision") == "false":
        return CUT_SHORT
    touched = _last_step_contact(rec)
    if touched is None:
        return None
    # an earlier contact does not end an episode; one in its last step does (end_on_collision)
    return CONTACT if touched else CUT_SHORT


def _last_step_contact(rec: Recording) -> bool | None:
    """Whether a robot touched a human during the last recorded step (straight motion within it, as the
    environment's end_on_collision takes it); None without two recorded states."""
    from pipelines.logs.view import episode_view

    try:
        view = episode_view(rec)
    except PipelineError:
        return None
    if len(view.steps) < 2:
        return None
    robots, humans = view.robot_positions[-2:], view.human_positions[-2:]
    present = ~np.isnan(humans).any(axis=-1)  # a replayed crowd's untracked people are not there
    closest = min_distance_between_steps(robots, np.nan_to_num(humans), present)
    return math.isfinite(closest) and closest < 2.0 * view.radius


ENDS: Final[tuple[str, ...]] = (SUCCESS, TIME_LIMIT, CONTACT, CUT_SHORT)
UNTOLD: Final[str] = "untold"  # ended_by null: the file does not say what ended it


def ends_count(summaries: Sequence[dict[str, Any]]) -> dict[str, int]:
    """How many of the runs each end ended (``ENDS``, then ``UNTOLD``), every end named, 0 included: the
    timeout rate beside it counts time_limit, contact, cut_short and untold alike, as not success."""
    ends = Counter(s.get("ended_by") or UNTOLD for s in summaries)
    return {end: ends[end] for end in (*ENDS, UNTOLD)}


def ends_text(counts: dict[str, int]) -> str:
    """The folder totals' line of what ended the episodes: "ended by: success 0, time limit 1, ..."."""
    shown = [f"{end.replace('_', ' ')} {n}" for end, n in counts.items() if end != UNTOLD]
    if counts.get(UNTOLD):
        shown.append(f"untold {counts[UNTOLD]} (the file does not say)")
    return "ended by: " + ", ".join(shown) + "; the timeout rate counts every end but success"


def metric_rows(summary: dict[str, Any]) -> list[tuple[str, Any]]:
    """The text review's rows of an ended episode: what ended it, then each recorded metric."""
    end = summary.get("ended_by")
    rows: list[tuple[str, Any]] = [("ended", ending_text(summary))]
    return rows + [(f"  {name}", metric_shown(name, v, end)) for name, v in summary["metrics"].items()]


def ending_text(summary: dict[str, Any]) -> str | None:
    """The text review's "ended" row: what ended the episode and when; None where unknown."""
    end = summary.get("ended_by")
    at = f"at {summary['sim_time_s']:.1f} s"
    if end == SUCCESS:
        return f"success {at}"
    if end == TIME_LIMIT:
        return f"time limit {at}"
    if end == CONTACT:
        return f"robot-human contact {at}, before the time limit"
    if end == CUT_SHORT:
        return f"stopped {at} by its loop, before the time limit (no success, no contact in its last step)"
    return None


def metric_shown(name: str, value: Any, end: str | None) -> Any:
    """A metric as the text review shows it: ``timeout`` of an episode that something else than the time limit
    ended says so beside the recorded value, which stays the metric (not success)."""
    if name == "timeout" and value is True and end in (CONTACT, CUT_SHORT):
        return "yes (the metric: not success; the time limit did not end it)"
    return value


def recording_outcome(rec: Recording) -> str | None:
    """``outcome_text`` of a recorded episode, None where the file holds no end (a killed run's)."""
    metrics_messages = rec.data("/episode/metrics")
    robots = rec.data("/robots")
    if not metrics_messages or not robots:
        return None
    metrics = metrics_messages[-1]["metrics"]
    env = rec.config().get("env")
    limit = env.get("time_limit") if isinstance(env, dict) else None
    if not isinstance(limit, (int, float)) or isinstance(limit, bool):
        limit = None
    travel = metrics.get("travel_time") if isinstance(metrics, dict) else None
    travel = float(travel) if isinstance(travel, (int, float)) and not isinstance(travel, bool) else None
    return outcome_text(ended_by(rec, metrics), float(robots[-1]["time"]), limit, travel)


def titled(rec: Recording) -> str:
    """The recording's label and, where the file holds its end, how it ended as simulate's title says it
    (review's figures once named neither: a timeout read as any run)."""
    outcome = recording_outcome(rec)
    return rec.label if outcome is None else f"{rec.label}: {outcome}"


def clock_decimals(dt: float) -> int:
    """Decimals that show every multiple of ``dt`` (s) as it is, 1 to 3: with one, a 0.25 s step's clock
    read 0.2, 0.8, 1.2 s at 0.25, 0.75, 1.25 s."""
    return next((d for d in (1, 2) if abs(round(dt, d) - dt) < 1e-9), 3)


def frame_texts(rec: Recording, times: np.ndarray, dt: float) -> Callable[[int], tuple[str, str]]:
    """An animation frame's title and clock at recorded state ``row`` of ``times`` (s), as a function of
    ``row`` (the clock to ``clock_decimals(dt)``, ``dt`` the step in s): the end only on the last frame
    ("seed 0: timeout at 5.2 s (time limit 6 s)"), before it the label, and the clock the time so far of
    the end's ("t = 1.2 s of 5.2 s"). Every frame once carried the end's title, so that a robot just setting
    off read "timeout at 5.2 s", a contact's first frame "robot-human contact at 3.2 s"; the gym's frames
    say the end only once reached too (``ended_text``)."""
    outcome = recording_outcome(rec)  # once: the file's end, read for every frame otherwise
    decimals = clock_decimals(dt)
    of = "" if outcome is None else f" of {times[-1]:.{decimals}f} s"
    truncated = "   (truncated file)" if rec.truncated else ""

    def texts(row: int) -> tuple[str, str]:
        last = row == len(times) - 1
        title = rec.label if outcome is None or not last else f"{rec.label}: {outcome}"
        return title, f"t = {times[row]:.{decimals}f} s{of}{truncated}"

    return texts


def compare_labels(a: Recording, b: Recording) -> dict[str, str]:
    """review --compare's legend entry of each run: its label, the settings in which the two differ (two runs
    of one scene with another MPC weight read the same without them) and, on a line of its own, how it ended
    as ``titled`` says it (the overlay once tagged a timeout as it tagged a success)."""
    differ = differing_settings(a, b)
    labels = {}
    for i, (tag, rec) in enumerate((("A", a), ("B", b))):
        label = " / ".join([rec.label, *(f"{key} {shown(values[i])}" for key, *values in differ)])
        outcome = recording_outcome(rec)
        labels[tag] = label if outcome is None else f"{label}\n{outcome}"
    return labels
