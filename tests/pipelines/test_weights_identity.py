"""Two sets of weights under one zoo name (``zoo add --replace``) are two predictors: their recordings were
one set-up in `review`, pooled into one aggregate, and a rerun of a seed with the new weights replaced the old
weights' recording without a word. The weights' sha256 is part of what identifies a run's recordings."""

from __future__ import annotations

import builtins
import io
import json
import os
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from crowdsim.world import OBS_LEN
from pipelines.cli import main
from pipelines.errors import PipelineError
from predictors.zoo_edit import add_to_zoo
from tests.pipelines.mcap_episode import record_episode

CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"

OLD, NEW = "86" * 32, "ee" * 32


def test_review_keeps_two_weights_of_one_name_apart(tmp_path, capsys):
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)
    record_episode(tmp_path, seed=2, steps=3, predictor_sha256=NEW)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "review.json")]) == 0
    groups = json.loads((tmp_path / "review.json").read_text())["groups"]
    assert len(groups) == 2 and all(len(g["files"]) == 1 for g in groups)
    assert sorted(g["settings"]["predictor_sha256"] for g in groups) == [OLD, NEW]


def test_a_recording_of_other_weights_is_not_replaced(tmp_path):
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)
    record_episode(tmp_path, seed=1, steps=3, predictor_sha256=OLD)  # a rerun of its own run replaces it
    with pytest.raises(PipelineError, match=r"it holds another run's episode \(.*predictor_sha256"):
        record_episode(tmp_path, seed=1, steps=3, predictor_sha256=NEW)


# ------------------------------------------------------------------ the weights a controller loaded, recorded
TOY = "tests.plugins.toy_predictor:ToyNet"


def _pair(kind: str, src: Path, seed: int) -> Path:
    """A checkpoint pair ``mine`` in ``src`` of weights drawn with ``seed``: of the shipped social_lstm_eth's
    net, or of a plugin's model kind."""
    from predictors.checkpoint import save_checkpoint
    from predictors.models import register_plugins
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
    from tests.plugins.toy_predictor import ToyNet

    src.mkdir()
    with torch.random.fork_rng(devices=[]):  # the global generator as it was, for the tests after
        torch.manual_seed(seed)
        if kind == "plugin":
            register_plugins([TOY])
            net, model = ToyNet(), TOY
        else:
            document = json.loads((CHECKPOINTS / "social_lstm_eth.json").read_text())
            net, model = SocialLSTM(SocialLSTMConfig(**document["net"])), "social_lstm"
    return save_checkpoint(net, model=model, name="mine", out_dir=src, obs_len=OBS_LEN)[0]


def replace_on_open(monkeypatch, weights: Path, weights_new: Path, **options) -> list:
    """`zoo add --replace` of ``weights_new`` as soon as the zoo's ``weights`` are first opened (in the list
    returned: the new entry)."""
    from predictors.zoo_edit import add_to_zoo

    real_open, replaced = io.open, []

    def opening(file, *args, **kwargs):
        handle = real_open(file, *args, **kwargs)
        if not replaced and isinstance(file, str | os.PathLike) and Path(file) == weights:
            replaced.append(add_to_zoo(weights_new, **options, replace=True))
        return handle

    monkeypatch.setattr(io, "open", opening)
    monkeypatch.setattr(builtins, "open", opening)
    return replaced


@pytest.mark.parametrize("kind", ["social_lstm", "plugin"])
def test_a_controller_records_the_weights_it_loaded_when_they_are_replaced_meanwhile(
    tmp_path, monkeypatch, kind
):
    """Building an MPC controller read the zoo's manifest to load the weights, then again for the sha256 its
    records name: a `zoo add --replace` in between had every episode name the new weights, run with the old.
    The replacement happens here as soon as the old weights file is opened."""
    from pipelines.loop.controllers import make_controller
    from pipelines.loop.spec import ControllerSpec
    from predictors.zoo_edit import add_to_zoo

    user = Path(os.environ["CROWDMPC_ZOO"])
    options = {"name": "mine", "protocol": "p", "training_data": {}, "metrics": {}, "directory": user}
    old = add_to_zoo(_pair(kind, tmp_path / "old", seed=1), **options)
    replaced = replace_on_open(
        monkeypatch, user / "mine.pt", _pair(kind, tmp_path / "new", seed=2), **options
    )
    controller = make_controller(ControllerSpec("cmpc", "mine"))
    assert replaced and replaced[0].sha256 != old.sha256  # the zoo names the new weights now
    assert controller.describe()["predictor_sha256"] == old.sha256  # the weights it plans with


