"""The model zoo against hostile input: every bad name, path, hash, config, weights file or option is refused
with a PredictorError/PipelineError that names the file (and key), which the CLI prints as one line, exit 2.

Every bad input is generated here, in tmp_path, from a copy of a real zoo entry; checkpoints/ is only read.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from pathlib import Path

import casadi
import numpy as np
import pytest
import torch

from pipelines.cli import main
from predictors import checkpoint, manifest, zoo, zoo_edit
from predictors.errors import CheckpointMismatch, PredictorError
from predictors.nets.social_gan import DiscriminatorConfig, generator_config
from predictors.nets.social_lstm import MAX_PARAMETERS, SocialLSTM, SocialLSTMConfig

REAL_ZOO = Path(__file__).resolve().parents[2] / "checkpoints"
NAME = "social_lstm_eth"


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def real_entry() -> dict:
    document = json.loads((REAL_ZOO / zoo.MANIFEST_NAME).read_text())
    return next(e for e in document["models"] if e["name"] == NAME)


def write_manifest(root: Path, *entries: dict) -> Path:
    path = root / zoo.MANIFEST_NAME
    path.write_text(json.dumps({"format": manifest.MANIFEST_FORMAT, "version": 1, "models": list(entries)}))
    return path


@pytest.fixture
def zoo_dir(tmp_path, monkeypatch) -> Path:
    """A private user zoo holding a copy of the real entry ``NAME`` (files and manifest entry), the CLI's
    zoo, beside an empty shipped zoo (tests/predictors/test_zoo.py has the shipped zoo's own cases)."""
    root = tmp_path / "zoo"
    root.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", root / f"{NAME}{suffix}")
    write_manifest(root, real_entry())
    (tmp_path / "shipped").mkdir()
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(tmp_path / "shipped"))
    monkeypatch.setenv(zoo.ZOO_ENV, str(root))
    return root


@pytest.fixture
def pair(tmp_path) -> tuple[Path, Path]:
    """A copy of the real checkpoint pair outside any zoo, with the metrics file `zoo add` reads."""
    src = tmp_path / "src"
    src.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", src / f"{NAME}{suffix}")
    (src / f"{NAME}.metrics.json").write_text("{}")
    return src / f"{NAME}.pt", src / f"{NAME}.json"


def cli(args: list[str], capsys) -> tuple[int, str]:
    """Exit code and the one line the CLI printed on stderr (asserted to be exactly one)."""
    capsys.readouterr()
    code = main(args)
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return code, lines[0]


def tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


# ------------------------------------------------------------------------------------------------ control
def test_the_copied_real_entry_verifies_and_loads(zoo_dir, capsys):
    assert main(["zoo", "verify"]) == 0
    assert "1 of 1 entries ok" in capsys.readouterr().out
    assert zoo.load_zoo(NAME).name == NAME


# ------------------------------------------------------------------------------------------------- names
@pytest.mark.parametrize(
    "name", ["../x", "ABS", ".", "..", "a/b", "a\\b", "", ".hidden", "-x", "x" * 65, "a b", "a\x00b"]
)
def test_zoo_add_refuses_unsafe_names_before_writing(tmp_path, zoo_dir, pair, capsys, name):
    if name == "ABS":
        name = str(tmp_path / "abs")
    before = tree(tmp_path)
    code, line = cli(["zoo", "add", str(pair[0]), f"--name={name}"], capsys)
    assert code == 2
    assert line.startswith("crowdmpc zoo add: error: zoo name ") and "is not allowed" in line
    assert tree(tmp_path) == before  # nothing written, inside the zoo or out of it
    with pytest.raises(PredictorError, match="is not allowed"):
        zoo_edit.add_to_zoo(pair[0], name=name, protocol="p", training_data={}, metrics={}, directory=zoo_dir)


def test_zoo_add_accepts_a_safe_name(zoo_dir, pair, capsys):
    assert main(["zoo", "add", str(pair[0]), "--name", "My_model-2.v1"]) == 0
    assert zoo.load_zoo("My_model-2.v1").name == "My_model-2.v1"
    assert (zoo_dir / "My_model-2.v1.pt").is_file()


def test_zoo_add_does_not_write_through_a_symbolic_link(tmp_path, zoo_dir, pair, capsys):
    outside = tmp_path / "outside.pt"
    outside.write_bytes(b"keep me")
    (zoo_dir / "linked.pt").symlink_to(outside)
    code, line = cli(["zoo", "add", str(pair[0]), "--name", "linked"], capsys)
    assert code == 2 and "lies outside the zoo directory" in line
    assert outside.read_bytes() == b"keep me"


@pytest.mark.parametrize("name", ["../x", "/tmp/x", "..", 7, None])
def test_manifest_names_must_be_safe(zoo_dir, capsys, name):
    manifest = write_manifest(zoo_dir, {**real_entry(), "name": name})
    with pytest.raises(PredictorError) as refused:
        zoo.read_manifest(zoo_dir)
    assert str(refused.value).startswith(f"{manifest}: zoo name ")
    code, line = cli(["zoo", "list"], capsys)
    assert code == 2 and str(manifest) in line and "is not allowed" in line


