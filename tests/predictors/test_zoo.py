"""The two zoos: the shipped one (read-only) and the user's (``$CROWDMPC_ZOO``, where ``zoo add`` writes),
checkpoints of any registered model kind, plugins included, and malformed manifests.

The shipped zoo of these tests is a copy of one real entry in tmp_path; checkpoints/ is only read.
"""

from __future__ import annotations

import hashlib
import json
import pwd
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from pipelines.cli import main
from predictors import checkpoint, manifest, models, zoo, zoo_edit
from predictors.errors import PredictorError, UnknownPredictor
from predictors.learned import LearnedPredictor
from predictors.models import load_plugin
from predictors.registry import available, checkpoint_sha256, load_predictor
from predictors.social_lstm_predictors import SocialGANPredictor
from predictors.zoo import ZOO_ENV, read_manifest, user_zoo_dir
from tests.cli_calls import one_line
from tests.predictors.test_models import check_sampling

REAL_ZOO = Path(__file__).resolve().parents[2] / "checkpoints"
NAME = "social_lstm_eth"
TOY = "tests.plugins.toy_predictor:ToyNet"


@pytest.mark.parametrize(
    ("models_", "message"),
    [({"a": 1}, '"models" must be a list'), ([1], "a zoo entry must be a JSON object, got 1")],
)
def test_malformed_manifest_is_a_predictor_error(tmp_path, models_, message):
    (tmp_path / "manifest.json").write_text(json.dumps({"format": "crowdmpc-zoo", "models": models_}))
    with pytest.raises(PredictorError, match=message):
        read_manifest(tmp_path)


# ------------------------------------------------------------------------------------------------ fixtures
def real_entry(name: str = NAME) -> dict:
    document = json.loads((REAL_ZOO / zoo.MANIFEST_NAME).read_text())
    return next(e for e in document["models"] if e["name"] == name)


def write_manifest(root: Path, *entries: dict) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    path = root / zoo.MANIFEST_NAME
    path.write_text(json.dumps({"format": manifest.MANIFEST_FORMAT, "version": 1, "models": list(entries)}))
    return path


def snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` and its sha256: what "untouched" means."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


@pytest.fixture
def shipped(tmp_path, monkeypatch) -> Path:
    """A shipped zoo holding a copy of the real entry ``NAME``."""
    root = tmp_path / "shipped"
    root.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", root / f"{NAME}{suffix}")
    write_manifest(root, real_entry())
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(root))
    return root


@pytest.fixture
def user(tmp_path, monkeypatch) -> Path:
    root = tmp_path / "user"  # not created: `zoo add` makes it
    monkeypatch.setenv(ZOO_ENV, str(root))
    return root


@pytest.fixture
def pair(tmp_path) -> Path:
    """A copy of the real checkpoint pair outside any zoo, with the metrics file `zoo add` reads."""
    src = tmp_path / "src"
    src.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", src / f"{NAME}{suffix}")
    (src / f"{NAME}.metrics.json").write_text(json.dumps({"metrics": {"test": {"ade": 0.5}}}))
    return src / f"{NAME}.pt"


def cli(args: list[str], capsys) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# ------------------------------------------------------------------------------------------- where it is
def test_the_user_zoo_defaults_to_the_users_data_directory(tmp_path, monkeypatch):
    monkeypatch.delenv(ZOO_ENV)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert user_zoo_dir() == tmp_path / "xdg" / "crowdmpc" / "zoo"
    monkeypatch.setenv("XDG_DATA_HOME", "relative/data")  # ignored, as the XDG spec says
    assert user_zoo_dir() == tmp_path / "home" / ".local" / "share" / "crowdmpc" / "zoo"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert user_zoo_dir() == tmp_path / "home" / ".local" / "share" / "crowdmpc" / "zoo"
    monkeypatch.setenv(ZOO_ENV, str(tmp_path / "mine"))
    assert user_zoo_dir() == tmp_path / "mine" and user_zoo_dir(tmp_path / "x") == tmp_path / "x"


@pytest.mark.parametrize("home", ["", "relative/home"])
def test_a_home_that_is_no_absolute_path_is_passed_over_as_none(tmp_path, monkeypatch, home):
    """An empty $HOME made the user zoo /.local/share/crowdmpc/zoo, a relative one a folder of the current
    directory: the password database's home is taken, as when $HOME is unset."""
    monkeypatch.delenv(ZOO_ENV)
    monkeypatch.delenv("XDG_DATA_HOME", raising=False)
    monkeypatch.setenv("HOME", home)
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=str(tmp_path / "pw")))
    assert user_zoo_dir() == tmp_path / "pw" / ".local" / "share" / "crowdmpc" / "zoo"
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=""))
    with pytest.raises(PredictorError) as refused:
        user_zoo_dir()
    assert str(refused.value) == (
        "cannot find the home directory for the user zoo (no absolute $HOME, and none in the password "
        f"database); set ${ZOO_ENV}"
    )


def test_a_zoo_variable_starting_with_a_tilde_names_the_home(tmp_path, monkeypatch):
    """As $CROWDMPC_DATA and $CROWDMPC_CACHE do: a quoted CROWDMPC_ZOO="~/zoo" made a folder "~" here."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv(ZOO_ENV, "~/zoo")
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, "~")
    assert user_zoo_dir() == tmp_path / "home" / "zoo"
    assert zoo.checkpoints_dir() == tmp_path / "home"
    monkeypatch.setenv(ZOO_ENV, "~no-such-user-here/zoo")
    with pytest.raises(PredictorError) as refused:
        user_zoo_dir()
    assert str(refused.value) == (
        f"${ZOO_ENV} ~no-such-user-here/zoo: no user 'no-such-user-here' here, "
        "so ~no-such-user-here names no home"
    )


# ---------------------------------------------------------------------------------------- add, see, remove
def test_add_writes_the_user_zoo_and_every_command_sees_both(shipped, user, pair, capsys):
    before = snapshot(shipped)
    code, out, _ = cli(["zoo", "add", str(pair), "--name", "mine"], capsys)
    assert code == 0 and f"to the user zoo {user}" in out
    assert snapshot(shipped) == before
    assert {"mine.pt", "mine.json", zoo.MANIFEST_NAME, manifest.LOCK_NAME} == set(snapshot(user))

    assert {NAME, "mine"} <= set(available())
    assert load_predictor("mine").name == "mine" and load_predictor(NAME).name == NAME
    assert checkpoint_sha256("mine") == hashlib.sha256((user / "mine.pt").read_bytes()).hexdigest()
    assert checkpoint_sha256(NAME) == real_entry()["sha256"]
    assert zoo.zoo_names() == sorted([NAME, "mine"]) and zoo.zoo_names(user) == ["mine"]

    code, out, _ = cli(["zoo", "list"], capsys)
    rows = [line.split() for line in out.splitlines()[2:4]]
    assert code == 0 and [(r[0], r[-1]) for r in rows] == [(NAME, "shipped"), ("mine", "user")]
    code, out, _ = cli(["zoo", "show", "mine"], capsys)
    assert code == 0 and json.loads(out)["zoo"] == "user"
    code, out, _ = cli(["zoo", "verify"], capsys)
    assert code == 0 and f"{NAME}: ok\nmine (user): ok\n2 of 2 entries ok\n" == out

    code, out, _ = cli(["zoo", "remove", "mine"], capsys)
    assert code == 0 and out == f"removed mine from the user zoo {user}\n"
    assert set(snapshot(user)) == {zoo.MANIFEST_NAME, manifest.LOCK_NAME} and zoo.zoo_names(user) == []
    with pytest.raises(UnknownPredictor):
        load_predictor("mine")
    assert snapshot(shipped) == before


def test_a_user_model_may_not_take_a_shipped_name(shipped, user, pair, capsys):
    before = snapshot(shipped)
    code, _, err = cli(["zoo", "add", str(pair)], capsys)  # its own name, social_lstm_eth, is shipped
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo add: error: zoo name {NAME!r} is taken by a model of the shipped zoo {shipped}; "
        "pick another name (--name)"
    )
    assert not user.exists() and snapshot(shipped) == before


def test_trains_zoo_hint_is_a_command_zoo_add_takes(shipped, user, pair, capsys):
    """`crowdmpc train` closes with `crowdmpc zoo add OUT/NAME.pt`; with the default --out, NAME is the
    shipped model's (social_lstm_eth), which `zoo add` refuses. The hint names a free --name then."""
    import shlex

    from pipelines.commands.train_report import print_summary

    summary = {"name": NAME, "model": "social_lstm", "metrics": {}, "training": {"median_epoch_time_s": 1.0}}
    capsys.readouterr()
    print_summary(summary, "best.ckpt", pair, None)
    command = capsys.readouterr().out.split("`")[1]
    assert command == f"crowdmpc zoo add {pair} --name my_{NAME}"
    code, out, err = cli(shlex.split(command)[1:], capsys)
    assert code == 0 and f"added my_{NAME} " in out, err
    print_summary(summary, "best.ckpt", pair, None)  # a second run's hint: my_NAME is the user zoo's now
    assert capsys.readouterr().out.split("`")[1] == f"crowdmpc zoo add {pair} --name my_{NAME}_2"

    mine = pair.with_name("mine.pt")  # a name of its own: the hint is the bare command
    print_summary({**summary, "name": "mine"}, "best.ckpt", mine, None)
    assert capsys.readouterr().out.split("`")[1] == f"crowdmpc zoo add {mine}"


