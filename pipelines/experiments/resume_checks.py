"""What a resumed sweep must match in the records it extends: the predictor weights and the margins each cell
plans with now, against those its records state (pipelines.experiments.sweep checks both before any episode
runs, so a table never silently mixes two predictors or two margin sets).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pipelines.errors import PipelineError
from pipelines.experiments.log import EPISODES_FILE
from pipelines.experiments.tasks import Cell, EpisodeTask
from pipelines.plain_json import plain


def check_same_predictors(out: Path, tasks: list[EpisodeTask], done: dict[str, dict[str, Any]]) -> None:
    """Refuse to extend a cell whose records came from other weights than the zoo holds now (a retrained
    model): its table would silently mix two predictors."""
    from predictors.registry import checkpoint_sha256

    current: dict[str | None, str | None] = {}  # predictor name (None in a record without one) -> sha256
    for task in tasks:
        record = done.get(task.key)
        if record is None:
            continue
        name = record.get("predictor")
        if name not in current:
            current[name] = checkpoint_sha256(name)
        if record.get("predictor_sha256") != current[name]:
            raise PipelineError(
                f"{out / EPISODES_FILE} holds episodes of {task.cell.key} run with predictor {name!r} of "
                f"sha256 {record.get('predictor_sha256')}, but the zoo's {name!r} is now {current[name]}; "
                "use another --out for the new weights"
            )


def check_same_margins(out: Path, tasks: list[EpisodeTask], done: dict[str, dict[str, Any]]) -> None:
    """Refuse to extend a cell whose records planned with other margins than the cell resolves now (a
    recalibration under the same alpha and source keeps the cell key): its table would silently mix two
    margin sets. Records without margins (baselines, records from before the config was kept) say nothing."""
    current: dict[str, dict[str, Any]] = {}  # cell key -> its margins now
    for task in tasks:
        stored = _stored_margins(done.get(task.key))
        if stored is None:
            continue
        key = task.cell.key
        if key not in current:
            current[key] = planned_margins(task.cell)
        if stored != current[key]:
            was, now = stored["margins_m"], current[key]["margins_m"]
            raise PipelineError(
                f"{out / EPISODES_FILE} holds episodes of {key} planned with margins {was} m, but the cell's "
                f"margins are now {now} m{' (per motion class)' if was == now else ''}: they changed since "
                "the records were made (recalibrated?); use another --out for the new margins"
            )


def planned_margins(cell: Cell) -> dict[str, Any]:
    """The margins ``cell``'s MPC plans with now, as its records state them (MPCController.describe's
    "margins": the same for every human, and per motion class), in their JSON form."""
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.registry import checkpoint_sha256

    spec = cell.spec
    name, sha256 = spec.predictor_name, checkpoint_sha256(spec.predictor_name)
    horizon = mpc_config(spec, world=cell.world.env_config().world()).horizon
    classes = spec.margins.resolve_classes(name, horizon, sha256)
    planned = {
        "margins_m": list(spec.margins.resolve(name, horizon, sha256)),
        "classes": None if classes is None else classes.to_json(),
    }
    return json.loads(json.dumps(plain(planned)))  # as read back from a record


def resume_fields(record: dict[str, Any]) -> dict[str, Any]:
    """What the checks above read of a record: its predictor, the predictor's sha256 and the margins its
    config states. A sweep holds every finished record while it plans the rest; a whole parsed record (~14 KB
    of Python objects, its effective config half of it) held 1.7 GB at 100,000 episodes before the first new
    one ran; these fields, 0.26 GB."""
    kept: dict[str, Any] = {}
    for name in ("predictor", "predictor_sha256"):
        if name in record:
            kept[name] = record[name]
    config = record.get("config")
    if isinstance(config, dict) and "margins" in config:  # else _stored_margins finds none: says nothing
        kept["config"] = {"margins": config["margins"]}
    return kept


def _stored_margins(record: dict[str, Any] | None) -> dict[str, Any] | None:
    """What ``record`` says its episode planned with, in ``planned_margins``' form; None: it says nothing."""
    config = record.get("config") if record is not None else None
    margins = config.get("margins") if isinstance(config, dict) else None
    if not isinstance(margins, dict) or "margins_m" not in margins:  # a controller that plans with none
        return None
    return {"margins_m": margins.get("margins_m"), "classes": margins.get("classes")}
