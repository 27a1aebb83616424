"""The sweep's Markdown table, laid out like the paper's Tables II/III, and the paired comparison it prints.

One column per method and number of pedestrians, the four metrics as rows, the paper's figure under each of
ours, and the better method of each group in bold (as the paper prints it); past ``MAX_CELL_COLUMNS`` cells,
a row per cell and the metrics as columns. Success is also compared pairwise
on the crowds both methods ran (the same scenarios and seeds), with the exact McNemar test.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Final

from crowdsim.replay import recorded
from crowdsim.world import PAPER_ROBOTS
from pipelines.experiments import safety_report as safety
from pipelines.experiments.cells import EXPERIMENTS, Experiment
from pipelines.experiments.paired import mcnemar_exact, p_text
from pipelines.experiments.summary import CellSummary, Rate
from pipelines.experiments.tasks import SCENARIOS

# Past this many cells table.md has a row per cell and a column per metric: a column per cell (the paper's
# layout) made a 100-cell sweep's table 101 columns wide, a row of 101 texts no reader follows. Every shipped
# experiment at its own sizes keeps the paper's layout (Tables II and III: 10 cells; safety, the widest: 16).
MAX_CELL_COLUMNS: Final[int] = 16
PAPER_ROW: Final[str] = "&nbsp;&nbsp;paper"  # the paper's figure, under ours
Row = tuple[str, list[str]]  # a metric's label and its text in each cell


def paired_success(reference: CellSummary, other: CellSummary) -> tuple[int, int, float]:
    """On the crowds both cells ran: (other succeeded where the reference failed, the reverse, McNemar p)."""
    shared = reference.successes.keys() & other.successes.keys()
    gained = sum(other.successes[k] and not reference.successes[k] for k in shared)
    lost = sum(reference.successes[k] and not other.successes[k] for k in shared)
    return gained, lost, mcnemar_exact(gained, lost)


# The simulator settings that place the humans around the robots (crowdsim.scenarios), as `crowdmpc compare`
# pairs crowds by them (pipelines.experiments.compare.CROWD_SETTINGS)
PLACEMENT: Final[tuple[str, ...]] = ("crossing", "spawn_separation", "formation", "robot_spacing")
# The episodes' own medians and p95s, summarised over the cell's episodes (summary.CellSummary): not the
# statistic `simulate` and `review` print, pooled over all control steps, which records cannot give.
STEP_TIME_LABEL: Final[str] = "Control step (ms): median of the episodes' medians / p95 of their p95s"
NOT_APPLICABLE: Final[str] = "n/a"  # a figure the method has no use for; "—" is one without data


def _fmt(x: float | None, digits: int = 1) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _rate_cell(r: Rate) -> str:
    lo, hi = r.interval
    return f"{_fmt(r.percent)} [{_fmt(lo)}, {_fmt(hi)}]" if r.n else "—"


def _added_rate_cell(s: CellSummary, name: str) -> str:
    """A rate of a flag added after the first records (crowdsim.metrics.ADDED_FLAGS), as ``_rate_cell``;
    "—" when some record of the cell predates it."""
    rate = s.added_rate(name)
    return "—" if rate is None else _rate_cell(rate)


def _best(values: Sequence[float], higher_is_better: bool) -> set[int]:
    """Indices of the best value (as printed, one decimal) in a group; none when every method with a value
    ties, as the paper leaves ties unmarked, or fewer than two have one: a travel time beside a method with
    no success (NaN) was bold against nothing."""
    finite = [(i, round(v, 1)) for i, v in enumerate(values) if not math.isnan(v)]
    if len(finite) < 2:
        return set()
    best = (max if higher_is_better else min)(v for _, v in finite)
    winners = {i for i, v in finite if v == best}
    return winners if len(winners) < len(finite) else set()


def _crossings(columns: Sequence[CellSummary]) -> str:
    """The crossings of the columns' episodes, counted as recorded (``success_by_scenario``): episode i of a
    plan is ``SCENARIOS[i % 2]``, but a cell whose episodes of one crossing raised or ran past
    --episode-timeout holds the other's alone, and the note, read off the number of episodes, said "half
    circle and half perpendicular" of two circles and "the circle crossing" of one perpendicular. A plan's
    first episodes read as they always did: one episode the circle alone, an odd count not half and half."""
    first, second = SCENARIOS
    counts = {tuple(s.success_by_scenario[sc].n for sc in SCENARIOS) for s in columns}
    if all(a == b for a, b in counts):
        return f"half {first} and half {second} crossing"
    if len(counts) == 1:
        ((a, b),) = counts
        if a + b == 1:
            return f"the {first if a else second} crossing"
        return " and ".join(f"{n} {name}" for n, name in ((a, first), (b, second)) if n) + " crossings"
    if all(a - b in (0, 1) for a, b in counts):  # each cell a plan's first episodes
        return f"{first} and {second} crossings in turn, the {first} first"
    return f"{first} and {second} crossings in other numbers per column"


def _table_notes(experiment: Experiment, columns: Sequence[CellSummary], world_line: str) -> str:
    """The paragraph above the table: how many episodes, which predictors and conventions, how to read it."""
    # in the columns' order (--predictors'), each once: sorted, the words and the columns read differently
    predictors = list(dict.fromkeys(s.cell.spec.predictor_name or "none" for s in columns))
    counts = sorted({s.episodes for s in columns})
    per_cell = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    notes = [
        f"## {experiment.title}",
        "",
        f"Ours: {per_cell} episode{'' if per_cell == '1' else 's'} per cell, {_crossings(columns)}, "
        "the same seeds in every cell; "
        f"predictor{'s' if len(predictors) > 1 else ''} {', '.join(predictors)}. Rates with their 95% Wilson "
        "interval in brackets; travel time over successful episodes ± the 95% interval of its mean "
        "(Student's t). Bold: the better method at each number of pedestrians, in the paper's four rows "
        "(success, travel time, collision, discomfort). Paired: episodes (same crowd) "
        f"this method succeeded and the first one{_crowds_note(columns)} failed / the reverse, with the "
        "exact McNemar p-value."
        + (
            f" {NOT_APPLICABLE}: a solver's figure for a controller that runs none."
            if not all(s.runs_solver for s in columns)
            else ""
        ),
        world_line,
    ]
    calibrations: dict[tuple[str, str], set[str]] = {}  # (predictor, margins) -> where they came from
    for s in columns:
        key = (s.cell.spec.predictor_name or "none", s.cell.spec.margins.label)
        calibrations.setdefault(key, set()).update(s.calibrations)
    made = [f"{p} {label}: {' and '.join(sorted(t))}" for (p, label), t in sorted(calibrations.items()) if t]
    if made:  # a user's block and a shipped one share a label
        notes.append(f"Calibrated margins from: {'; '.join(made)}.")
    robots = sorted({s.cell.n_robots for s in columns})
    if robots != [PAPER_ROBOTS]:
        teams = ", ".join(map(str, robots))
        notes.append(f"Robots: {teams} per episode (the paper's tables: {PAPER_ROBOTS}).")
        if len(robots) > 1:
            notes[-1] += " Bold among the columns of one team: another team is another task."
    if any(s.paper for s in columns):
        notes.append(f"Paper ('paper' rows): 1000 episodes per cell (500 + 500), {experiment.paper_source}.")
        if _beside_other_settings(experiment, columns):
            notes[-1] += (
                " They are of the paper's settings (Table I, margins none), not of the columns above them, "
                "which ran with others (as said above)."
            )
    elif experiment.paper and robots != [PAPER_ROBOTS]:
        notes.append(
            f"The paper's figures ({experiment.paper_source}) are for {PAPER_ROBOTS} robots: not shown "
            "beside these."
        )
    elif experiment.paper:
        notes.append(f"The paper's figures ({experiment.paper_source}) have no column at these crowd sizes.")
    else:
        notes.append("The paper has no such table.")
    return "\n".join(notes)


def _beside_other_settings(experiment: Experiment, columns: Sequence[CellSummary]) -> bool:
    """Whether a column beside the paper's figures ran with other settings than the shipped experiment's
    methods (``--set mpc.d_min=0.9``, ``--margins``, ``--profile``, ``[env]``): a ``--vary`` column of another
    value gets no paper figures, but these apply to every column."""
    shipped = EXPERIMENTS.get(experiment.name)
    if shipped is None:
        return False
    own = {(spec, shipped.method_worlds.get(label, shipped.world)) for label, spec in shipped.methods}
    return any(s.paper and (s.cell.spec, s.cell.world) not in own for s in columns)


def _crowds(s: CellSummary) -> tuple[Any, ...]:
    """What decides a column's crowds beside the seed, the scenario and the number of humans
    (crowdsim.scenarios): its number of robots (a human drawn near a robot is redrawn), its profile and the
    simulator settings that place the humans (``PLACEMENT``: ``--vary env.spawn_separation=0.1,1`` paired
    columns of other crowds), and the recording a replayed crowd plays. Visibility, sensing and margins do
    not, nor the humans' ORCA or the time limit (the same people, who then move otherwise)."""
    world = s.cell.world
    env = world.env_config()
    placement = tuple(getattr(env, name) for name in PLACEMENT)
    return s.cell.n_robots, world.profile, recorded(world.crowd), placement