def test_trains_zoo_hint_for_a_name_the_user_zoo_holds_is_a_command_zoo_add_takes(
    shipped, user, pair, capsys
):
    """A model trained again (or resumed) under the name its user zoo entry has: the hint was the bare `zoo
    add OUT/mine.pt`, which `zoo add` refused (the zoo has 'mine'). It names a free --name now, and says how
    to replace the entry on purpose (--replace), each a command `zoo add` takes."""
    import shlex

    from pipelines.commands.train_report import print_summary

    for suffix in (".pt", ".json", ".metrics.json"):
        shutil.copyfile(pair.with_name(f"{NAME}{suffix}"), pair.with_name(f"mine{suffix}"))
    mine = pair.with_name("mine.pt")
    assert cli(["zoo", "add", str(mine)], capsys)[0] == 0
    summary = {
        "name": "mine",
        "model": "social_lstm",
        "metrics": {},
        "training": {"median_epoch_time_s": 1.0},
    }
    capsys.readouterr()
    print_summary(summary, "best.ckpt", mine, None)
    hint = capsys.readouterr().out
    add, replace = hint.split("`")[1], hint.split("`")[3]
    assert add == f"crowdmpc zoo add {mine} --name mine_2"
    assert replace == f"crowdmpc zoo add {mine} --replace" and "your zoo holds mine already" in hint
    code, out, err = cli(shlex.split(replace)[1:], capsys)
    assert code == 0 and "nothing changed" in out, err  # the same weights: a no-op, not a refusal
    code, out, err = cli(shlex.split(add)[1:], capsys)
    assert code == 0 and "added mine_2 " in out, err
    print_summary(summary, "best.ckpt", mine, None)  # mine_2 is the zoo's now
    assert capsys.readouterr().out.split("`")[1] == f"crowdmpc zoo add {mine} --name mine_3"


@pytest.mark.parametrize("where", ["env", "env_inside", "env_symlink", "dir_option"])
def test_the_shipped_zoo_is_read_only(tmp_path, shipped, pair, monkeypatch, capsys, where):
    before = snapshot(shipped)
    target = {"env": shipped, "env_inside": shipped / "sub", "dir_option": shipped}.get(
        where, tmp_path / "link"
    )
    if where == "env_symlink":
        target.symlink_to(shipped)
    options = ["--dir", str(target)] if where == "dir_option" else []
    if where != "dir_option":
        monkeypatch.setenv(ZOO_ENV, str(target))
    for action in (["add", str(pair), "--name", "other"], ["remove", NAME]):
        code, _, err = cli(["zoo", *options, *action], capsys)
        line = one_line(err)
        assert (
            code == 2 and f"{target} is the shipped zoo {shipped} (or inside it), which is read-only" in line
        )
    assert snapshot(shipped) == before
    with pytest.raises(PredictorError, match="which is read-only"):
        zoo_edit.add_to_zoo(pair, name="other", protocol="p", training_data={}, metrics={}, directory=shipped)
    assert snapshot(shipped) == before


def test_maintainers_add_to_the_shipped_zoo_on_purpose_only(shipped, user, pair):
    entry = zoo_edit.add_to_zoo(pair, name="other", protocol="p", training_data={}, metrics={}, shipped=True)
    assert (shipped / "other.pt").is_file() and zoo.locate("other").source == zoo.SHIPPED == "shipped"
    assert entry.name in read_manifest(shipped) and not user.exists()


def test_a_user_zoo_that_is_a_file_is_refused(user, pair, capsys):
    user.write_text("not a directory")
    code, _, err = cli(["zoo", "add", str(pair), "--name", "other"], capsys)
    assert code == 2 and one_line(err) == f"crowdmpc zoo add: error: the user zoo {user} is not a directory"


def test_the_real_shipped_zoo_is_never_written(pair, monkeypatch, capsys):
    monkeypatch.delenv(zoo.CHECKPOINTS_ENV, raising=False)
    monkeypatch.setenv(ZOO_ENV, str(REAL_ZOO))
    manifest = (REAL_ZOO / zoo.MANIFEST_NAME).read_bytes()
    code, _, err = cli(["zoo", "add", str(pair), "--name", "other"], capsys)
    assert code == 2 and "which is read-only" in one_line(err)
    assert (REAL_ZOO / zoo.MANIFEST_NAME).read_bytes() == manifest and not (REAL_ZOO / "other.pt").exists()


def test_remove_refuses_what_the_user_zoo_does_not_have(shipped, user, capsys):
    code, _, err = cli(["zoo", "remove", NAME], capsys)
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo remove: error: {NAME!r} is a model of the shipped zoo {shipped}, which is read-only"
    )
    code, _, err = cli(["zoo", "remove", "nope"], capsys)
    assert (
        code == 2
        and one_line(err) == f"crowdmpc zoo remove: error: the user zoo {user} has no entry 'nope'; it has []"
    )
    code, _, err = cli(["zoo", "remove", "../x"], capsys)
    assert code == 2 and "zoo name '../x' is not allowed" in one_line(err)


def test_zoo_list_shows_the_class_a_model_loads_as_for_either_zoo(shipped, user, pair, capsys):
    """The shipped manifest's "class" predates model kinds: its social_lstm row said SocialLSTMPredictor and
    the same weights added to the user zoo LearnedPredictor, the class both load as."""
    assert real_entry()["class"] == "SocialLSTMPredictor"  # what the shipped manifest records
    assert cli(["zoo", "add", str(pair), "--name", "mine"], capsys)[0] == 0
    code, out, _ = cli(["zoo", "list"], capsys)
    classes = {line.split()[0]: line.split()[1] for line in out.splitlines()[2:4]}
    loaded = type(load_predictor(NAME)).__name__
    assert code == 0 and classes == {NAME: loaded, "mine": loaded} and loaded == "LearnedPredictor"


