"""``crowdmpc zoo calibrations``: the conformal calibration blocks in force, one line each.

A run plans with the block of its predictor, source and alpha made behind its own sensor (or with every
human in view), and a user block hides the shipped block of its key (``predictors.calibration_store``): the
list shows which blocks there are, which zoo each comes from, the margins they give, and whether the
weights they were made for are the ones the zoo holds now (a block of other weights is refused when a run
plans with it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipelines.errors import PipelineError
from pipelines.whole_files import save_figure

if TYPE_CHECKING:
    from predictors.calibration import Calibration

HEADER = [
    "predictor",
    "source",
    "alpha",
    "view",
    "margins (m), k = 1..H",
    "samples",
    "per class",
    "weights",
    "controller",
    "crowd (humans, profile, robots)",
    "episodes (seeds)",
    "made",
]


def blocks_of(user_dir: Path | None, predictor: str | None = None) -> list[tuple[str, Calibration]]:
    """``(zoo, block)`` for every block in force (of ``predictor`` alone where given), user zoo first."""
    from predictors.calibration_store import blocks_in_force, zoo_calibration_files

    files = zoo_calibration_files(user_dir)
    zoo_of = {path: zoo for zoo, path in files}
    found = blocks_in_force([path for _, path in files])
    return [(zoo_of[path], block) for path, block in found if predictor in (None, block.predictor)]


def calibration_table(user_dir: Path | None, predictor: str | None = None) -> list[list[str]]:
    """The header and a row per block of ``blocks_of``, each row ending with the zoo it comes from."""
    return table_rows(blocks_of(user_dir, predictor), user_dir)


def table_rows(found: list[tuple[str, Calibration]], user_dir: Path | None) -> list[list[str]]:
    """The header and a row per ``(zoo, block)`` of ``found``."""
    return [[*HEADER, "zoo"], *([*_row(block, user_dir), zoo] for zoo, block in found)]


def _row(block: Calibration, user_dir: Path | None) -> list[str]:
    from predictors.calibration_store import made_with
    from predictors.conformal import alpha_text

    made = made_with(block)  # the settings the crowd and episodes columns read

    view = "recorded" if block.source == "real" else _view(block)
    per_class = [name for name, table in (("motion", block.classes), ("shortfall", block.shortfall)) if table]
    return [
        block.predictor,
        block.source,
        alpha_text(block.alpha),
        view,
        " / ".join(f"{q:.2f}" for q in block.quantiles),
        str(min(block.n)),
        ", ".join(per_class) or "-",
        _weights(block, user_dir),
        str(block.details.get("controller", "-")) if block.source == "closed-loop" else "-",
        _crowd(made),
        _episodes(block, made),
        block.created[:16].replace("T", " "),
    ]


def _crowd(made: dict[str, str]) -> str:
    """The closed-loop crowds a block was made among: "5..9, paper, visible" (its crowd sizes, the humans'
    profile, whether they saw the robots), "-" where not recorded; a run among others gets a note
    (pipelines.commands.calibration_notes), and the list said nothing of them. ``made``: the block's
    ``made_with``."""
    if not made.get("humans"):
        return "-"
    texts = made["humans"].split(",")
    sizes = [int(h) for h in texts if h.strip().isdigit()]
    run = len(sizes) == len(texts) > 2 and sizes == list(range(sizes[0], sizes[-1] + 1))
    humans = f"{sizes[0]}..{sizes[-1]}" if run else made["humans"]  # a hand-edited block's as it stands
    return ", ".join([humans, *(made[key] for key in ("profile", "visibility") if key in made)])


def _episodes(block: Calibration, made: dict[str, str]) -> str:
    """The closed-loop episodes a block was made on: "200 (1000000..1000199)", "-" where not recorded (a
    real block's scenes were recorded): blocks of one alpha made on other episodes give other margins.
    ``made``: the block's ``made_with``."""
    if "episodes" not in made:
        return "-"
    seeds = block.details.get("seeds")
    if not isinstance(seeds, list) and "seed" in made:  # a block made before its seed range was recorded
        seeds = [int(made["seed"]), int(made["seed"]) + int(made["episodes"]) - 1]
    if not isinstance(seeds, list) or not seeds:
        return made["episodes"]
    span = f"{seeds[0]}" if seeds[0] == seeds[-1] else f"{seeds[0]}..{seeds[-1]}"  # not "1 (7..7)"
    return f"{made['episodes']} ({span})"


def _view(block: Calibration) -> str:
    """How a closed-loop block's robots saw the humans: "every human", "3 m sensor", "3 m untracked"."""
    made = block.sensor_range
    if made is None:
        return "every human"
    return f"{made:g} m sensor" if block.sensor_tracks else f"{made:g} m untracked"


def _weights(block: Calibration, user_dir: Path | None) -> str:
    """Whether ``block`` was made for the weights its predictor has now: "ok", "other" (a run refuses it:
    recalibrate), "no model" (no predictor of that name) or "?" (the zoo's manifest does not read)."""
    from predictors import zoo
    from predictors.errors import PredictorError
    from predictors.registry import PREDICTORS

    if block.predictor in PREDICTORS:
        current = None  # weightless: constant velocity, the ORCA oracle
    else:
        try:
            located = zoo.locate(block.predictor, user_dir)
        except PredictorError:
            return "?"
        if located is None:
            return "no model"
        current = located.entry.sha256
    return "ok" if block.predictor_sha256 == current else "other"


def format_table(rows: list[list[str]]) -> str:
    """``rows`` (the header first) as aligned columns under a rule."""
    from predictors.text_table import aligned_lines

    return "\n".join(aligned_lines(rows[0], rows[1:], numbers_right=False))


def plot_margins(blocks: list[Calibration], title: str) -> Any:
    """A figure of ``blocks``' margins against the horizon step, a panel per source (closed-loop, real), a
    colour per alpha and a line style per view of the humans. A ``matplotlib.figure.Figure``, not
    pyplot's: a notebook's backend and open figures stay as they were."""
    from matplotlib.figure import Figure

    from crowdsim.world import DT
    from predictors.conformal import alpha_text

    sources = [s for s in ("closed-loop", "real") if any(b.source == s for b in blocks)]
    alphas = sorted({b.alpha for b in blocks})
    ranges = sorted({b.sensor_range for b in blocks if b.sensor_range is not None})
    fig = Figure(figsize=(5.0 * len(sources), 3.8), layout="constrained")
    axes = fig.subplots(1, len(sources), squeeze=False, sharey=True)[0]
    for ax, source in zip(axes, sources, strict=True):
        ours = sorted(
            (b for b in blocks if b.source == source), key=lambda b: (b.alpha, b.sensor_range or 0.0)
        )
        for block in ours:
            steps = range(1, block.horizon + 1)
            made = block.sensor_range
            view = "" if made is None else f", {_view(block)}"
            ax.plot(
                steps,
                block.quantiles,
                marker="o",
                color=f"C{alphas.index(block.alpha) % 10}",
                linestyle=_DASHES[(0 if made is None else 1 + ranges.index(made)) % len(_DASHES)],
                label=f"alpha {alpha_text(block.alpha)}{view}",
            )
        horizon = max(b.horizon for b in blocks if b.source == source)
        ax.set_xticks(range(1, horizon + 1))
        ax.set_xlabel(f"horizon step k (x {DT:g} s)")
        ax.set_title({"closed-loop": "closed-loop episodes", "real": "recorded scenes (real)"}[source])
        ax.grid(alpha=0.3)
        ax.legend(fontsize="x-small")
    axes[0].set_ylabel("margin m_k (m)")
    fig.suptitle(title, fontsize="medium")
    return fig


_DASHES = ("-", "--", ":", "-.")  # every human in view, then each sensor range, shortest first


def run_calibrations(user_dir: Path | None, predictor: str | None, plot: Path | None = None) -> int:
    from predictors.calibration_store import zoo_calibration_files

    if plot is not None:
        from crowdsim.plotting import check_figure_path
        from pipelines.commands import check_writable

        if predictor is None:
            raise PipelineError("--plot draws one predictor's blocks: add --predictor NAME")
        check_figure_path(plot, "--plot")  # savefig chose a format of its own for a name without a suffix
        check_writable(plot, "--plot", room=0)
    found = blocks_of(user_dir, predictor)  # read once: the table and the plot
    if not found:
        where = " or ".join(str(path) for _, path in zoo_calibration_files(user_dir))
        if predictor is None:
            print(f"no calibrations in {where}")
            return 0
        from predictors import zoo
        from predictors.errors import UnknownPredictor
        from predictors.registry import PREDICTORS

        names = sorted({*PREDICTORS, *(located.entry.name for located in zoo.zoo_entries(user_dir))})
        if predictor not in names:  # a typo, rather than a model never calibrated
            raise UnknownPredictor(predictor, names)
        how = (
            f"make them with crowdmpc calibrate --predictor {predictor} --source closed-loop|real --alpha 0.1"
        )
        if plot is not None:  # the file asked for is not written: not a success
            raise PipelineError(f"--plot {plot}: no calibrations of {predictor!r} to draw in {where}; {how}")
        print(f"no calibrations of {predictor!r} in {where}; {how}")
        return 0
    rows = table_rows(found, user_dir)
    print(format_table(rows))
    if plot is not None:
        blocks = [block for _, block in found]
        figure = plot_margins(blocks, f"Conformal margins of {predictor} (crowdmpc zoo calibrations)")
        plot.parent.mkdir(parents=True, exist_ok=True)
        save_figure(plot, lambda name: figure.savefig(name, dpi=120))
        print(f"wrote {plot}")
    print(
        "margins: the (1 - alpha) quantile of the displacement error at horizon steps 1..H, those of "
        "--margins conformal:ALPHA[:SOURCE]; per class: the block also holds those of conformal-motion and "
        "conformal-shortfall; weights other: made for other weights, refused until recalibrated; controller, "
        "crowd, episodes (seeds): the closed-loop episodes the block was made on (crowd sizes, the humans' "
        "profile, robots visible to them or not)"
    )
    orphans = sorted({row[0] for row in rows[1:] if row[7] == "no model"})
    if orphans:  # what `zoo remove` left: not in force for any run, kept on purpose
        print(
            f"weights no model: blocks of {', '.join(orphans)}, which no zoo holds (`zoo remove` keeps "
            "them: a zoo add of the same weights plans with them again, and sweeps planned with them "
            "resume); `crowdmpc zoo remove --calibrations NAME` removes them"
        )
    return 0
