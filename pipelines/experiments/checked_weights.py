"""The predictor weights a sweep's workers plan with are those its driver checked.

The driver loads each zoo predictor of the plan before any worker starts (``check_plan``); the workers, other
processes (or Ray actors on other machines), load it again from the zoo as they build a cell's controller. A
`zoo add --replace` in between (a model retrained into the zoo while a sweep runs) had them run, and record,
other weights than were checked, and a table mix two predictors under one name. The driver hands each task
the sha256 of the weights it checked (``with_checked_weights``); a worker refuses a controller that loaded
others (``check_loaded_weights``) before any episode runs on them, and the driver stops the sweep at that
first refusal (``WeightsReplaced``), in one line naming the file: every later episode of the predictor met the
same refusal, each an entry of errors.jsonl, and the sweep ran on with nothing of them to record.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from pipelines.errors import PipelineError
from pipelines.experiments.tasks import EpisodeTask
from pipelines.loop.contract import checked_description
from pipelines.loop.controllers import Controller
from predictors.text_table import counted

if TYPE_CHECKING:
    from predictors.zoo import Located


class WeightsReplaced(PipelineError):
    """A worker's controller loaded other weights than the sweep's driver checked: no episode error (a rerun
    with those weights is refused, pipelines.experiments.resume_checks), but the end of the sweep."""


def zoo_located(tasks: Iterable[EpisodeTask]) -> dict[str, Located | None]:
    """The zoo entry of each predictor ``tasks`` plan with, as the zoo's manifests name it now (None: no
    entry, a predictor without weights)."""
    from predictors import zoo

    names = sorted({n for t in tasks if (n := t.cell.spec.predictor_name) is not None})
    return {name: zoo.locate(name) for name in names}


def zoo_weights(located: Mapping[str, Located | None]) -> dict[str, str]:
    """The sha256 of the weights of each entry ``zoo_located`` found: the weights a library sweep
    (``run_sweep`` without ``weights``) checks its workers against, as its resume checks its records
    against them."""
    return {name: found.entry.sha256 for name, found in located.items() if found is not None}


def with_checked_weights(tasks: list[EpisodeTask], weights: Mapping[str, str | None]) -> list[EpisodeTask]:
    """``tasks``, each holding the sha256 of its cell's predictor's weights in ``weights`` (by name; a name
    not there, or None, a predictor without weights: nothing to check)."""
    checked = []
    for task in tasks:
        name = task.cell.spec.predictor_name
        if name is not None and name in weights:
            task = dataclasses.replace(task, weights_sha256=weights[name])
        checked.append(task)
    return checked


def check_loaded_weights(task: EpisodeTask, controller: Controller) -> None:
    """WeightsReplaced, in one line naming the weights file, when ``controller`` (built for ``task``'s cell)
    loaded other weights than the driver checked (``task.weights_sha256``); a controller that states no
    weights (a baseline, a plugin's describing none) is not checked."""
    expected = task.weights_sha256
    if expected is None:
        return
    loaded = checked_description(controller).get("predictor_sha256")
    if loaded is None or loaded == expected:
        return
    name = task.cell.spec.predictor_name
    raise WeightsReplaced(
        f"predictor {name!r}: the weights {_weights_file(name)} have sha256 {loaded}, not the {expected} "
        "this sweep checked before its workers started (replaced in the zoo since, `zoo add --replace`?); "
        "no episode runs on them: sweep the new weights into another --out, or put the checked ones back "
        "and rerun to resume"
    )


def stopped_by(refusal: str, recorded: int, out: Path) -> str:
    """The line a sweep stops with at a worker's ``refusal`` (``WeightsReplaced``'s), ``recorded`` episodes
    of its plan in ``out``'s log: they are kept, and a rerun with the checked weights back runs the rest."""
    if recorded == 0:
        kept = f"no episode of it is recorded in {out} yet"
    else:
        kept = f"the {counted(recorded, 'episode')} recorded in {out} kept"
    return f"{refusal} (the sweep stopped at the first episode that loaded them, {kept})"


def _weights_file(name: str | None) -> str:
    """The weights file the zoo's ``name`` loads now (the manifest read again, on a refusal only)."""
    from predictors import zoo

    try:
        located = zoo.locate(name) if name is not None else None
    except Exception:  # a damaged manifest: the refusal names the predictor all the same
        located = None
    if located is None:
        return f"of {name!r}"
    return str(located.entry.paths(located.root, located.manifest)[0])