def test_a_user_entry_under_a_shipped_name_is_reported_and_never_loads(shipped, user, capsys):
    for suffix in (".pt", ".json"):
        user.mkdir(exist_ok=True)
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", user / f"{NAME}{suffix}")
    write_manifest(user, real_entry())  # written by hand: `zoo add` refuses the name
    assert zoo.locate(NAME).source == zoo.SHIPPED
    assert available().count(NAME) == 1
    code, out, _ = cli(["zoo", "verify"], capsys)
    assert code == 1 and f"{NAME} (user): {user / zoo.MANIFEST_NAME}: a shipped model has this name" in out
    code, out, _ = cli(["zoo", "list"], capsys)  # listed without a mark, it read as a model one could use
    rows = [line.split()[:3] for line in out.splitlines() if line.startswith(NAME)]
    assert code == 0 and rows == [
        [NAME, "LearnedPredictor", "social_lstm"],
        [NAME, "!", "LearnedPredictor"],
    ]
    assert f"! {user / zoo.MANIFEST_NAME}: a shipped model has this name, so this entry never loads" in out


def test_a_user_entry_under_a_built_in_predictors_name_is_reported_and_never_loads(shipped, user, capsys):
    """A user entry named constant_velocity (written by hand, or by a version whose add took the name): the
    name loads the built-in, yet verify said ok and show printed the entry as the model of that name."""
    for suffix in (".pt", ".json"):
        user.mkdir(exist_ok=True)
        shutil.copyfile(REAL_ZOO / f"{NAME}{suffix}", user / f"constant_velocity{suffix}")
    entry = {**real_entry(), "name": "constant_velocity"}
    write_manifest(user, {**entry, "file": "constant_velocity.pt", "config": "constant_velocity.json"})
    assert type(load_predictor("constant_velocity")).__name__ == "ConstantVelocity"
    said = (
        f"{user / zoo.MANIFEST_NAME}: the built-in predictor 'constant_velocity' has this name, so this "
        "entry never loads; remove it (`crowdmpc zoo remove constant_velocity`) and add it under another name"
    )
    code, out, _ = cli(["zoo", "verify"], capsys)
    assert code == 1 and f"constant_velocity (user): {said}" in out.splitlines()
    code, out, _ = cli(["zoo", "list"], capsys)
    assert code == 0 and "constant_velocity !" in out and f"! {said}" in out.splitlines()
    code, out, err = cli(["zoo", "show", "constant_velocity"], capsys)
    assert code == 0 and json.loads(out)["zoo"] == "user" and one_line(err) == f"note: {said}"
    (user / zoo.MANIFEST_NAME).unlink()
    code, _, err = cli(["zoo", "show", "orca_oracle"], capsys)  # was "unknown predictor 'orca_oracle'"
    assert code == 2 and one_line(err) == (
        "crowdmpc zoo show: error: 'orca_oracle' is a built-in predictor, with no weights: no zoo holds it"
    )


def test_a_broken_user_manifest_stops_no_shipped_model(shipped, user, capsys):
    user.mkdir()
    (user / zoo.MANIFEST_NAME).write_text("{")
    assert load_predictor(NAME).name == NAME
    code, _, err = cli(["zoo", "list"], capsys)
    assert code == 2 and one_line(err).startswith(
        f"crowdmpc zoo list: error: {user / zoo.MANIFEST_NAME}: not valid JSON"
    )


# ------------------------------------------------------------------------------------ any kind, plugins too
def toy_pair(tmp_path: Path, model: str = TOY) -> Path:
    kind = load_plugin(TOY)
    torch.manual_seed(0)
    weights, _ = checkpoint.save_checkpoint(
        kind.build_net(kind.config({"hidden_dim": 4})),
        model=model,
        name="toy_eth",
        out_dir=tmp_path,
        obs_len=9,
    )
    return weights


def test_a_plugin_model_goes_through_the_user_zoo(tmp_path, shipped, user, monkeypatch):
    weights = toy_pair(tmp_path / "run")
    document = json.loads(weights.with_suffix(".json").read_text())
    assert document["model"] == TOY and document["class"] == "LearnedPredictor"
    assert document["net"] == {"hidden_dim": 4, "radius": 2.0}
    entry = zoo_edit.add_to_zoo(weights, name="toy_eth", protocol="custom", training_data={}, metrics={})
    assert entry.model == TOY and (user / "toy_eth.pt").is_file()
    predictor = load_predictor("toy_eth")
    assert isinstance(predictor, LearnedPredictor) and predictor.kind == TOY and predictor.name == "toy_eth"

    monkeypatch.setattr(models, "_PLUGINS", {})  # a new process, without --plugin
    with pytest.raises(PredictorError) as refused:
        load_predictor("toy_eth")
    assert str(refused.value) == (
        f"predictor 'toy_eth' of the user zoo ({user / 'manifest.json'}): model {TOY!r} is a plugin that is "
        f"not registered; register it with `crowdmpc --plugin {TOY} COMMAND ...` or CROWDMPC_PLUGINS={TOY}"
    )


