"""The JSON files a user may edit by hand (a zoo's manifest, a predictor's config, a calibrations file, a
training run's train_settings.json and NAME.metrics.json, a prepared data manifest, a synth provenance file)
name each key once: json keeps the last of a key given twice without a
word, so a value typed above the one already there did nothing. The shipped and written files do."""

import json
from pathlib import Path

import pytest

from pipelines.commands.train_resume import SETTINGS_FILE, read_run_settings
from pipelines.errors import PipelineError
from predictors.calibration_store import read_calibration_file
from predictors.checkpoint import parse_document, save_checkpoint
from predictors.errors import PredictorError, unique_keys
from predictors.manifest import read_manifest_at
from predictors.zoo import checkpoints_dir

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "name, text, reader",
    [
        (
            "manifest.json",
            '{"format": "crowdmpc-zoo", "version": 1, "models": [], "models": []}',
            lambda path: read_manifest_at(path.parent),
        ),
        (
            "calibrations.json",
            '{"format": "crowdmpc-calibrations", "version": 1, "calibrations": [], "version": 1}',
            read_calibration_file,
        ),
    ],
)
def test_a_zoo_file_that_names_a_key_twice_is_refused_naming_file_and_key(tmp_path, name, text, reader):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    key = "models" if name == "manifest.json" else "version"
    with pytest.raises(PredictorError) as exc:
        reader(path)
    assert str(exc.value) == (
        f"{path}: the key '{key}' appears twice in one object; give each key once (json would keep the last)"
    )


def test_a_predictor_config_with_a_key_twice_in_a_nested_object_is_refused(tmp_path):
    """{"net": {"hidden_dim": 32, "hidden_dim": 64}} loaded a 64-unit net where the file read 32 first."""
    path = tmp_path / "net.json"
    data = b'{"format": "crowdmpc-predictor", "net": {"hidden_dim": 32, "hidden_dim": 64}}'
    with pytest.raises(PredictorError, match=r"net\.json: the key 'hidden_dim' appears twice in one object;"):
        parse_document(path, data, "crowdmpc-predictor", "crowdmpc predictor config")


def test_train_settings_with_a_key_twice_are_refused(tmp_path):
    (tmp_path / SETTINGS_FILE).write_text('{"epochs": 3, "epochs": 30}', encoding="utf-8")
    with pytest.raises(PipelineError) as exc:
        read_run_settings(tmp_path)
    assert str(exc.value) == (
        f"--resume: {tmp_path / SETTINGS_FILE}: the key 'epochs' appears twice in one object; give each key "
        "once (json would keep the last)"
    )


def test_every_shipped_json_file_names_each_key_once():
    files = sorted(checkpoints_dir().glob("*.json")) + sorted((REPO / "docs").rglob("*.json"))
    files += sorted((REPO / "tests" / "data").rglob("*.json"))
    assert len(files) >= 9
    for path in files:
        json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=unique_keys)


def test_a_written_checkpoint_config_reads_back_with_each_key_once(tmp_path):
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

    net = SocialLSTM(SocialLSTMConfig(hidden_dim=8, embedding_dim=4))
    _, config = save_checkpoint(net, model="social_lstm", name="net", out_dir=tmp_path, obs_len=9)
    document = parse_document(config, config.read_bytes(), "crowdmpc-predictor", "crowdmpc predictor config")
    assert document["name"] == "net"


def test_the_advice_is_the_errors_own_so_every_reader_gives_it_alike():
    """The advice was written by each of the four readers that catch DuplicateKey (checkpoint's documents,
    train_settings.json, --net-config, a zoo metrics file); it is now the error's, their lines as before."""
    from pipelines.commands.train_net import parse_net_config
    from predictors.errors import DuplicateKey

    advice = "appears twice in one object; give each key once (json would keep the last)"
    assert str(DuplicateKey("seed")) == f"the key 'seed' {advice}"
    with pytest.raises(PipelineError) as exc:
        parse_net_config('{"hidden_dim": 32, "hidden_dim": 64}')
    assert str(exc.value) == f"--net-config: the key 'hidden_dim' {advice}"


ADVICE = "appears twice in one object; give each key once (json would keep the last)"


def test_a_prepared_data_manifest_with_a_key_twice_is_refused(tmp_path):
    """A prepared folder's manifest.json ({"files": {...}, "files": {}}) was read as its last "files": one
    listing no file, whose splits were then checked against nothing."""
    from predictors.data.locate import load_manifest, prepared_dir

    path = tmp_path / "manifest.json"
    path.write_text('{"format": "crowdmpc-prepared", "files": {"a": 1}, "files": {}}', encoding="utf-8")
    for read in (load_manifest, prepared_dir):
        with pytest.raises(PredictorError) as exc:
            read(tmp_path)
        assert str(exc.value) == f"{path}: the key 'files' {ADVICE}"


def test_a_synth_provenance_file_with_a_key_twice_is_refused(tmp_path, capsys):
    """`data synth --out x.ndjson` reads x.synth.json beside it to tell whose data it records ("data"): one
    naming "data" twice was read as its last, and another file's provenance could be taken for --out's."""
    from pipelines.cli import main

    out = tmp_path / "x.ndjson"
    provenance = tmp_path / "x.synth.json"
    provenance.write_text('{"format": "crowdmpc-synth", "data": "y.ndjson", "data": "x.ndjson"}', "utf-8")
    capsys.readouterr()
    argv = ["data", "synth", "--out", str(out), "--episodes", "1", "--humans", "1", "--seed", "0"]
    assert main([*argv, "--no-progress", "--replace"]) == 2
    assert capsys.readouterr().err == f"crowdmpc data synth: error: {provenance}: the key 'data' {ADVICE}\n"
    assert not out.exists()


def test_a_metrics_file_with_a_key_twice_is_refused_on_a_resume(tmp_path):
    """A finished run's NAME.metrics.json, read by --resume for the epochs its --patience stopped it after,
    was read as its last "training" without a word."""
    from pipelines.commands.train_epochs import check_more_epochs

    metrics = tmp_path / "net.metrics.json"
    metrics.write_text('{"training": {"stopped_early_after": 3}, "training": {}}', encoding="utf-8")
    with pytest.raises(PipelineError) as exc:
        check_more_epochs(tmp_path, 10, 5, metrics)
    assert str(exc.value) == f"--resume: {metrics}: the key 'training' {ADVICE}"
