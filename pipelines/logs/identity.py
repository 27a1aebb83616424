"""What identifies a run's recordings: the episode metadata's controller, predictor and crowd, and every
setting of its "config" metadata but those of speed only (``run_identity``). A recording is replaced only by a
rerun of its own run (``check_replaceable``; its file name is the episode's, scenario and seed, the same for
every run), and ``crowdmpc review DIR`` aggregates per run."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final

from mcap.reader import make_reader

from pipelines.errors import PipelineError, RecordingRefused
from pipelines.logs.reader import Recording, decode_metadata, read_metadata
from pipelines.logs.recorder import UNFINISHED_SUFFIX

# What tells two runs' recordings of one (scenario, seed) apart (its file name is the same for both), and
# two set-ups in `crowdmpc review DIR`: these values of the "episode" metadata, then every setting of the
# "config" metadata (``run_identity``): the simulator's ("env.formation") and the controller's ("mpc.horizon",
# "margins.mode", "coupling", "flocking"...).
RUN_IDENTITY: Final[tuple[str, ...]] = ("controller", "predictor", "n_robots", "n_humans")
# Settings added after recordings were made, with the value that recordings made before them ran with; and
# the sensor's, which a run without one does not record (pipelines.loop.sensing adds them): null, every human
# seen. Left out, a --sensor-range run silently replaced the full observation's recordings in their folder.
UNRECORDED_DEFAULTS: Final[Mapping[str, Any]] = {
    "env.formation": "auto",
    "env.robot_spacing": None,
    "env.crowd": "orca",
    "sensing.radius_m": None,
    "sensing.report_tracks": None,
    "mpc.flock_distance": "uniform",  # the paper's one d_flock, which every run before the option ran
    "mpc.flock_range": 0.0,  # every pair flocks (the paper), as every run before the option did
    "mpc.dmpc_conflicts": False,  # no conflict pair moves (the paper), as every run before the option
}
# Settings that change how fast a run goes, not its episodes (jit compiles the same NLP; DMPC's threads give
# the serial result, tests/mpc): a rerun with another value replaces its recordings, as the same command's.
SPEED_ONLY: Final[tuple[str, ...]] = ("mpc.jit", "mpc.dmpc_parallel")
# Where the calibration block the margins came from is stored (the shipped zoo or the user's), for a reader:
# its "created" and "data_sha256" beside it tell the block, and recordings made before it was kept lack it.
NOT_SETTINGS: Final[tuple[str, ...]] = ("margins.calibration.zoo",)
MAX_DIFFERENCES_NAMED: Final = 8  # in the refusal; the rest counted
MISSING: Final = "(not set)"  # a setting the held recording has and this run has not


def dotted_settings(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested settings as dotted keys: {"env": {"formation": "row"}} -> {"env.formation": "row"}."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping) and value:
            out.update(dotted_settings(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def run_identity(episode: Mapping[str, str], config: Mapping[str, Any]) -> dict[str, Any]:
    """What defines a run's episodes besides scenario and seed: the ``RUN_IDENTITY`` values of its "episode"
    metadata (strings; those it lacks left out) and its "config" metadata (decoded, as
    ``pipelines.logs.reader.decode_metadata`` reads it) flattened to dotted keys, where a setting a recording
    predates takes its ``UNRECORDED_DEFAULTS`` value; and the predictor's weights (``predictor_sha256``,
    where it has weights): a zoo name replaced by other weights (``zoo add --replace``) named two predictors,
    whose runs `review` pooled and whose recordings replaced each other."""
    identity: dict[str, Any] = {k: episode[k] for k in RUN_IDENTITY if k in episode}
    if episode.get("predictor_sha256"):  # "" for a predictor without weights, absent in the oldest
        identity["predictor_sha256"] = episode["predictor_sha256"]
    flat = dotted_settings(config)
    for key, value in UNRECORDED_DEFAULTS.items():
        if key.partition(".")[0] in config or not key.startswith("mpc."):  # ORCA's records have no [mpc]
            flat.setdefault(key, value)
    left_out = {*identity, *SPEED_ONLY, *NOT_SETTINGS}
    return identity | {k: v for k, v in flat.items() if k not in left_out}


def differing_settings(a: Recording, b: Recording) -> list[tuple[str, Any, Any]]:
    """(setting, A's value, B's value) of each ``run_identity`` value beyond controller and predictor that
    both recordings name and that differs: what ``crowdmpc review A --compare B`` shows of two runs of one
    scene, whose file names are the same (``--set mpc.w_coll=1e6`` beside the demo). A setting only one of
    them has (an MPC weight beside ORCA) is told by the controller, not by a row of "not set"."""
    ia, ib = (run_identity(rec.episode(), rec.config()) for rec in (a, b))
    own_rows: tuple[str, ...] = ("controller", "predictor")
    if ia.get("predictor") != ib.get("predictor"):  # two predictors: their weights differ as they do
        own_rows += ("predictor_sha256",)
    return [(k, ia[k], ib[k]) for k in ia if k in ib and k not in own_rows and ia[k] != ib[k]]


def shown(value: Any) -> str:
    """A setting's value in a message: text as it is ("-" when empty), anything else as JSON."""
    if isinstance(value, str):
        return value or "-"
    return json.dumps(value, sort_keys=True)