def test_manifest_names_must_be_unique(zoo_dir):
    manifest = write_manifest(zoo_dir, real_entry(), real_entry())
    with pytest.raises(PredictorError, match=f"^{re.escape(str(manifest))}: entry '{NAME}' appears twice$"):
        zoo.read_manifest(zoo_dir)


# ------------------------------------------------------------------------------------------ file paths
@pytest.mark.parametrize("key", ["file", "config"])
@pytest.mark.parametrize(
    "where", ["dotdot", "absolute", "inner_dotdot", "symlink", "the_zoo_itself", "empty"]
)
def test_manifest_files_must_lie_inside_the_zoo(tmp_path, zoo_dir, capsys, key, where):
    suffix = ".pt" if key == "file" else ".json"
    outside = tmp_path / f"outside{suffix}"
    shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", outside)  # a valid file: only its place is wrong
    (zoo_dir / "sub").mkdir()
    if where == "symlink":
        (zoo_dir / f"link{suffix}").symlink_to(outside)
    value = {
        "dotdot": f"../outside{suffix}",
        "absolute": str(outside),
        "inner_dotdot": f"sub/../../outside{suffix}",
        "symlink": f"link{suffix}",
        "the_zoo_itself": ".",
        "empty": "",
    }[where]
    manifest = write_manifest(zoo_dir, {**real_entry(), key: value})
    with pytest.raises(PredictorError) as refused:
        zoo.load_zoo(NAME)
    message = str(refused.value)
    assert message.startswith(f'{manifest}: entry {NAME!r}: "{key}" ')
    assert "outside the zoo directory" in message or "must be a file name inside the zoo" in message
    for args in (["zoo", "verify"], ["zoo", "list"], ["export", NAME, "--out", str(tmp_path / "o.casadi")]):
        code, line = cli(args, capsys)
        assert code == 2 and f'entry {NAME!r}: "{key}"' in line, args
    assert not (tmp_path / "o.casadi").exists()


def test_a_file_in_a_subdirectory_of_the_zoo_is_fine(zoo_dir):
    (zoo_dir / "sub").mkdir()
    (zoo_dir / f"{NAME}.pt").rename(zoo_dir / "sub" / "w.pt")
    write_manifest(zoo_dir, {**real_entry(), "file": "sub/w.pt"})
    assert zoo.load_zoo(NAME).name == NAME


# ------------------------------------------------------------------------------------------------ hashes
def tamper_weights(path: Path) -> None:
    """A valid state_dict with other values: what a hash check exists to catch."""
    state = torch.load(path, weights_only=True)
    state["head.bias"] = state["head.bias"] + 1.0
    torch.save(state, path)


@pytest.mark.parametrize("key", ["sha256", "config_sha256"])
@pytest.mark.parametrize("value", [None, "", "0" * 63, "A" * 64, "g" * 64, 12, ["0" * 64], "MISSING"])
def test_a_missing_or_malformed_sha256_is_refused_never_skipped(tmp_path, zoo_dir, capsys, key, value):
    tamper_weights(zoo_dir / f"{NAME}.pt")
    entry = real_entry()
    if value == "MISSING":
        del entry[key]
    else:
        entry[key] = value
    manifest = write_manifest(zoo_dir, entry)
    with pytest.raises(PredictorError) as refused:
        zoo.load_zoo(NAME)
    message = str(refused.value)
    assert message.startswith(f"{manifest}: ")
    assert f'"{key}" must be a sha256 (64 lowercase hex digits)' in message or f"lacks ['{key}']" in message
    code, line = cli(["export", NAME, "--out", str(tmp_path / "o.casadi")], capsys)
    assert code == 2 and str(manifest) in line and key in line
    assert not (tmp_path / "o.casadi").exists()


def test_tampered_weights_with_the_recorded_sha256_are_refused(tmp_path, zoo_dir, capsys):
    tamper_weights(zoo_dir / f"{NAME}.pt")
    with pytest.raises(CheckpointMismatch):
        zoo.load_zoo(NAME)
    code, line = cli(["export", NAME, "--out", str(tmp_path / "o.casadi")], capsys)
    assert code == 2 and "the manifest expects" in line


def test_a_tampered_config_with_the_recorded_sha256_is_refused(tmp_path, zoo_dir, capsys):
    """The config is half the checkpoint (what net to build, how many steps it observes): the manifest's
    config_sha256 guards it as sha256 guards the weights."""
    config = zoo_dir / f"{NAME}.json"
    document = json.loads(config.read_text())
    config.write_text(json.dumps({**document, "obs_len": 8}))  # still valid, just not the recorded one
    with pytest.raises(CheckpointMismatch):
        zoo.load_zoo(NAME)
    code, line = cli(["export", NAME, "--out", str(tmp_path / "o.casadi")], capsys)
    assert code == 2 and "the manifest expects" in line and f"{NAME}.json" in line