def test_a_zoo_file_never_imports_a_module(tmp_path, shipped, user):
    weights = toy_pair(tmp_path / "run")
    config = weights.with_suffix(".json")
    never = "tests.plugins.never_imported:Net"
    config.write_text(json.dumps({**json.loads(config.read_text()), "model": never}))
    with pytest.raises(PredictorError, match=f"model {never!r} is a plugin that is not registered"):
        checkpoint.load_checkpoint(weights)
    assert "tests.plugins.never_imported" not in sys.modules


def test_a_shipped_name_in_the_user_zoo_reads_as_the_shipped_entry(shipped, user):
    """The merged listing shows what loads: the shipped entry, not a user entry under the same name."""
    other = {**real_entry(), "metrics": {"test": {"ade": 9.99}}}
    write_manifest(user, other)
    assert read_manifest()[NAME].metrics == real_entry()["metrics"]
    assert [located.source for located in zoo.zoo_entries()] == [zoo.SHIPPED, zoo.USER]


def test_a_user_zoo_set_to_the_shipped_one_is_read_once(shipped, monkeypatch):
    """$CROWDMPC_ZOO at the shipped zoo: one zoo, whose entries shadow nothing (read twice, every entry
    would be listed twice and verified as a user entry under a shipped name)."""
    monkeypatch.setenv(ZOO_ENV, str(shipped))
    assert zoo.zoo_roots() == [(zoo.SHIPPED, shipped)]
    assert [(located.entry.name, problem) for located, problem in zoo.verify_entries()] == [(NAME, None)]


def test_verify_loads_each_entry_of_a_zoo_directory(shipped, user):
    """verify checks the files, not just the manifest: weights that no longer match are named."""
    assert zoo.verify(shipped) == [(NAME, None)]
    (shipped / f"{NAME}.pt").write_bytes((shipped / f"{NAME}.pt").read_bytes() + b"\0")
    [(name, problem)] = zoo.verify(shipped)
    assert name == NAME and problem is not None and "the manifest expects" in problem
    [(located, problem)] = zoo.verify_entries()  # both zoos (the user zoo is empty)
    assert located.entry.name == NAME and problem is not None and "the manifest expects" in problem


@pytest.mark.parametrize(
    "key, value, problem",
    [
        ("model", "vanilla_lstm", "says model 'vanilla_lstm', its config social_lstm_eth.json 'social_lstm'"),
        ("training", {"epochs": 50}, "says training.epochs 50, its config social_lstm_eth.json 25"),
        ("training", {"limit_batches": 3}, None),  # of which the shipped config says nothing
        # a kind of 100,000 characters was printed whole: cut as the other messages cut a file's values
        ("model", "x" * 100_000, f"says model '{'x' * 56}..., its config social_lstm_eth.json 'social_lstm'"),
    ],
    ids=["model", "epochs", "limit_batches", "long-model"],
)
def test_verify_names_a_manifest_entry_that_says_other_than_its_config(shipped, key, value, problem):
    """A manifest edited by hand ("model": another kind, epochs or limit_batches changed to hide a quick
    check) listed one model and ran another, and verify said ok: the config, whose sha256 the entry holds, is
    the pair's truth."""
    entry = real_entry()
    entry[key] = {**entry[key], **value} if key == "training" else value
    write_manifest(shipped, entry)
    said = (
        None
        if problem is None
        else (
            f"{shipped / zoo.MANIFEST_NAME}: entry {NAME!r} {problem} (the manifest edited by hand?); add "
            "the model again with `crowdmpc zoo add --replace`, or restore the manifest"
        )
    )
    assert zoo.verify(shipped) == [(NAME, said)]
    assert [problem for _, problem in zoo.verify_entries()] == [said]


def test_a_saved_pair_reads_back_as_saved(tmp_path):
    """float32 weights whatever the net's dtype (the zoo's files are float32), the observed steps asked for
    (not the default 9), and the name a caller gives over the file's own."""
    kind = load_plugin(TOY)
    torch.manual_seed(0)
    net = kind.build_net(kind.config({"hidden_dim": 4})).double()
    weights, config = checkpoint.save_checkpoint(net, model=TOY, name="toy_eth", out_dir=tmp_path, obs_len=6)
    state = torch.load(weights, weights_only=True)
    assert {t.dtype for t in state.values()} == {torch.float32}
    assert json.loads(config.read_text())["obs_len"] == 6
    predictor = checkpoint.load_checkpoint(weights)
    assert (predictor.obs_len, predictor.name) == (6, "toy_eth")
    assert checkpoint.load_checkpoint(weights, name="renamed").name == "renamed"


