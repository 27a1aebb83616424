"""A checkpoint file is read once: the bytes whose sha256 is checked are the bytes built and loaded. Hashed,
then read again, a file replaced between the two reads (`zoo add --replace` while a run starts) loaded other
weights, or built another net, than the manifest's sha256 had vouched for."""

from __future__ import annotations

import builtins
import hashlib
import io
import json
import os
import shutil
from pathlib import Path

import pytest
import torch

from predictors import checkpoint

REAL_ZOO = Path(__file__).resolve().parents[2] / "checkpoints"
NAME = "social_lstm_eth"


@pytest.fixture
def pair(tmp_path) -> tuple[Path, Path]:
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", tmp_path / f"{NAME}{suffix}")
    return tmp_path / f"{NAME}.pt", tmp_path / f"{NAME}.json"


def replace_after_first_open(monkeypatch, target: Path, content: bytes) -> list[Path]:
    """Every later open of ``target`` finds ``content``: the file is replaced (renamed over, as `zoo add
    --replace` does) as soon as it is first opened. Returns the list of replaced files, to check it ran."""
    real_open = io.open
    replaced: list[Path] = []

    def opening(file, *args, **kwargs):
        handle = real_open(file, *args, **kwargs)
        if not replaced and isinstance(file, str | os.PathLike) and Path(file) == target:
            replaced.append(target)
            staged = target.with_name(target.name + ".staged")
            staged.write_bytes(content)
            os.replace(staged, target)
        return handle

    monkeypatch.setattr(io, "open", opening)
    monkeypatch.setattr(builtins, "open", opening)
    return replaced


def other_weights(weights: Path) -> bytes:
    state = torch.load(weights, weights_only=True)
    state["head.bias"] = state["head.bias"] + 1.0
    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


def test_weights_replaced_after_their_hash_are_not_what_loads(pair, monkeypatch):
    weights, config = pair
    original = weights.read_bytes()
    bias = torch.load(weights, weights_only=True)["head.bias"].to(torch.float64)
    expected = {
        "expected_sha256": hashlib.sha256(original).hexdigest(),
        "expected_config_sha256": hashlib.sha256(config.read_bytes()).hexdigest(),
    }
    replaced = replace_after_first_open(monkeypatch, weights, other_weights(weights))
    predictor = checkpoint.load_checkpoint(weights, config, **expected)
    assert replaced == [weights] and weights.read_bytes() != original
    assert torch.equal(predictor.net.state_dict()["head.bias"], bias)  # the checked weights, not the new


def test_a_config_replaced_after_its_hash_is_not_what_builds(pair, monkeypatch):
    weights, config = pair
    document = json.loads(config.read_text())
    expected = {
        "expected_sha256": hashlib.sha256(weights.read_bytes()).hexdigest(),
        "expected_config_sha256": hashlib.sha256(config.read_bytes()).hexdigest(),
    }
    other = json.dumps({**document, "obs_len": document["obs_len"] - 1}).encode()  # valid, not the hashed
    replaced = replace_after_first_open(monkeypatch, config, other)
    predictor = checkpoint.load_checkpoint(weights, config, **expected)
    assert replaced == [config]
    assert predictor.obs_len == document["obs_len"]


# ------------------------------------------------------------------------------------ zoo add: the bytes kept
def nan_weights(weights: Path) -> bytes:
    """Weights that do not load (a NaN): a pair holding them is refused."""
    state = torch.load(weights, weights_only=True)
    state["head.bias"][0] = float("nan")
    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


@pytest.mark.parametrize("suffix", [".pt", ".json"])
def test_zoo_add_keeps_the_bytes_it_checked_when_the_source_is_replaced_meanwhile(pair, monkeypatch, suffix):
    """`zoo add` loaded the pair to check it, then read the config again and copied and hashed the weights
    again: a source replaced in between (here by a pair that never loads) was added unchecked."""
    from predictors import zoo
    from predictors.zoo_edit import add_to_zoo

    weights, config = pair
    source = weights if suffix == ".pt" else config
    original = {path: path.read_bytes() for path in pair}
    unloadable = config.read_bytes().replace(b'"obs_len": 9', b'"obs_len": 1')  # obs_len is 2..100
    broken = nan_weights(weights) if suffix == ".pt" else unloadable
    replaced = replace_after_first_open(monkeypatch, source, broken)
    directory = weights.parent / "zoo"
    entry = add_to_zoo(weights, name="mine", protocol="p", training_data={}, metrics={}, directory=directory)
    monkeypatch.undo()
    assert replaced == [source] and source.read_bytes() == broken
    assert (directory / "mine.pt").read_bytes() == original[weights]
    assert entry.sha256 == hashlib.sha256(original[weights]).hexdigest()
    assert json.loads((directory / "mine.json").read_text())["obs_len"] == 9
    assert zoo.verify(directory) == [("mine", None)]


# --------------------------------------------------------------------- zoo verify: of the config that loaded
@pytest.mark.parametrize("both_zoos", [False, True])
def test_zoo_verify_reports_on_the_config_that_loaded(pair, monkeypatch, both_zoos):
    """`zoo verify` loaded each entry, then read its config again to compare it with the entry: a config
    replaced in between was reported on (here a training record the entry does not have), not the one that
    loaded, which agrees with it."""
    from predictors import zoo
    from predictors.zoo_edit import add_to_zoo

    weights, _ = pair
    directory = weights.parent / "zoo"
    add_to_zoo(
        weights,
        name="mine",
        protocol="p",
        training_data={},
        metrics={},
        training={"epochs": 25},  # as its config says
        directory=directory,
    )
    config = directory / "mine.json"
    document = json.loads(config.read_text())
    other = {**document, "training": {**document["training"], "epochs": 99}}
    replaced = replace_after_first_open(monkeypatch, config, json.dumps(other).encode())
    if both_zoos:
        problems = [(located.entry.name, problem) for located, problem in zoo.verify_entries(directory)]
    else:
        problems = zoo.verify(directory)
    assert replaced == [config]
    assert ("mine", None) in problems