def _crowds_note(columns: Sequence[CellSummary]) -> str:
    """Whom a column is paired with, where the columns do not all run the same crowds (``_paired_texts``);
    nothing where they do."""
    if len({_crowds(s) for s in columns}) == 1:
        return ""
    return " on the same crowds (as many robots, the same profile and placement)"


def markdown_table(experiment: Experiment, summaries: Sequence[CellSummary]) -> str:
    """The paper's layout: a column per (number of pedestrians, method), metrics as rows, paper under ours."""
    if not summaries:
        return f"## {experiment.title}\n\nNo episodes recorded yet.\n"
    groups: dict[int, list[CellSummary]] = {}
    for s in summaries:
        groups.setdefault(s.cell.n_humans, []).append(s)
    columns = [s for n in sorted(groups) for s in groups[n]]
    rows: list[Row] = [("Numbers of pedestrians", [str(s.cell.n_humans) for s in columns])]
    world_line, worlds = safety.world_note([s.cell for s in columns])
    if worlds:
        rows.append((safety.world_row_label([s.cell for s in columns]), worlds))
    rows += _metric_rows(groups, columns)
    rows += _detail_rows(groups, columns)
    notes = _table_notes(experiment, columns, world_line)
    methods = [s.cell.method for s in columns]
    if len(columns) > MAX_CELL_COLUMNS:
        return notes + "\n" + _transposed_note(len(columns)) + "\n\n" + _transposed(methods, rows)
    lines = [_line("Metrics \\ Methods", methods), "|---|" + "---|" * len(columns)]
    return notes + "\n\n" + "\n".join(lines + [_line(label, texts) for label, texts in rows]) + "\n"