def test_a_saved_gan_reads_back_as_a_gan_also_as_a_legacy_config(tmp_path):
    """The config names the GAN's class (load refuses a GAN kind under another class) and keeps what the
    caller adds (training); a config from before "model" and "name" reads by its class and file name."""
    kind = models.model_kind("social_gan")
    net_config = json.loads((REAL_ZOO / "social_gan_eth.json").read_text())["net"]
    weights, config = checkpoint.save_checkpoint(
        kind.build_net(net_config),
        model="social_gan",
        name="gan",
        out_dir=tmp_path,
        obs_len=9,
        extra={"training": {"epochs": 1}},
    )
    document = json.loads(config.read_text())
    assert (document["class"], document["training"]) == ("SocialGANPredictor", {"epochs": 1})
    assert isinstance(checkpoint.load_checkpoint(weights), SocialGANPredictor)
    legacy = {k: v for k, v in document.items() if k not in ("model", "name")}
    config.write_text(json.dumps(legacy))
    predictor = checkpoint.load_checkpoint(weights)
    assert isinstance(predictor, SocialGANPredictor) and predictor.name == "gan"  # NAME.pt's NAME


def test_save_checkpoint_refuses_what_it_cannot_reload(tmp_path):
    kind = load_plugin(TOY)
    net = kind.build_net(kind.config())
    with pytest.raises(PredictorError, match="unknown model 'nope'"):
        checkpoint.save_checkpoint(net, model="nope", name="x", out_dir=tmp_path, obs_len=9)
    with pytest.raises(PredictorError, match="model 'social_lstm' is a SocialLSTM, got a ToyNet"):
        checkpoint.save_checkpoint(net, model="social_lstm", name="x", out_dir=tmp_path, obs_len=9)
    with pytest.raises(PredictorError, match="checkpoint name '../x' is not allowed"):
        checkpoint.save_checkpoint(net, model=TOY, name="../x", out_dir=tmp_path, obs_len=9)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "name, kind, cls",
    [
        ("social_lstm_eth", "social_lstm", LearnedPredictor),
        ("vanilla_lstm_eth", "vanilla_lstm", LearnedPredictor),
    ],
)
def test_configs_from_before_model_kinds_still_load(tmp_path, name, kind, cls):
    for suffix in (".pt", ".json"):
        shutil.copyfile(REAL_ZOO / f"{name}{suffix}", tmp_path / f"{name}{suffix}")
    config = tmp_path / f"{name}.json"
    document = json.loads(config.read_text())
    del document["model"]  # the class and the pooling say which kind it is
    config.write_text(json.dumps(document))
    predictor = checkpoint.load_checkpoint(tmp_path / f"{name}.pt")
    assert isinstance(predictor, cls) and predictor.kind == kind
    del document["class"]
    config.write_text(json.dumps(document))
    with pytest.raises(PredictorError, match='"model" is missing'):
        checkpoint.load_checkpoint(tmp_path / f"{name}.pt")


def test_the_shipped_gan_loads_as_a_sampling_predictor():
    predictor = zoo.load_zoo("social_gan_eth", REAL_ZOO)
    assert isinstance(predictor, SocialGANPredictor) and predictor.kind == "social_gan"
    check_sampling(predictor)


# ------------------------------------------------------- taken names, another run's metrics, shipped kinds
def retrained(pair: Path, stem: str, config_name: str | None = None) -> Path:
    """``stem.pt``/``stem.json`` beside ``pair``: other weights (one value changed), the config naming
    ``config_name`` (default ``stem``), as `crowdmpc train` writes it, and the pair's metrics."""
    state = torch.load(pair, weights_only=True)
    key = next(iter(state))
    state[key] = state[key] + 0.5
    weights = pair.with_name(f"{stem}.pt")
    torch.save(state, weights)
    document = json.loads(pair.with_suffix(".json").read_text())
    weights.with_suffix(".json").write_text(json.dumps({**document, "name": config_name or stem}))
    shutil.copyfile(pair.with_suffix(".metrics.json"), weights.with_suffix(".metrics.json"))
    return weights


def test_adding_a_taken_name_is_refused_unless_replace(shipped, user, pair, capsys):
    assert cli(["zoo", "add", str(pair), "--name", "mine"], capsys)[0] == 0
    first = read_manifest(user)["mine"]
    before = snapshot(user)
    other = retrained(pair, "other")
    code, _, err = cli(["zoo", "add", str(other), "--name", "mine"], capsys)
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo add: error: the user zoo {user} already has 'mine': sha256 "
        f"{first.sha256[:12]}…, model "
        "social_lstm; add it with --replace to replace that entry, or under another --name"
    )
    assert snapshot(user) == before

    code, out, _ = cli(["zoo", "add", str(pair), "--name", "mine"], capsys)  # the very same model again
    assert code == 0 and out == (
        f"mine is already in the user zoo {user} with these weights (sha256 {first.sha256[:12]}…); "
        "nothing changed\n"
    )
    assert snapshot(user) == before

    code, out, _ = cli(["zoo", "add", str(other), "--name", "mine", "--replace"], capsys)
    new = read_manifest(user)["mine"]
    assert code == 0 and out.startswith(f"replaced mine (was sha256 {first.sha256[:12]}…, model social_lstm)")
    assert new.sha256 == hashlib.sha256(other.read_bytes()).hexdigest() != first.sha256
    assert set(read_manifest(user)) == {"mine"} and load_predictor("mine").name == "mine"