@pytest.mark.parametrize("suffix", [".pt", ".json"])
def test_a_zoo_file_replaced_by_one_over_its_size_cap_is_named_as_replaced(zoo_dir, capsys, suffix):
    """A zoo file the manifest vouches for fitted its cap when it was added: one over it is not that file,
    and `zoo verify` said so (restore it, or add the model again) until the caps were checked before the
    hashes, when it said only how many bytes the file had."""
    path = zoo_dir / f"{NAME}{suffix}"
    with path.open("r+b") as handle:  # sparse: no 64 MiB written
        handle.truncate(checkpoint.MAX_DOCUMENT_BYTES + 1)
    with pytest.raises(CheckpointMismatch):
        zoo.load_zoo(NAME)
    assert main(["zoo", "verify"]) == 1
    out = capsys.readouterr().out
    assert f"{path} has sha256" in out and "the file is corrupt or was replaced" in out


@pytest.mark.parametrize("which", ["user", "user --dir", "shipped"])
def test_verify_says_what_to_do_of_a_replaced_file(tmp_path, zoo_dir, monkeypatch, capsys, which):
    """`zoo verify`'s line of a replaced file ended in the loading refusal's advice, "`crowdmpc zoo verify`
    lists every entry whose files differ", the command just run; it now says how to mend the entry: add it
    again with --replace or remove it (a user entry, the --dir given named), add it --shipped (a shipped
    one)."""
    tamper_weights(zoo_dir / f"{NAME}.pt")
    args = ["zoo", "verify"]
    if which == "shipped":
        monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(zoo_dir))
        monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "no_user_zoo"))
    elif which == "user --dir":
        monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "no_user_zoo"))
        args = ["zoo", "--dir", str(zoo_dir), "verify"]
    assert main(args) == 1
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith(NAME))
    assert "has sha256" in line and "the file is corrupt or was replaced" in line
    assert "zoo verify" not in line
    if which == "shipped":
        assert f"`crowdmpc zoo add --shipped FILE.pt --name {NAME} --replace`" in line
        return
    option = "" if which == "user" else f" --dir {zoo_dir}"
    assert f"`crowdmpc zoo{option} add FILE.pt --name {NAME} --replace`" in line
    assert f"`crowdmpc zoo{option} remove {NAME}`" in line


def test_load_checkpoint_checks_both_expected_hashes(pair):
    weights, config = pair
    good = {"expected_sha256": sha256(weights), "expected_config_sha256": sha256(config)}
    assert checkpoint.load_checkpoint(weights, **good).name == NAME
    config.write_text(config.read_text() + " ")  # the same document, other bytes
    with pytest.raises(CheckpointMismatch, match=rf"checkpoint {re.escape(str(config))} has sha256"):
        checkpoint.load_checkpoint(weights, **good)


def test_load_checkpoint_refuses_a_malformed_expected_sha256(pair):
    with pytest.raises(PredictorError, match="must be a sha256"):
        checkpoint.load_checkpoint(pair[0], expected_sha256="not a hash")


# ------------------------------------------------------------------------------------- finite weights
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("everywhere", [True, False])
def test_non_finite_weights_are_refused_naming_the_tensor(tmp_path, zoo_dir, capsys, bad, everywhere):
    weights = zoo_dir / f"{NAME}.pt"
    state = torch.load(weights, weights_only=True)
    if everywhere:
        state = {k: torch.full_like(v, bad) for k, v in state.items()}
        tensor = next(iter(state))
    else:
        tensor = "decoder.weight_hh"
        state[tensor] = state[tensor].clone()
        state[tensor][3, 1] = bad
    torch.save(state, weights)
    write_manifest(zoo_dir, {**real_entry(), "sha256": sha256(weights)})  # a consistent, hostile zoo
    message = f"{weights.resolve()}: tensor '{tensor}' holds NaN or infinite values"
    with pytest.raises(PredictorError, match=f"^{re.escape(message)}$"):
        zoo.load_zoo(NAME)
    capsys.readouterr()
    assert main(["zoo", "verify"]) == 1
    out = capsys.readouterr().out
    assert f"{NAME} (user): {message}\n" in out and "0 of 1 entries ok" in out
    code, line = cli(["export", NAME, "--out", str(tmp_path / "o.casadi")], capsys)
    assert code == 2 and "holds NaN or infinite values" in line


# ------------------------------------------------------------------------------------- weights files
def real_state() -> dict[str, torch.Tensor]:
    return torch.load(REAL_ZOO / f"{NAME}.pt", weights_only=True)


