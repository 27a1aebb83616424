"""The JSON files a user may edit by hand (a zoo's manifest, a predictor's config, a calibrations file, a
training run's train_settings.json) name each key once: json keeps the last of a key given twice without a
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