def test_replacing_an_entry_with_the_very_same_files_changes_nothing(shipped, user, pair, capsys):
    """`zoo add --replace` of the weights already there said "replaced mine (was sha256 f932…) with mine.pt
    (sha256 f932…)" and wrote them again, where a plain re-add says nothing changed."""
    assert cli(["zoo", "add", str(pair), "--name", "mine"], capsys)[0] == 0
    first = read_manifest(user)["mine"]
    before = snapshot(user)
    code, out, _ = cli(["zoo", "add", str(pair), "--name", "mine", "--replace"], capsys)
    assert code == 0 and out == (
        f"mine is already in the user zoo {user} with these weights (sha256 {first.sha256[:12]}…); "
        "nothing changed\n"
    )
    assert snapshot(user) == before and read_manifest(user)["mine"] == first


def test_names_that_differ_only_in_case_are_taken(shipped, user, pair, capsys):
    """On a case-insensitive file system Mine.pt is mine.pt: adding it would overwrite mine's weights."""
    assert cli(["zoo", "add", str(pair), "--name", "mine"], capsys)[0] == 0
    before = snapshot(user)
    code, _, err = cli(["zoo", "add", str(retrained(pair, "other")), "--name", "Mine"], capsys)
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo add: error: the user zoo {user} already has 'mine', which is 'Mine' when "
        f"case is ignored "
        "(their files are the same on a case-insensitive file system); add it as --name mine --replace to "
        "replace that entry, or under another --name"
    )
    code, _, err = cli(["zoo", "add", str(pair), "--name", NAME.upper()], capsys)
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo add: error: zoo name {NAME.upper()!r} is taken by a model of the shipped zoo "
        f"{shipped} "
        f"(as {NAME!r}: names are compared ignoring case); pick another name (--name)"
    )
    assert snapshot(user) == before and set(read_manifest(user)) == {"mine"}
    for built_in in ("constant_velocity", "ORCA_Oracle"):  # the name loads the built-in: never the entry
        code, _, err = cli(["zoo", "add", str(pair), "--name", built_in], capsys)
        assert code == 2 and f"zoo name {built_in!r} is the built-in predictor" in err
    assert snapshot(user) == before


def test_the_same_weights_with_other_metrics_are_refused_too(shipped, user, pair, capsys):
    assert cli(["zoo", "add", str(pair), "--name", "mine"], capsys)[0] == 0
    before = snapshot(user)
    pair.with_suffix(".metrics.json").write_text(json.dumps({"metrics": {"test": {"ade": 0.4}}}))
    code, _, err = cli(["zoo", "add", str(pair), "--name", "mine"], capsys)
    assert code == 2 and "(the same weights, with other metrics or settings); add it with --replace" in err
    assert snapshot(user) == before and read_manifest(user)["mine"].metrics == {"test": {"ade": 0.5}}


def run_metrics(pair: Path, name: str, model: str = "social_lstm") -> Path:
    """NAME.metrics.json as `crowdmpc train` writes it beside its checkpoint."""
    path = pair.with_name(f"{name}.metrics.json")
    path.write_text(json.dumps({"name": name, "model": model, "metrics": {"test": {"ade": 0.5}}}))
    return path


def test_the_zoo_name_is_the_checkpoints_not_the_metrics_files(shipped, user, pair, capsys):
    best = retrained(pair, "best", config_name="run1")  # run1's checkpoint, its files renamed
    metrics = run_metrics(pair, "run1")
    code, out, _ = cli(["zoo", "add", str(best), "--metrics", str(metrics)], capsys)
    assert code == 0 and out.startswith("added best (best.pt") and zoo.zoo_names(user) == ["best"]
    assert read_manifest(user)["best"].metrics == {"test": {"ade": 0.5}}


@pytest.mark.parametrize(
    ("metrics_of", "key", "theirs"), [("run1", "name", "'run1'"), ("run2", "model", "'social_gru'")]
)
def test_metrics_of_another_checkpoint_are_refused(shipped, user, pair, capsys, metrics_of, key, theirs):
    for stem in ("run1", "run2"):
        retrained(pair, stem)
    metrics = run_metrics(pair, metrics_of, model="social_gru" if key == "model" else "social_lstm")
    weights = pair.with_name("run2.pt")
    own = "'run2'" if key == "name" else "'social_lstm'"
    code, _, err = cli(["zoo", "add", str(weights), "--metrics", str(metrics), "--name", "mine"], capsys)
    assert code == 2 and one_line(err) == (
        f"crowdmpc zoo add: error: {metrics} holds the metrics of {key} {theirs}, not of {weights} "
        f"({key} {own} "
        "in run2.json); pass the NAME.metrics.json `crowdmpc train` wrote beside these weights"
    )
    assert not user.exists()