def _weights_cases() -> dict[str, tuple[object, str]]:
    """Name -> (bytes to write, or an object to torch.save; what the one-line message says after the path)."""
    good = (REAL_ZOO / f"{NAME}.pt").read_bytes()
    state = real_state()
    return {
        "empty": (b"", ": not a state_dict of tensors as `crowdmpc train` writes"),
        "truncated": (good[: len(good) // 2], ": not a state_dict of tensors as `crowdmpc train` writes"),
        "truncated_end": (good[:-30], ": not a state_dict of tensors as `crowdmpc train` writes"),
        "garbage": (b"\x00\xff" * 500, ": not a state_dict of tensors as `crowdmpc train` writes"),
        "text": (b"not a torch file\n", ": not a state_dict of tensors as `crowdmpc train` writes"),
        "too_large": (b"\x00" * (2 << 20), "bytes, more than the"),
        "a_list": ([1, 2, 3], ": not a state_dict (a dict of tensors), but a list"),
        "a_tensor": (torch.zeros(3), ": not a state_dict (a dict of tensors), but a Tensor"),
        "strings": ({"a": "b"}, ": 'a' is a str, not a dense tensor"),
        "string_values": ({k: "x" for k in state}, ": 'pool.hidden_encoding.weight' is a str, not a dense"),
        "nested": ({k: [1, [2, {"x": None}]] for k in state}, ": 'pool.hidden_encoding.weight' is a list"),
        "int_key": ({**state, 3: torch.zeros(1)}, ": a state_dict key is 3, not a string"),
        "missing": (
            {k: v for k, v in state.items() if k != "head.bias"},
            "missing ['head.bias'], unexpected []",
        ),
        "extra": ({**state, "x": torch.zeros(1)}, "missing [], unexpected ['x']"),
        "shape": ({**state, "head.bias": torch.zeros(7)}, ": tensor 'head.bias' has shape (7,), the net of"),
        "wrong_rank": ({**state, "head.bias": torch.zeros(5, 1)}, "has shape (5, 1), the net of"),
        "int_dtype": (
            {**state, "head.bias": torch.zeros(5, dtype=torch.int64)},
            "is torch.int64, not floating",
        ),
        "bool_dtype": (
            {**state, "head.bias": torch.zeros(5, dtype=torch.bool)},
            "is torch.bool, not floating",
        ),
        "complex": ({**state, "head.bias": torch.zeros(5, dtype=torch.complex64)}, "not floating point"),
        # floating point to is_floating_point, but with no isfinite: a traceback before
        "float8": (
            {**state, "head.bias": torch.zeros(5).to(torch.float8_e4m3fn)},
            "is torch.float8_e4m3fn, not floating point of 16, 32 or 64 bits",
        ),
        "meta": ({**state, "head.bias": torch.empty(5, device="meta")}, "is on device 'meta', not the cpu"),
    }


@pytest.mark.parametrize("case", sorted(_weights_cases()))
def test_bad_weights_files_are_one_line_errors_naming_the_file(pair, zoo_dir, capsys, case):
    weights, config = pair
    content, message = _weights_cases()[case]
    if isinstance(content, bytes):
        weights.write_bytes(content)
    else:
        torch.save(content, weights)
    with pytest.raises(PredictorError) as refused:
        checkpoint.load_checkpoint(weights)
    text = str(refused.value)
    assert text.startswith(str(weights)) and message in text and "\n" not in text
    code, line = cli(["zoo", "add", str(weights)], capsys)
    assert code == 2 and line.startswith(f"crowdmpc zoo add: error: {weights}") and message in line
    assert tree(zoo_dir) == {zoo.MANIFEST_NAME, f"{NAME}.pt", f"{NAME}.json"}  # the zoo untouched


def test_weights_that_are_not_a_regular_file_are_refused(pair):
    weights, _ = pair
    weights.unlink()
    weights.mkdir()
    with pytest.raises(
        PredictorError, match=f"^checkpoint file {re.escape(str(weights))} is not a regular file$"
    ):
        checkpoint.load_checkpoint(weights)


# ------------------------------------------------------------------------------------------------ configs
def _config_cases() -> dict[str, tuple[dict, str]]:
    """Name -> (changes to the config document, "net" entries merged; what the message says)."""
    wrong = "holds a value of the wrong type"
    return {
        "hidden_64GB": ({"net": {"hidden_dim": 4_000_000}}, '"net": hidden_dim must be in 1..4096'),
        "hidden_0": ({"net": {"hidden_dim": 0}}, "hidden_dim must be in 1..4096, got 0"),
        "hidden_str": ({"net": {"hidden_dim": "32"}}, f"{wrong}: hidden_dim must be an integer, got '32'"),
        "hidden_bool": ({"net": {"hidden_dim": True}}, f"{wrong}: hidden_dim must be an integer, got True"),
        "hidden_float": ({"net": {"hidden_dim": 32.5}}, f"{wrong}: hidden_dim must be an integer"),
        "hidden_null": ({"net": {"hidden_dim": None}}, f"{wrong}: hidden_dim must be an integer, got None"),
        "hidden_nested": (
            {"net": {"hidden_dim": [[1], {"a": 2}]}},
            f"{wrong}: hidden_dim must be an integer",
        ),
        "grid_huge": ({"net": {"grid_size": 100_000}}, "grid_size must be in 1..64"),
        "latent_huge": ({"net": {"latent_dim": 10**30}}, "latent_dim must be in 1..4096"),
        "params_total": (
            {"net": {"grid_size": 64, "latent_dim": 4096, "pool_dim": 4096}},
            f"parameters, more than the {MAX_PARAMETERS:,} allowed",
        ),
        "embedding_2": ({"net": {"embedding_dim": 2}}, "embedding_dim must be > 2"),
        "noise_negative": ({"net": {"noise_dim": -1}}, "noise_dim must be in 0..4096"),
        "cell_nan": ({"net": {"cell_side": float("nan")}}, "cell_side must be a finite number, got nan"),
        "cell_inf": ({"net": {"cell_side": float("inf")}}, "cell_side must be a finite number"),
        "cell_negative": ({"net": {"cell_side": -1}}, "cell_side must be in (0, 100]"),
        "cell_str": ({"net": {"cell_side": "0.8"}}, f"{wrong}: cell_side must be a number"),
        "scale_huge": ({"net": {"input_scale": 1e9}}, "input_scale must be in (0, 1000]"),
        "pooling_int": ({"net": {"pooling": 3}}, f"{wrong}: pooling must be a string, got 3"),
        "pooling_unknown": ({"net": {"pooling": "max"}}, "pooling 'max' is not one of"),
        "head_list": ({"net": {"head": ["gaussian"]}}, f"{wrong}: head must be a string"),
        "net_list": ({"net": [1, 2]}, '"net": a social_lstm config must be a JSON object, got [1, 2]'),
        "net_unknown_key": ({"net": {"hidden": 3}}, "unknown social_lstm config keys ['hidden']"),
        "obs_len_huge": ({"obs_len": 10**9}, '"obs_len" must be in 2..100, got 1000000000'),
        "obs_len_1": ({"obs_len": 1}, '"obs_len" must be in 2..100, got 1'),
        "obs_len_str": ({"obs_len": "9"}, "\"obs_len\" must be an integer, got '9'"),
        "obs_len_bool": ({"obs_len": True}, '"obs_len" must be an integer, got True'),
        "class_list": ({"class": ["SocialLSTMPredictor"]}, "unknown predictor class ['SocialLSTMPredictor']"),
        "class_unknown": ({"class": "Transformer"}, "unknown predictor class 'Transformer'"),
        "model_unknown": ({"model": "transformer"}, "\"model\": unknown model 'transformer'; choose from"),
        "model_list": ({"model": ["social_lstm"]}, "\"model\": unknown model ['social_lstm']; choose from"),
        "model_mismatch": ({"model": "social_gan"}, '"model" \'social_gan\' does not go with "class"'),
        # a plugin that is not registered: refused, never imported on the file's word
        "model_plugin": (
            {"model": "os:system"},
            "\"model\": model 'os:system' is a plugin that is not registered; register it with "
            "`crowdmpc --plugin os:system COMMAND ...` or CROWDMPC_PLUGINS=os:system",
        ),
        "model_no_such_module": (
            {"model": "no_such_module_xyz:Net"},
            "model 'no_such_module_xyz:Net' is a plugin that is not registered",
        ),
        "model_other_kind": ({"model": "social_gru"}, "unknown social_gru config keys ['noise_dim']"),
        # social_lstm_eth's grid-pooled net under the kind without pooling
        "model_vanilla_pooled": (
            {"model": "vanilla_lstm"},
            "\"net\": pooling 'grid' is not a vanilla_lstm: the kind is defined by pooling 'none'",
        ),
        "name_dict": ({"name": {"a": 1}}, '"name" must be a string'),
        "format": ({"format": "other"}, "not a crowdmpc predictor config"),
    }


@pytest.mark.parametrize("case", sorted(_config_cases()))
def test_bad_configs_are_refused_naming_the_file_before_a_net_is_built(
    pair, zoo_dir, monkeypatch, capsys, case
):
    weights, config = pair
    changes, message = _config_cases()[case]
    document = json.loads(config.read_text())
    for key, value in changes.items():
        document[key] = {**document[key], **value} if key == "net" and isinstance(value, dict) else value
    config.write_text(json.dumps(document))  # NaN and Infinity as JSON's common extension, as Python reads it

    def no_net(*args, **kwargs):
        raise AssertionError("a net was built from a bad config")

    monkeypatch.setattr(SocialLSTM, "__init__", no_net)
    with pytest.raises(PredictorError) as refused:
        checkpoint.load_checkpoint(weights)
    text = str(refused.value)
    assert text.startswith(f"{config}: ") and message in text and "\n" not in text
    code, line = cli(["zoo", "add", str(weights)], capsys)
    assert code == 2 and line.startswith(f"crowdmpc zoo add: error: {config}: ") and message in line


def test_a_sparse_tensor_in_the_weights_is_refused(pair):
    weights, _ = pair
    state = torch.load(weights, weights_only=True)
    state["head.bias"] = state["head.bias"].to_sparse()
    torch.save(state, weights)
    with pytest.raises(PredictorError, match="'head.bias' is a Tensor, not a dense tensor"):
        checkpoint.load_checkpoint(weights)


def test_a_folder_in_place_of_a_document_is_named(tmp_path):
    (tmp_path / "manifest.json").mkdir()
    with pytest.raises(PredictorError, match="manifest.json: not a regular file"):
        checkpoint.read_document(tmp_path / "manifest.json", "crowdmpc-zoo", "zoo manifest")


def test_obs_len_bounds_are_inclusive(pair):
    weights, config = pair
    document = json.loads(config.read_text())
    config.write_text(json.dumps({**document, "obs_len": checkpoint.MAX_OBS_LEN}))
    assert checkpoint.load_checkpoint(weights).obs_len == 100  # 2..100 includes 100


def test_a_config_over_the_size_cap_is_refused_before_it_is_read(pair):
    weights, config = pair
    with config.open("r+b") as handle:  # sparse: no 64 MiB written
        handle.truncate(checkpoint.MAX_DOCUMENT_BYTES + 1)
    with pytest.raises(PredictorError) as refused:
        checkpoint.load_checkpoint(weights)
    assert str(refused.value) == (
        f"{config}: {checkpoint.MAX_DOCUMENT_BYTES + 1} bytes, more than the {checkpoint.MAX_DOCUMENT_BYTES} "
        "a crowdmpc predictor config may have"
    )


@pytest.mark.parametrize(
    "content, message",
    [
        (b"\xff\xfe{}", "not valid JSON (not UTF-8 text)"),
        (b"[" * 100_000, "not valid JSON"),
        (b'{"obs_len": ' + b"9" * 5000 + b"}", "not valid JSON"),
        (b"{", "not valid JSON"),
    ],
)
def test_unreadable_configs_are_one_line_errors(pair, content, message):
    weights, config = pair
    config.write_bytes(content)
    with pytest.raises(PredictorError) as refused:
        checkpoint.load_checkpoint(weights)
    assert str(refused.value).startswith(f"{config}: {message}") and "\n" not in str(refused.value)


def test_config_bounds_refuse_nothing_real_and_count_parameters_exactly():
    for config in [
        SocialLSTMConfig(pooling="none"),
        SocialLSTMConfig(pooling="grid", head="point"),
        SocialLSTMConfig(pooling="soft"),
        generator_config(),
        SocialLSTMConfig(hidden_dim=128, embedding_dim=64, grid_size=12, latent_dim=16, pool_dim=256),
    ]:
        assert config.parameter_count() == sum(p.numel() for p in SocialLSTM(config).parameters())
    with pytest.raises(PredictorError, match="discriminator hidden_dim must be an integer in 1..4096"):
        DiscriminatorConfig(hidden_dim=10**9)
    with pytest.raises(PredictorError, match="discriminator input_scale must be a number"):
        DiscriminatorConfig(input_scale=float("nan"))


# ------------------------------------------------------------------------------------------- manifests
@pytest.mark.parametrize("kind", ["directory", "dangling_link", "fifo"])
def test_a_manifest_that_is_not_a_regular_file_is_refused(zoo_dir, capsys, kind):
    manifest = zoo_dir / zoo.MANIFEST_NAME
    manifest.unlink()
    if kind == "directory":
        manifest.mkdir()
    elif kind == "dangling_link":
        manifest.symlink_to(zoo_dir / "nowhere.json")
    else:
        os.mkfifo(manifest)  # reading it would block forever
    with pytest.raises(
        PredictorError, match=f"^{re.escape(str(manifest))}: the zoo manifest is not a regular file$"
    ):
        zoo.read_manifest(zoo_dir)
    for args in (["zoo", "verify"], ["zoo", "list"]):
        code, line = cli(args, capsys)
        assert (
            code == 2
            and line == f"crowdmpc zoo {args[1]}: error: {manifest}: the zoo manifest is not a regular file"
        )


def test_an_absent_manifest_is_still_an_empty_zoo(zoo_dir, capsys):
    (zoo_dir / zoo.MANIFEST_NAME).unlink()
    assert zoo.read_manifest(zoo_dir) == {}
    assert main(["zoo", "verify"]) == 0
    assert "0 of 0 entries ok" in capsys.readouterr().out


@pytest.mark.parametrize(
    "change, message",
    [
        ({"metrics": [1]}, '"metrics" must be a JSON object'),
        ({"training": "x"}, '"training" must be a JSON object'),
        ({"training_data": None}, '"training_data" must be a JSON object'),
        ({"protocol": 3}, '"protocol" must be a string'),
        ({"class": None}, '"class" must be a string'),
        ({"file": 3}, '"file" must be a file name inside the zoo'),
        ({"config": "a\x00b"}, '"config" must be a file name inside the zoo'),
    ],
)
def test_manifest_values_of_the_wrong_type_are_refused(zoo_dir, capsys, change, message):
    manifest = write_manifest(zoo_dir, {**real_entry(), **change})
    with pytest.raises(PredictorError) as refused:
        zoo.read_manifest(zoo_dir)
    assert str(refused.value).startswith(f"{manifest}: entry {NAME!r}: ") and message in str(refused.value)
    code, line = cli(["zoo", "show", NAME], capsys)
    assert code == 2 and message in line


def test_a_non_utf8_manifest_is_a_one_line_error(zoo_dir, capsys):
    manifest = zoo_dir / zoo.MANIFEST_NAME
    manifest.write_bytes(b"\xff\xfe")
    code, line = cli(["zoo", "verify"], capsys)
    assert code == 2 and line == f"crowdmpc zoo verify: error: {manifest}: not valid JSON (not UTF-8 text)"


def test_zoo_list_shows_junk_metrics_as_question_marks(zoo_dir, capsys):
    write_manifest(zoo_dir, {**real_entry(), "metrics": {"val": [1], "test": {"ade": "x", "topk_ade": {}}}})
    assert main(["zoo", "list"]) == 0
    row = capsys.readouterr().out.splitlines()[2].split()
    assert row[0] == NAME and row[5:9] == ["-", "-", "?", "-"] and row[9] == "?/-"


def test_zoo_list_cuts_a_manifests_long_or_unprintable_text_and_show_keeps_it(zoo_dir, capsys):
    """A hand-edited kind of 100,000 characters made every line of `zoo list` 100,000 characters wide (as
    `zoo verify`'s line was): each cell of the manifest's own text is cut as messages cut a file's values,
    and one holding a line break is shown escaped, not split over two rows. `zoo show` prints the entry as
    JSON, the data as stored, which scripts read: whole."""
    long = "x" * 100_000
    edited = {**real_entry(), "model": long, "class": "C" * 200, "protocol": "one\ntwo"}
    write_manifest(zoo_dir, {**edited, "training": {**edited["training"], "size_kb": [1] * 1000}})
    assert main(["zoo", "list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert max(map(len, out)) < 400 and len(out) == 4  # header, rule, the row, the metrics note
    row = out[2].split("  ")
    cells = [cell.strip() for cell in row if cell.strip()]
    assert cells[:3] == [NAME, "C" * 57 + "...", "x" * 57 + "..."]  # an unknown kind: its "class"
    assert "'one\\ntwo'" in cells and str([1] * 1000)[:57] + "..." in cells

    write_manifest(zoo_dir, {**real_entry(), "model": "m" * 60})  # as long as a cell shows: whole
    assert main(["zoo", "list"]) == 0
    assert "m" * 60 + "  " in capsys.readouterr().out

    write_manifest(zoo_dir, edited)
    assert main(["zoo", "show", NAME]) == 0
    assert json.loads(capsys.readouterr().out) == {**edited, "zoo": "user"}


@pytest.mark.parametrize("summary", [{"training": "x"}, {"metrics": [1]}, {"name": 5}, {"protocol": 3}])
def test_zoo_add_refuses_a_bad_metrics_file_before_writing(tmp_path, zoo_dir, pair, capsys, summary):
    (pair[0].with_suffix(".metrics.json")).write_text(json.dumps(summary))
    before = tree(tmp_path)
    code, line = cli(["zoo", "add", str(pair[0])], capsys)
    assert code == 2 and line.startswith("crowdmpc zoo add: error: ")
    assert tree(tmp_path) == before


def test_zoo_add_refuses_a_metrics_file_that_names_a_key_twice(tmp_path, zoo_dir, pair, capsys):
    """json kept the last of a key given twice: a metrics file edited to '"protocol": "paper"' above the
    one there added the entry as the other, where every other JSON file a user edits is refused so."""
    metrics = pair[0].with_suffix(".metrics.json")
    metrics.write_text('{"protocol": "paper", "protocol": "custom"}')
    before = tree(tmp_path)
    code, line = cli(["zoo", "add", str(pair[0])], capsys)
    assert (code, line) == (
        2,
        f"crowdmpc zoo add: error: {metrics}: the key 'protocol' appears twice in one object; give each key "
        "once (json would keep the last)",
    )
    assert tree(tmp_path) == before


@pytest.mark.parametrize("where", ["/dev/zero", "folder"])
def test_zoo_add_names_a_metrics_path_that_is_no_file_as_such(tmp_path, zoo_dir, pair, capsys, where):
    """`--metrics /dev/zero` (or a folder) was refused as "does not exist", which it does."""
    metrics = Path(where) if where.startswith("/") else tmp_path
    before = tree(zoo_dir)
    code, line = cli(["zoo", "add", str(pair[0]), "--metrics", str(metrics)], capsys)
    assert (code, line) == (
        2,
        f"crowdmpc zoo add: error: {metrics} is not a file; pass --metrics FILE (written by "
        f"`crowdmpc train`)",
    )
    assert tree(zoo_dir) == before


@pytest.mark.parametrize(
    ("key", "shown"),
    [
        ("obs_lenn", "'obs_lenn'"),
        ("Net", "'Net'"),
        # a Cyrillic 'о' read 'obs_len' beside the same name listed as allowed; a long key flooded the line
        ("\u043ebs_len", "'\\u043ebs_len'"),
        ("k" * 100_000, "'" + "k" * 56 + "..."),
    ],
    ids=["misspelt", "case", "look-alike", "long"],
)
def test_zoo_add_refuses_a_config_key_train_never_writes(tmp_path, zoo_dir, pair, capsys, key, shown):
    """A misspelt key ("obs_lenn": 8) was added and ignored, so the entry ran as if it were absent."""
    document = json.loads(pair[1].read_text())
    pair[1].write_text(json.dumps({**document, key: 8}))
    before = tree(tmp_path)
    code, line = cli(["zoo", "add", str(pair[0])], capsys)
    assert (code, line) == (
        2,
        f"crowdmpc zoo add: error: {pair[1]}: unknown key {shown}; a predictor config holds "
        "['class', 'format', 'model', 'name', 'net', 'obs_len', 'training']",
    )
    assert tree(tmp_path) == before


# ---------------------------------------------------------------------------------------------- export
@pytest.mark.parametrize(
    "option, value", [("--horizon", 100_000), ("--horizon", 0), ("--horizon", 101), ("--humans", 10**6)]
)
def test_export_sizes_are_bounded_and_checked_before_any_work(
    tmp_path, zoo_dir, monkeypatch, capsys, option, value
):
    import predictors.registry

    def no_load(name):
        raise AssertionError("a predictor was loaded before the options were checked")

    monkeypatch.setattr(predictors.registry, "load_predictor", no_load)
    out = tmp_path / "o.casadi"
    code, line = cli(["export", NAME, "--out", str(out), option, str(value)], capsys)
    assert code == 2
    got = f"7, 3, {value}" if option == "--horizon" else f"{value}, 3, 4"
    assert line == (
        "crowdmpc export: error: need --humans in 1..50, --robots in 0..12, --horizon in 1..100, got " + got
    )
    assert not out.exists()


def test_export_to_a_place_it_cannot_write_is_refused_before_any_work(tmp_path, zoo_dir, monkeypatch, capsys):
    import predictors.registry

    def no_load(name):
        raise AssertionError("a predictor was loaded before --out was checked")

    monkeypatch.setattr(predictors.registry, "load_predictor", no_load)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    code, line = cli(["export", NAME, "--out", str(blocker / "o.casadi")], capsys)
    assert (code, line) == (
        2,
        f"crowdmpc export: error: --out {blocker / 'o.casadi'}: {blocker} is not a directory",
    )


def test_export_at_the_horizon_bound_works(tmp_path, zoo_dir):
    out = tmp_path / "o.casadi"
    assert main(["export", "constant_velocity", "--out", str(out), "--horizon", "100"]) == 0
    f = casadi.Function.load(str(out))
    assert (f.size1_in(0), f.size1_in(1), f.size1_out(0)) == (4 * 7, 100 * 3 * 2, 100 * 7 * 2)
    # 7 humans (the default), human i at (i, 0) m walking (i, -1) m/s
    pos = np.array([[float(i), 0.0] for i in range(7)])
    vel = np.array([[float(i), -1.0] for i in range(7)])
    got = np.asarray(f(np.concatenate([pos.ravel(), vel.ravel()]), np.zeros(600))).reshape(100, 7, 2)
    # position + (h + 1) tau velocity, tau = 0.4 s: after 100 steps (40 s) human 2 is at (2 + 80, -40)
    np.testing.assert_allclose(got[99, 2], [82.0, -40.0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[0, 6], [6.0 + 2.4, -0.4], rtol=0, atol=1e-12)
    steps = 0.4 * np.arange(1, 101)[:, None, None]
    np.testing.assert_allclose(got, pos[None] + steps * vel[None], rtol=0, atol=1e-9)


def test_adding_the_same_pair_again_rewrites_a_damaged_copy(pair, tmp_path, monkeypatch, capsys):
    """Adding the same weights twice changes nothing, but a zoo copy damaged since was left damaged ("nothing
    changed", exit 0) while `zoo verify` reported the sha256 mismatch; it is now written again."""
    weights, _ = pair
    root = tmp_path / "fresh"
    (tmp_path / "shipped").mkdir()
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(tmp_path / "shipped"))
    monkeypatch.setenv(zoo.ZOO_ENV, str(root))
    assert main(["zoo", "add", str(weights)]) == 0
    assert main(["zoo", "add", str(weights)]) == 0
    assert "with these weights" in capsys.readouterr().out.splitlines()[-1]
    (root / f"{NAME}.pt").write_bytes((root / f"{NAME}.pt").read_bytes()[:100])  # truncated
    assert main(["zoo", "add", str(weights)]) == 0
    assert (
        capsys.readouterr()
        .out.strip()
        .endswith("was damaged; wrote it again (sha256 " + (zoo.read_manifest(root)[NAME].sha256[:12] + "…)"))
    )
    assert (root / f"{NAME}.pt").read_bytes() == weights.read_bytes()
    assert main(["zoo", "verify"]) == 0


def test_a_plain_pickle_in_place_of_the_weights_is_refused_without_torchs_advice(tmp_path):
    """torch's UserWarning on the pickle's protocol ("please file an issue ...") was printed with its source
    line before the one-line refusal."""
    import pickle
    import warnings

    weights = tmp_path / f"{NAME}.pt"
    weights.write_bytes(pickle.dumps(os.getcwd, protocol=4))  # a function, by reference: never loaded
    shutil.copyfile(REAL_ZOO / f"{NAME}.json", tmp_path / f"{NAME}.json")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with pytest.raises(PredictorError, match="not a state_dict of tensors"):
            checkpoint.load_checkpoint(weights)
    assert [str(w.message) for w in shown] == []


def test_a_damaged_user_manifest_stops_no_run_that_loads_no_zoo_model(tmp_path, monkeypatch, capsys):
    """A sweep of constant velocity and ORCA, and simulate with constant velocity, failed on the user zoo's
    manifest.json, which they never need; a run of a zoo model still names it."""
    user = tmp_path / "zoo"
    user.mkdir()
    (user / "manifest.json").write_text("{")
    monkeypatch.setenv(zoo.ZOO_ENV, str(user))
    sweep = ["sweep", "--experiment", "baselines", "--humans", "2", "--dry-run", "--out", str(tmp_path / "s")]
    assert main(sweep) == 0
    simulate = ["simulate", "--controller", "cmpc", "--humans", "2", "--no-progress"]
    assert main([*simulate, "--predictor", "constant_velocity"]) == 0
    capsys.readouterr()
    assert main([*simulate, "--predictor", "my_model"]) == 2  # looked for in the user zoo
    assert f"{user / 'manifest.json'}: not valid JSON" in capsys.readouterr().err