def check_replaceable(path: Path, identity: Mapping[str, Any]) -> None:
    """Refuse to replace ``path`` when it holds another run's episode (another ``run_identity``: controller,
    predictor, crowd, simulator or controller settings): rerunning a command into its folder replaces its own
    recordings (``make demo``), but a second controller, or a run with another formation, recorded into the
    same folder silently replaced the first's. A setting the held recording does not name (recorded before
    it existed, and not in ``UNRECORDED_DEFAULTS``) tells nothing apart. The metadata are read as ``crowdmpc
    review`` reads them, so that a cut file (a killed run's ``.part``, a copy that stopped) still names its
    run. A ``.part`` that is no recording (a killed run's, cut inside its header) is left to the recorder,
    which takes it over; at the episode's own name, where only a finished recording is renamed to, anything
    else is the user's (a file of theirs named so was replaced without a word), refused, and so are a
    symbolic link and a folder there (a folder was found only after the episode had run)."""
    if path.is_symlink():
        raise RecordingRefused(f"cannot record to {path}: it is a symbolic link; remove it")
    if not path.is_file():
        if path.exists():
            raise RecordingRefused(
                f"cannot record to {path}: a folder (or another thing than a file) has that name; remove it, "
                "or record into another folder"
            )
        return
    records = _held_metadata(path)
    if records is None or "episode" not in records:  # not an MCAP file, or cut inside its header
        if path.name.endswith(UNFINISHED_SUFFIX):
            return
        raise RecordingRefused(
            f"cannot record to {path}: it holds no crowdmpc recording (a file of your own?); remove it, or "
            "record into another folder"
        )
    held = run_identity(records["episode"], decode_metadata(records.get("config", {})))
    differ = [k for k in held if held[k] != identity.get(k, MISSING)]
    if differ:
        named = differ[:MAX_DIFFERENCES_NAMED]
        more = f", and {len(differ) - len(named)} more" if len(differ) > len(named) else ""
        was = ", ".join(f"{k} {shown(held[k])}" for k in named)
        now = ", ".join(f"{k} {shown(identity.get(k, MISSING))}" for k in named)
        raise RecordingRefused(
            f"cannot record to {path}: it holds another run's episode ({was}{more}; this run: {now}); record "
            "into another folder, or remove it"
        )


def _held_metadata(path: Path) -> dict[str, dict[str, str]] | None:
    """The metadata records of ``path`` from its summary, read without the data (a complete file, the common
    case: a walk reads every byte of it), else as ``crowdmpc review`` reads a cut file (``read_metadata``);
    None for a file that is no recording."""
    try:
        with open(path, "rb") as f:
            records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
        if "episode" in records:
            return records
    except Exception:  # noqa: BLE001 (a cut or damaged file: mcap raises many kinds) - walked below
        pass
    try:
        return read_metadata(path)
    except PipelineError:
        return None


def null_none(value: str | None) -> str | None:
    return None if value in (None, "", "null") else value


def recorded_plugins(value: str | None) -> dict[str, Any] | None:
    """The recorded plugins' code (JSON in the metadata), None where absent or not a JSON object."""
    try:
        plugins = json.loads(value) if value else None
    except (ValueError, RecursionError):  # a hand-edited file (nested past json's stack too): no code named
        return None
    return plugins if isinstance(plugins, dict) else None