def test_the_shipped_zoo_takes_no_plugin_kind(tmp_path, shipped, user, capsys):
    weights = toy_pair(tmp_path / "run")
    weights.with_suffix(".metrics.json").write_text("{}")
    (tmp_path / "pyproject.toml").write_text("")  # the shipped zoo of a clone, as --shipped requires
    before = snapshot(shipped)
    message = (
        f"{weights.with_suffix('.json')}: model {TOY!r} is not a kind this project ships ("
        f"{', '.join(sorted(models.shipped()))}), so the shipped zoo cannot hold it; add it to your user zoo "
        "without --shipped"
    )
    code, _, err = cli(["--plugin", TOY, "zoo", "add", str(weights), "--shipped"], capsys)
    assert code == 2 and one_line(err) == f"crowdmpc zoo add: error: {message}"
    with pytest.raises(PredictorError) as refused:
        zoo_edit.add_to_zoo(weights, name="toy", protocol="p", training_data={}, metrics={}, shipped=True)
    assert str(refused.value) == message
    assert snapshot(shipped) == before and not user.exists()
    code, _, _ = cli(["--plugin", TOY, "zoo", "add", str(weights)], capsys)  # the user zoo takes it
    assert code == 0 and zoo.zoo_names(user) == ["toy_eth"]


def test_an_unknown_predictors_name_is_cut_in_the_message():
    """A name pasted by mistake (a whole file) must not become a 900 kB error line."""
    with pytest.raises(UnknownPredictor) as error:
        load_predictor("x" * 100_000)
    assert len(str(error.value)) < 1000 and "unknown predictor 'xxx" in str(error.value)


@pytest.mark.parametrize("name", ["social_lstm_eth", "social_gan_eth"])
def test_loading_a_model_leaves_torchs_random_numbers_alone(name):
    """A notebook seeds torch for its own work, then loads a zoo model: building the net drew its initial
    weights, which the checkpoint replaces at once, from torch's global generator, so the notebook's next
    random numbers were others than without the load."""
    torch.manual_seed(0)
    expected = torch.rand(3)
    torch.manual_seed(0)
    load_predictor(name)
    assert torch.equal(torch.rand(3), expected)


def test_a_quick_check_is_added_with_a_note_and_listed_with_a_mark(shipped, user, pair, capsys):
    """docs/extending.md: a model trained with --limit-batches "is never mistaken for a trained one"; only
    `zoo show` had said so. The note quotes the name, as simulate's, evaluate's and export's do."""
    metrics = pair.with_suffix(".metrics.json")
    metrics.write_text(json.dumps({"metrics": {"test": {"ade": 0.5}}, "training": {"limit_batches": 10}}))
    code, out, err = cli(["zoo", "add", str(pair), "--name", "quick"], capsys)
    assert code == 0 and out.startswith("added quick")
    assert err == (
        "note: 'quick' trained on 10 batches an epoch (train --limit-batches 10): a quick check, not a "
        "trained model (zoo list: *)\n"
    )
    code, out, _ = cli(["zoo", "list"], capsys)
    lines = out.splitlines()
    assert any(line.startswith("quick *") for line in lines)
    assert not any(line.startswith(f"{NAME} *") for line in lines)  # the shipped one trained on every batch
    assert lines[-1].startswith("* a quick check (train --limit-batches")


def test_a_user_zoo_that_is_a_file_is_refused_where_the_zoos_are_read(tmp_path, monkeypatch):
    """`zoo list` refused $CROWDMPC_ZOO naming a file, while simulate with a shipped predictor ran and
    silently read none of the user's calibrations from it."""
    from predictors.zoo import locate

    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"x")
    monkeypatch.setenv("CROWDMPC_ZOO", str(junk))
    with pytest.raises(
        PredictorError, match=r"^\$CROWDMPC_ZOO: the user zoo .*junk.mcap is a file, not a dir"
    ):
        locate("social_lstm_eth")


def test_a_zoo_config_without_net_builds_the_kinds_default_net(tmp_path):
    """Every config `crowdmpc train` wrote and every shipped one holds "net", but `zoo add` has always taken a
    config without it (written by hand or by another tool) into the user zoo: it loads with the model kind's
    default net (docs/outputs.md, NAME.json), where a refusal would stop the zoos and sweep folders that
    earlier versions made with it."""
    from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

    weights, config = checkpoint.save_checkpoint(
        SocialLSTM(SocialLSTMConfig()), model="social_lstm", name="nonet", out_dir=tmp_path / "src", obs_len=9
    )
    document = json.loads(config.read_text())
    del document["net"]
    config.write_text(json.dumps(document))
    options = {"protocol": "p", "training_data": {}, "metrics": {}, "directory": tmp_path / "zoo"}
    zoo_edit.add_to_zoo(weights, name="nonet", **options)
    assert "net" not in json.loads((tmp_path / "zoo" / "nonet.json").read_text())
    assert zoo.load_zoo("nonet", tmp_path / "zoo").net.config == SocialLSTMConfig()