def test_evaluate_records_the_entry_it_scored_when_it_is_replaced_meanwhile(tmp_path, monkeypatch):
    """evaluate loaded the weights, scored them, then read the manifest again for the sha256 and protocol its
    JSON names: a `zoo add --replace` during the scoring gave the old weights' scores the new entry's."""
    from predictors.zoo_edit import add_to_zoo
    from tests.predictors.samples import write_walk_file

    user = Path(os.environ["CROWDMPC_ZOO"])
    options = {"name": "mine", "training_data": {}, "metrics": {}, "directory": user}
    old = add_to_zoo(_pair("social_lstm", tmp_path / "old", seed=1), protocol="old", **options)
    new_weights = _pair("social_lstm", tmp_path / "new", seed=2)
    replaced = replace_on_open(monkeypatch, user / "mine.pt", new_weights, protocol="new", **options)
    walk, out = write_walk_file(tmp_path / "walk.ndjson"), tmp_path / "scores.json"
    assert main(["evaluate", "--predictor", "mine", "--test", str(walk), "--json", str(out)]) == 0
    scores = json.loads(out.read_text())
    assert replaced and replaced[0].sha256 != old.sha256
    assert (scores["predictor_sha256"], scores["trained_protocol"]) == (old.sha256, "old")


# ------------------------------------------------------------ calibrate: the weights its quantiles came from
CALIBRATE = ["calibrate", "--predictor", "mine", "--no-progress"]


def _calibrate_zoo(tmp_path) -> tuple[dict, Path, Path]:
    """The zoo entry "mine" (weights of seed 1), the options to add to it, and other weights (seed 2)."""
    from predictors.zoo_edit import add_to_zoo

    user = Path(os.environ["CROWDMPC_ZOO"])
    options = {"name": "mine", "protocol": "p", "training_data": {}, "metrics": {}, "directory": user}
    add_to_zoo(_pair("social_lstm", tmp_path / "old", seed=1), **options)
    return options, user, _pair("social_lstm", tmp_path / "new", seed=2)


def _fake_episodes(monkeypatch) -> list:
    """Closed-loop episodes that measure tests/calibration_blocks.class_errors(4); returns the sha256 of the
    weights each episode's controller planned with."""
    from tests.calibration_blocks import class_errors

    planned: list = []

    def episode(controller, *, observers, **_):
        planned.append(controller.describe()["predictor_sha256"])
        scores, motion = class_errors(4)
        observers[0].rows.append(scores)
        observers[0].class_rows.append(motion)
        observers[0].shortfall_rows.append(scores)
        return SimpleNamespace(metrics=SimpleNamespace(success=1))

    monkeypatch.setattr("pipelines.loop.episode.run_episode", episode)
    return planned


def _replace_at_call(
    monkeypatch, module, function: str, call: int, weights: Path, after: bool = False, **options
) -> list:
    """`zoo add --replace` of ``weights`` as ``module.function`` is called for the ``call``-th time, before it
    runs (``after``: once it has returned); in the list returned, the new entry."""
    from predictors.zoo_edit import add_to_zoo

    real, calls, replaced = getattr(module, function), [], []

    def replacing(*args, **kwargs):
        calls.append(1)
        if len(calls) == call and not after:
            replaced.append(add_to_zoo(weights, **options, replace=True))
        result = real(*args, **kwargs)
        if len(calls) == call and after:
            replaced.append(add_to_zoo(weights, **options, replace=True))
        return result

    monkeypatch.setattr(module, function, replacing)
    return replaced


def test_calibrate_names_the_weights_its_episodes_loaded_when_they_are_replaced_meanwhile(
    tmp_path, monkeypatch
):
    """calibrate read the weights' sha256 from the manifest before its episodes' controller loaded them: a
    `zoo add --replace` in between stamped the new weights' margins with the old weights' sha256."""
    from pipelines.experiments import calibrate as experiment

    options, _, new_weights = _calibrate_zoo(tmp_path)
    planned = _fake_episodes(monkeypatch)
    replaced = _replace_at_call(monkeypatch, experiment, "closed_loop_errors", 1, new_weights, **options)
    out = tmp_path / "blocks.json"
    argv = [*CALIBRATE, "--source", "closed-loop", "--episodes", "1", "--dry-run", "--json", str(out)]
    assert main(argv) == 0
    [block] = json.loads(out.read_text())["blocks"]
    assert planned == [replaced[0].sha256]
    assert block["predictor_sha256"] == replaced[0].sha256


