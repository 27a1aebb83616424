"""``crowdmpc simulate``'s printed summary: the header line naming the run and the metrics table; and its
--plot with its title."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from crowdsim.metrics import COLLISION_DISTANCE
from crowdsim.reaction import reacts
from crowdsim.world import RADIUS
from pipelines.whole_files import save_figure
from predictors.text_table import counted

# The statuses of control steps that the MPC's wall-time budget (mpc.time_limit_s) cut short: the IBR loop
# stopped at it ("timeout", mpc/cmpc.py, dmpc.py, coupled.py) or a solve ran past it (IPOPT's status, which
# mpc/solvers.py gives a Fatrop solve too).
BUDGET_STATUSES: Final[tuple[str, ...]] = ("timeout", "Maximum_WallTime_Exceeded")
# The status of a control step whose prediction held NaN or inf (it falls back unless an iteration before
# the NaN had solved: format_table).
NAN_PREDICTION: Final[str] = "nan_prediction"

if TYPE_CHECKING:
    from pathlib import Path

    from crowdsim.env_config import EnvConfig
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.episode import EpisodeResult


def table_header(
    cfg: RunConfig,
    spec: ControllerSpec,
    run_meta: dict[str, Any],
    finished: int | None = None,
    stopped: str = "interrupted",
    episode_config: Mapping[str, Any] | None = None,
) -> str:
    """The line above the table: controller, predictor, margins, conventions, task and the seeds run;
    ``finished``: the episodes that ended before the run was ``stopped`` (None: it was not);
    ``episode_config``: the first episode's effective config (``EpisodeConfigs``), whose record of the
    calibration the margins came from is said beside them (a user's block and a shipped one share the
    label)."""
    from pipelines.loop.margins import calibration_text

    scenario, sim, env_config = cfg.scenario, cfg.simulate, cfg.env
    # The paper's task needs no mention; goals as slots is another task and must show in every summary.
    goals = "" if env_config.goal_assignment == "fixed" else f"goals {env_config.goal_assignment} | "
    goals += "" if env_config.formation == "auto" else f"formation {env_config.formation} | "
    spacing = env_config.robot_spacing
    goals += "" if spacing is None else f"robot spacing {spacing:g} m | "
    reactive = reacts(env_config.crowd)
    if env_config.crowd != "orca":
        goals += f"crowd {env_config.crowd} ({'replayed, yielding' if reactive else 'replayed'}) | "
    # a controller behind a sensor saw fewer humans than the metrics count: a result of another set-up
    if sim.sensor_range is not None:
        goals += f"sensor {sim.sensor_range:g} m{'' if sim.sensor_tracks else ' without tracks'} | "
    # a plain replayed crowd sees no robot: the visibility does nothing there
    seeing = env_config.crowd == "orca" or reactive
    conventions = run_meta["profile"] + (f"/{run_meta['visibility']}" if seeing else "")
    # beside the paper's method (Algorithms 1 and 2 with flocking) another method: it must show
    method = "" if spec.coupling == "ibr" else f"coupling {spec.coupling} | "
    method += "" if spec.flocking or spec.predictor_name is None else "no flocking | "
    calibration = (episode_config or {}).get("margins", {}).get("calibration")
    made = "" if calibration is None else f" ({calibration_text(calibration)})"
    return (
        f"controller {spec.controller} | predictor {spec.predictor_name or '-'} | {method}"
        f"margins {spec.margins.label}{made} | {conventions} | {goals}scenario {scenario.name} | "
        f"humans {scenario.humans} | robots {scenario.robots} | episodes {sim.episodes} | seeds {sim.seed}.."
        f"{sim.seed + sim.episodes - 1}"
        + (f" | {stopped}: {finished} episodes finished" if finished is not None else "")
    )


def _fmt(x: float | None, unit: str = "", digits: int = 2) -> str:
    # inf: no pair of agents to measure (no humans), as the JSON's null says
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}f}{unit}"


def format_table(
    summary: dict[str, Any], header: str, radius: float = RADIUS, time_limit_s: float | None = None
) -> str:
    """The printed summary; ``radius`` (m): the run's agents', whose sum is the contact threshold that the
    metrics used (crowdsim.metrics; [world] radius may differ from the default); ``time_limit_s``: the MPC's
    wall-time budget, named in a row of the steps it cut short (shown only when some were)."""
    n = summary["episodes"]

    def rate(name: str) -> str:
        if summary.get(f"{name}_rate") is None or math.isnan(summary[f"{name}_rate"]):
            return "n/a"  # an episode without the field (an older record)
        return f"{summary[f'{name}_rate']:6.1f} %  ({summary[f'{name}_count']}/{n})"

    rows = [
        ("success", rate("success")),
        (
            "travel time",
            f"{_fmt(summary['travel_time_mean'], ' s')}  (mean over successes, std "
            f"{_fmt(summary['travel_time_std'], ' s')})",
        ),  # fmt: skip
        (f"collision (<{COLLISION_DISTANCE:g} m)", rate("collision")),
        (f"contact (<{2 * radius:g} m)", rate("contact")),  # the radii touch (crowdsim.metrics)
        # the closest approach with linear motion within each step, as CrowdNav takes it (crowdsim.metrics)
        ("collision between steps", rate("collision_between_steps")),
        ("contact between steps", rate("contact_between_steps")),  # what ends a gym episode on contact
        ("discomfort", rate("discomfort")),
        # Not a metric of the paper (its metrics are all robot-human): two robots touched (crowdsim.metrics).
        (
            "robot-robot contact",
            f"{rate('robot_contact')}, {_fmt(summary.get('robot_contact_step_freq'), ' %')} of states, "
            f"between steps {' '.join(rate('robot_contact_between_steps').split())}: two robots closer than "
            f"{2 * radius:g} m (not in the paper)",
        ),
        (
            "per step",
            f"collision {_fmt(summary.get('collision_step_freq'), ' %')}, contact "
            f"{_fmt(summary.get('contact_step_freq'), ' %')}, discomfort "
            f"{_fmt(summary.get('discomfort_step_freq'), ' %')} of states",
        ),  # fmt: skip
        ("timeout", rate("timeout")),
        (
            "min distance",
            f"{_fmt(summary['min_distance_mean'], ' m')} mean, "
            f"{_fmt(summary['min_distance_min'], ' m')} min (robot-human)",
        ),  # fmt: skip
        ("path length", f"{_fmt(summary['path_length_mean'], ' m')} mean per robot"),
        (
            "solve time",
            f"median {_fmt(summary['solve_time_median_ms'], ' ms')}, "
            f"p95 {_fmt(summary['solve_time_p95_ms'], ' ms')}, "
            f"max {_fmt(summary['solve_time_max_ms'], ' ms')} per control step",
        ),  # fmt: skip
        ("IBR iterations", f"mean {_fmt(summary['iterations_mean'])}, max {summary['iterations_max']}"),
        ("fallback steps", f"{summary['fallback_steps']} of {summary['control_steps']}"),
    ]
    rows += _cut_short_rows(summary, time_limit_s)
    width = max(len(name) for name, _ in rows)
    return "\n".join([header] + [f"  {name:<{width}}  {text}" for name, text in rows])


def _cut_short_rows(summary: dict[str, Any], time_limit_s: float | None) -> list[tuple[str, str]]:
    """The rows shown only when some steps were cut short: by the MPC's wall-time budget, by solves that
    mostly failed, by a NaN prediction."""
    found: list[tuple[str, str]] = []
    # The budget is far above a step's time at Table I's horizon; a long horizon or a slow predictor reaches
    # it, and then what those steps planned depends on the machine's speed and load.
    statuses = summary.get("statuses", {})
    cut = sum(int(statuses.get(status, 0)) for status in BUDGET_STATUSES)
    if cut:
        limit = "" if time_limit_s is None else f" = {time_limit_s:g} s"
        longest = summary.get("solve_time_max_ms")
        took = "" if longest is None else f", the longest step {longest / 1e3:.3g} s"
        # IBR stops at the budget between solves and IPOPT inside one, but Fatrop cannot be stopped inside a
        # solve: at horizon 100 each ran 20 s past a 1 s budget, and the row said the steps were "cut short"
        fatrop = (
            "; a step whose solve reached it brakes (a Fatrop solve only once it has run to its end)"
            if statuses.get("Maximum_WallTime_Exceeded")
            else ""
        )
        found.append(
            (
                "wall-time budget",
                f"{cut} of {summary['control_steps']} steps reached mpc.time_limit_s{limit}{took}{fatrop}: "
                "their plans depend on this machine's speed",
            )
        )
    # A predictor returning NaN or inf (mpc/cmpc.py, dmpc.py, coupled.py) is a bug in it, not its quality:
    # it ends the step's iterations, and the metrics above read as the predictor's without this row. Not every
    # such step fell back: one whose NaN came after a solved iteration keeps that iteration's plan (its status
    # is still nan_prediction), so the row names the prediction and leaves the count of fallbacks to its row.
    # Most steps falling back is no result of the method: the robots brake or hold a stale plan, and a world
    # far from Table I's (a shorter dt, say) can leave every solve short of its iterations.
    fell, steps = int(summary.get("fallback_steps") or 0), int(summary.get("control_steps") or 0)
    if steps and fell > steps / 2:
        failed = {k: v for k, v in summary.get("statuses", {}).items() if k != "ok"}
        most = max(failed, key=lambda k: failed[k]) if failed else "failed"
        # a budget cut: more iterations cannot help (they named solver_max_iter at every wall-time stop)
        remedy = (
            "a longer mpc.time_limit_s"
            if most in BUDGET_STATUSES
            else "mpc.solver_max_iter or mpc.cost_scale"
        )
        found.append(
            (
                "mostly fallbacks",
                f"{fell} of {steps} steps fell back (most: {most}): the MPC rarely solved, so these metrics "
                f"are of its fallback; {remedy} may let it solve",
            )
        )
    nan_steps = int(summary.get("statuses", {}).get(NAN_PREDICTION, 0))
    if nan_steps:
        found.append(
            (
                "NaN predictions",
                f"{nan_steps} of {summary['control_steps']} steps stopped at a NaN or inf prediction (a step "
                "with no solved iteration before it fell back)",
            )
        )
    return found


def plot_title(controller: str, episode: EpisodeResult, env_config: EnvConfig) -> str:
    """What the --plot figure shows: who drove (with its predictor), the crowd, the seed; then how it ended
    and how close a robot came to a human, with the collision or contact the metrics counted, and two robots
    touching each other, at their closest (between steps where the record has it). The crowd is the
    simulator's (EnvConfig.crowd), named when replayed, which a title of the scenario alone hid. The title
    once named neither predictor nor crowd, called a run through a human a "success" with nothing more,
    gave "min robot-human distance inf m" for an episode without humans, and said "timeout" without when
    (pipelines.logs.ending.outcome_text, as review's titles say it)."""
    from pipelines.logs.ending import SUCCESS, TIME_LIMIT, outcome_text

    m = episode.metrics
    who = controller + (f" with {episode.predictor}" if episode.predictor else "")
    seed = "" if episode.seed is None else f", seed {episode.seed}"
    robots = counted(episode.n_robots, "robot")
    humans = counted(episode.n_humans, "human")
    replayed = "" if env_config.crowd == "orca" else f", crowd {env_config.crowd}"
    crowd = f"{episode.scenario}, {robots}, {humans}{replayed}{seed}"
    steps = len(episode.robot_positions) - 1
    # simulate's episodes end at success or at the time limit; a shorter one was stopped by its loop
    end = SUCCESS if m.success else (TIME_LIMIT if steps >= env_config.max_steps else None)
    outcome = outcome_text(end, steps * env_config.dt, env_config.time_limit, m.travel_time)
    if episode.n_humans == 0:
        closest = "no humans"
    else:
        closest = f"min robot-human distance {m.min_distance:.2f} m"
        if m.contact:
            closest += ": contact"
        elif m.collision:
            closest += f": collision (< {COLLISION_DISTANCE:g} m)"
    # two robots that touched (not a metric of the paper) read as a clean run without this
    if m.robot_contact or m.robot_contact_between_steps:
        swept = m.min_distance_robots_between_steps
        closest += f"; robots touched ({m.min_distance_robots if swept is None else swept:.2f} m apart)"
    return f"{who}, {crowd}\n{outcome}, {closest}"


def plot_first_episode(
    path: Path,
    controller: str,
    first: EpisodeResult,
    env_config: EnvConfig,
    sensor_range: float | None = None,
) -> None:
    """simulate's --plot: ``first_episode_figure`` written to ``path``."""
    fig = first_episode_figure(controller, first, env_config, sensor_range)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(path, lambda name: fig.savefig(name, dpi=120, bbox_inches="tight"))
    print(f"wrote {path}")


def first_episode_figure(
    controller: str, first: EpisodeResult, env_config: EnvConfig, sensor_range: float | None = None
) -> Any:
    """The first episode's paths, titled by ``plot_title``, with each robot's sensor range at each snapshot
    behind ``--sensor-range`` (as review --plot draws it from the recording: without it the figure of a run
    behind a sensor looked like one that saw every human)."""
    from crowdsim.plotting import default_snapshots, plot_episode
    from pipelines.logs.plots import draw_sensor_ranges

    fig = plot_episode(
        first.robot_positions,
        first.human_positions,
        first.robot_goals,
        title=plot_title(controller, first, env_config),
        radius=env_config.radius,
        dt=env_config.dt,
        human_present=first.human_present,
    )
    if sensor_range is not None:
        ax = fig.axes[0]
        draw_sensor_ranges(
            ax, first.robot_positions, default_snapshots(len(first.robot_positions)), sensor_range
        )
        # plot_episode's legend was made before the circles: again, to name them
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.8)
    return fig