def _transposed_note(cells: int) -> str:
    return (
        f"A row per cell ({cells} cells, too many for a column each past {MAX_CELL_COLUMNS}): rows and "
        "columns are swapped, what these notes call a column is a row of the table and a row a column, the "
        "paper's figure in the column after ours."
    )


def _transposed(methods: list[str], rows: list[Row]) -> str:
    """``rows`` (a label, a text per cell) as a table of a row per cell, the labels heading its columns; the
    paper's figure is headed by its metric's label."""
    labels = [
        f"{rows[i - 1][0]}, paper" if label == PAPER_ROW else label for i, (label, _) in enumerate(rows)
    ]
    lines = [_line("Methods", labels), "|---|" + "---|" * len(labels)]
    lines += [_line(method, [texts[j] for _, texts in rows]) for j, method in enumerate(methods)]
    return "\n".join(lines) + "\n"


def _line(label: str, texts: Sequence[str]) -> str:
    return f"| {label} | " + " | ".join(texts) + " |"


def _bolded(
    groups: dict[int, list[CellSummary]],
    columns: list[CellSummary],
    texts: list[str],
    values: list[float],
    higher_is_better: bool,
) -> list[str]:
    """``texts`` (one per column), the best of each group of columns by ``values`` in bold: of a crowd size's
    columns, those of one team (``--vary scenario.robots``: another team is another task, not a rival
    method, and its crowds are others)."""
    bold: set[int] = set()
    for n in sorted(groups):
        for team in sorted({s.cell.n_robots for s in groups[n]}):
            idx = [columns.index(s) for s in groups[n] if s.cell.n_robots == team]
            bold |= {idx[j] for j in _best([values[i] for i in idx], higher_is_better)}
    return [f"**{text}**" if i in bold else text for i, text in enumerate(texts)]