def test_calibrate_refuses_held_out_episodes_of_other_weights(tmp_path, monkeypatch, capsys):
    """The held-out episodes loaded the predictor again: weights replaced after the calibration's episodes
    had their coverage printed as the stored margins'. They are refused, and nothing is stored, before any
    held-out episode runs: refused after them, the minutes they took were lost."""
    from pipelines.experiments import calibrate as experiment

    options, user, new_weights = _calibrate_zoo(tmp_path)
    planned = _fake_episodes(monkeypatch)
    replaced = _replace_at_call(monkeypatch, experiment, "closed_loop_errors", 2, new_weights, **options)
    assert main([*CALIBRATE, "--source", "closed-loop", "--episodes", "1", "--holdout"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(planned) == 1 and replaced[0].sha256 != planned[0]  # the calibration's episode alone ran
    assert (
        f"margins of sha256 {planned[0][:12]}…, held out with {replaced[0].sha256[:12]}…; none stored" in err
    )
    assert "\n" not in err and not (user / "calibrations.json").exists()


def test_real_calibration_names_the_weights_it_measured_when_they_are_replaced_meanwhile(
    tmp_path, monkeypatch
):
    """calibrate --source real read the weights' sha256 from the manifest, then loaded the predictor: a
    `zoo add --replace` in between stamped the new weights' margins with the old weights' sha256."""
    from pipelines.commands import calibrate as command
    from predictors.data import locate
    from tests.predictors.samples import write_crowds

    options, _, new_weights = _calibrate_zoo(tmp_path)
    replaced = _replace_at_call(monkeypatch, command, "_check_first", 1, new_weights, after=True, **options)
    scenes = write_crowds(tmp_path / "scenes.ndjson")
    split = {"train": [], "val": [scenes], "test": []}
    monkeypatch.setattr(locate, "protocol_files", lambda *args, **kwargs: split)
    monkeypatch.setattr(locate, "prepared_dir", lambda *args, **kwargs: tmp_path)
    out = tmp_path / "blocks.json"
    argv = [*CALIBRATE, "--source", "real", "--alpha", "0.5", "--dry-run", "--json", str(out)]
    assert main(argv) == 0
    [block] = json.loads(out.read_text())["blocks"]
    assert block["predictor_sha256"] == replaced[0].sha256


SWEEP_MINE = ["sweep", "--experiment", "table2", "--predictor", "mine", "--robots", "1", "--no-progress"]
SWEEP_MINE += ["--backend", "inline", "--set", "env.time_limit=2"]


def _refusal(out: Path, weights: Path, replaced: str, checked: str, recorded: int) -> str:
    """The line a sweep stops with when a worker loaded ``replaced`` weights where it checked ``checked``."""
    kept = (
        f"no episode of it is recorded in {out} yet"
        if recorded == 0
        else f"the {recorded} episode{'s' if recorded > 1 else ''} recorded in {out} kept"
    )
    return (
        f"predictor 'mine': the weights {weights} have sha256 {replaced}, not the {checked} this sweep "
        "checked before its workers started (replaced in the zoo since, `zoo add --replace`?); no episode "
        "runs on them: sweep the new weights into another --out, or put the checked ones back and rerun to "
        f"resume (the sweep stopped at the first episode that loaded them, {kept})"
    )


def test_a_sweeps_workers_refuse_weights_replaced_after_the_driver_checked_them(
    tmp_path, monkeypatch, capsys
):
    """A sweep's workers load each predictor again after the driver checked it (processes): a `zoo add
    --replace` in between (retraining into the zoo during a sweep) had every episode run, and be recorded,
    with other weights than the sweep checked. The first worker to load them refuses them, naming the file,
    and the sweep stops there in that one line: no episode of them is recorded, nor written to errors.jsonl
    (each was, one by one)."""
    from pipelines.experiments import sweep
    from predictors import zoo

    options, user, new_weights = _calibrate_zoo(tmp_path)
    checked = zoo.locate("mine").entry.sha256
    # as the run starts: after check_plan loaded the weights, before any worker does
    replaced = _replace_at_call(monkeypatch, sweep, "make_scratch_root", 1, new_weights, **options)
    out = tmp_path / "sweep"
    argv = [*SWEEP_MINE, "--humans", "2", "--episodes-per-cell", "1", "--out", str(out)]
    assert main(argv) == 2
    assert replaced and replaced[0].sha256 != checked
    log = out / "episodes.jsonl"
    assert not log.exists() or not log.read_text().strip()  # no episode of the new weights recorded
    assert not (out / "errors.jsonl").exists()
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == "crowdmpc sweep: error: " + _refusal(out, user / "mine.pt", replaced[0].sha256, checked, 0)


def test_a_sweep_stops_at_weights_replaced_mid_way_and_a_rerun_with_the_checked_ones_resumes(
    tmp_path, monkeypatch, capsys
):
    """Weights replaced once some episodes are recorded: a worker's cell whose controller was built already
    ran on (on the weights checked), and every episode of the cells it built after failed, each its own
    entry in errors.jsonl (33 of a 60-episode sweep, `--workers 2`, replaced after the first record). The
    sweep now stops at the first refusal, the episodes recorded kept; with the checked weights back, a
    rerun of the same command runs the rest."""
    from pipelines.experiments.log import EpisodeLog
    from predictors import zoo

    options, user, new_weights = _calibrate_zoo(tmp_path)
    checked = zoo.locate("mine").entry.sha256
    replaced = _replace_at_call(monkeypatch, EpisodeLog, "append", 1, new_weights, after=True, **options)
    out = tmp_path / "sweep"
    argv = [*SWEEP_MINE, "--humans", "2,3", "--episodes-per-cell", "2", "--out", str(out)]
    assert main(argv) == 2  # 4 cells, an episode of each in turn: the second cell's controller refuses
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == "crowdmpc sweep: error: " + _refusal(out, user / "mine.pt", replaced[0].sha256, checked, 1)
    first = (out / "episodes.jsonl").read_text()
    assert len(first.splitlines()) == 1 and not (out / "errors.jsonl").exists()
    add_to_zoo(tmp_path / "old" / "mine.pt", **options, replace=True)  # the checked weights back
    assert main(argv) == 0
    held = (out / "episodes.jsonl").read_text()
    assert held.startswith(first) and len(held.splitlines()) == 8
    assert {json.loads(line)["predictor_sha256"] for line in held.splitlines()} == {checked}


def test_a_resume_checks_the_records_against_the_weights_its_driver_checked(tmp_path, monkeypatch):
    """The resume check read the zoo's manifest again for the weights' sha256, after the plan's checks had
    loaded them (the sha256 the workers are handed, pipelines.experiments.checked_weights): a manifest that
    named other weights between the reads (a `zoo add --replace`, put back) refused the records of the very
    weights the workers load."""
    import json
    import shutil

    from pipelines.experiments import sweep
    from pipelines.experiments.log import episode_log
    from predictors import zoo
    from tests.pipelines.test_checked_calibrations import SWEEP

    shipped = tmp_path / "checkpoints"
    shutil.copytree(zoo.shipped_checkpoints_dir(), shipped)
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(shipped))
    manifest, name = shipped / "manifest.json", "social_lstm_eth"
    plan = [{"constant_velocity": name, "1,2": "2"}.get(word, word) for word in SWEEP]  # 2 cells
    out = tmp_path / "sweep"
    assert main([*plan, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    checked, real = manifest.read_bytes(), sweep.read_recorded
    other = json.loads(checked)
    next(entry for entry in other["models"] if entry["name"] == name)["sha256"] = "ee" * 32

    def replaced_meanwhile(*args, **kwargs):  # after the plan's checks, put back before any worker loads
        manifest.write_text(json.dumps(other))
        try:
            return real(*args, **kwargs)
        finally:
            manifest.write_bytes(checked)

    monkeypatch.setattr(sweep, "read_recorded", replaced_meanwhile)
    assert main([*plan, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    records = list(episode_log(out).load().values())
    assert len(records) == 4 and {r["predictor_sha256"] for r in records} == {zoo.locate(name).entry.sha256}
