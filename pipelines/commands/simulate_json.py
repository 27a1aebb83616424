"""``crowdmpc simulate --json``'s document: the run, its code, its summary and each episode's record, also
of a run stopped before its first episode finished."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from pipelines.commands import write_output
from pipelines.commands.standard_output import is_stdout, shown
from pipelines.errors import EpisodeFailed, PipelineError
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from pipelines.loop.episode import EpisodeResult


def write_json(
    path: Any,
    run_meta: dict[str, Any],
    results: list[EpisodeResult],
    configs: list[dict[str, Any]],
    interrupted: bool,
    failure: PipelineError | None,
    summary: dict[str, Any] | None = None,
) -> None:
    """--json's document into ``path`` (a file, "-" for stdout; None: no --json), also of a run stopped
    before its first episode finished (``summary`` null, no episodes): it wrote nothing, leaving an earlier
    run's file in place."""
    if path is None:
        return
    from pipelines.plugins import code_with_plugins

    payload = {
        "run": run_meta,
        "code": code_with_plugins(),
        **({"interrupted": True, "episodes_finished": len(results)} if interrupted else {}),
        **({"failed": failed_record(failure), "episodes_finished": len(results)} if failure else {}),
        "summary": summary,
        # an episode that started and did not finish (Ctrl-C, a plugin's error) has a config, no result
        "episodes": [
            r.record().to_dict() | {"config": c}
            for r, c in zip(results, configs[: len(results)], strict=True)
        ],
    }
    write_output(path, json.dumps(plain(payload), indent=1) + "\n", "--json")
    if not is_stdout(path):
        print(f"wrote {shown(path)}")


def failed_record(failure: PipelineError) -> dict[str, Any]:
    """The JSON's record of the error that stopped a run: the failing episode's seed (None: it came after
    the last episode, from the controller's close()) and the error's line."""
    return {"seed": failure.seed if isinstance(failure, EpisodeFailed) else None, "error": str(failure)}