def _metric_rows(groups: dict[int, list[CellSummary]], columns: list[CellSummary]) -> list[Row]:
    """The paper's four metrics: ours with their intervals, and the paper's figures under each when it has
    them, the better method of each group in bold."""
    has_paper = any(s.paper for s in columns)
    metric_rows = (
        ("Success rate (%)", "success", True),
        ("Average travel time (s)", "travel_time", False),
        ("Collision rate (%)", "collision", False),
        ("Discomfort rate (%)", "discomfort", False),
    )
    lines: list[Row] = []
    for label, name, higher in metric_rows:
        if name == "travel_time":
            values = [s.travel_time_mean for s in columns]
            texts = [
                f"{_fmt(s.travel_time_mean)} ± {_fmt(s.travel_time_ci)}"
                if s.travel_time_ci == s.travel_time_ci
                # one success has no interval: said, where the header promises one
                else _fmt(s.travel_time_mean) + (" (1 success)" if s.success.count == 1 else "")
                for s in columns
            ]
        else:
            rates: list[Rate] = [getattr(s, name) for s in columns]
            values = [r.percent for r in rates]
            texts = [_rate_cell(r) for r in rates]
        lines.append((label, _bolded(groups, columns, texts, values, higher)))
        if has_paper:
            pv = [getattr(s.paper, name) if s.paper else math.nan for s in columns]
            paper = _bolded(groups, columns, [_fmt(v) for v in pv], pv, higher)
            lines.append((PAPER_ROW, paper))
    return lines


def _paired_texts(groups: dict[int, list[CellSummary]], columns: list[CellSummary]) -> list[str]:
    """Each column's successes paired with those of the first method of its group that ran the same crowds
    (the reference; ``_crowds``): a column of another team or profile ran other crowds from the same seeds,
    and ``--vary scenario.robots`` paired "CMPC robots=6" with "CMPC robots=3", the conventions experiment
    "paper/visible/none" with "v1/visible/none", as if on the same ones."""
    paired = []
    for s in columns:
        same = [c for c in groups[s.cell.n_humans] if _crowds(c) == _crowds(s)]
        reference = same[0]
        if s is reference:
            paired.append("reference" if len(same) > 1 else "—")
        else:
            gained, lost, p = paired_success(reference, s)
            paired.append(f"+{gained} / −{lost} (p = {p_text(p)})")
    return paired


def _detail_rows(groups: dict[int, list[CellSummary]], columns: list[CellSummary]) -> list[Row]:
    """What the paper does not print: contact, robots touching each other, collisions and robot contact
    between steps, per-step collisions, closest approach, success per scenario, the paired comparison,
    and what the controller cost."""
    return [
        ("Contact rate (%) (< 0.6 m)", [_rate_cell(s.contact) for s in columns]),
        (
            "Robot-robot contact rate (%) (< 0.6 m; not in the paper)",
            [_added_rate_cell(s, "robot_contact") for s in columns],
        ),
        # straight motion within each step (crowdsim.metrics): a crossing the 0.4 s states step over
        (
            "Collision between steps (%) (not in the paper)",
            [_added_rate_cell(s, "collision_between_steps") for s in columns],
        ),
        (
            "Robot-robot contact between steps (%)",
            [_added_rate_cell(s, "robot_contact_between_steps") for s in columns],
        ),
        ("Collision per step (%)", [_fmt(s.collision_step_freq, 2) for s in columns]),
        ("Min robot-human distance, median (m)", [_fmt(s.min_distance_median, 2) for s in columns]),
        (
            "Success circle / perpendicular (%)",
            # one decimal as every rate here: without, 199 of 200 read "100", a scenario without a failure
            [" / ".join(_fmt(s.success_by_scenario[sc].percent) for sc in SCENARIOS) for s in columns],
        ),
        ("Success, paired with the group's first method", _paired_texts(groups, columns)),
        ("Episodes", [str(s.episodes) for s in columns]),
        (
            STEP_TIME_LABEL,
            [f"{_fmt(s.step_median_ms, 2)} / {_fmt(s.step_p95_ms, 2)}" for s in columns],
        ),
        ("IBR iterations per step (mean)", [_solver_fmt(s, s.iterations_mean) for s in columns]),
        ("Fallback steps (%)", [_solver_fmt(s, s.fallback_step_rate) for s in columns]),
    ]


def _solver_fmt(s: CellSummary, value: float) -> str:
    """``value`` of a solver figure; n/a for a controller that runs no solver (ORCA, straight line), whose
    0 iterations and 0 fallbacks would read as a measurement."""
    return _fmt(value, 2) if s.runs_solver or not math.isnan(value) else NOT_APPLICABLE
