"""A zoo model of a plugin's net whose module file changed since training is noted where it is used: the
net's outputs may differ from the figures `zoo list` shows, and it loaded without a word."""

from __future__ import annotations

from types import SimpleNamespace

from pipelines.commands import simulate_checks


def zoo_notes(predictor: str | None) -> list[str]:
    """The notes as simulate, sweep, evaluate and export make them, of the entry the name loads."""
    return simulate_checks.zoo_notes(predictor, simulate_checks.zoo_entry(predictor))


def _model(monkeypatch, trained: str, now: str | None) -> None:
    entry = SimpleNamespace(model="mine:Net", training={"code": {"plugins": {"mine:Net": trained}}})
    monkeypatch.setattr("predictors.zoo.locate", lambda name: SimpleNamespace(entry=entry))
    monkeypatch.setattr("pipelines.plugins.plugin_code", lambda: {} if now is None else {"mine:Net": now})


def test_a_changed_plugin_file_is_noted(monkeypatch):
    _model(monkeypatch, "a" * 64, "b" * 64)
    assert zoo_notes("my_net_eth") == [
        "note: 'my_net_eth' was trained with plugin mine:Net of sha256 aaaaaaaaaaaa, its file is now "
        "bbbbbbbbbbbb: if the net's code changed, so may its predictions (zoo list's figures are the "
        "trained code's)"
    ]


def test_the_same_file_or_no_record_says_nothing(monkeypatch):
    _model(monkeypatch, "a" * 64, "a" * 64)
    assert zoo_notes("my_net_eth") == []
    _model(monkeypatch, "a" * 64, None)  # not registered here: loading it is refused elsewhere
    assert zoo_notes("my_net_eth") == []
    assert zoo_notes(None) == []


def test_a_quick_check_is_noted_where_it_runs(monkeypatch):
    """`zoo add` and `zoo list` said so; simulate, sweep, evaluate and export ran it beside trained models.
    Not among the notes before the load (zoo_notes): printed once the inputs are taken
    (tests/pipelines/test_quick_check_note_order.py)."""
    from pipelines.commands.quick_check_notes import quick_check_note

    entry = SimpleNamespace(model="mine:Net", training={"limit_batches": 20})
    monkeypatch.setattr("predictors.zoo.locate", lambda name: SimpleNamespace(entry=entry))
    located = simulate_checks.zoo_entry("my_net_eth")
    assert quick_check_note("my_net_eth", located) == (
        "note: 'my_net_eth' trained on 20 batches an epoch (train --limit-batches 20): a quick check, not a "
        "trained model (zoo list: *)"
    )
    assert zoo_notes("my_net_eth") == []
    entry.training = {}
    assert quick_check_note("my_net_eth", located) is None
    assert quick_check_note("constant_velocity", simulate_checks.zoo_entry("constant_velocity")) is None


def test_export_says_a_changed_plugin_before_a_load_that_fails(monkeypatch, tmp_path, capsys):
    """An edited plugin whose weights no longer fit was refused ("weights do not fit the net") with the
    note that explains it printed only after a successful load."""
    import pipelines.commands.sweep_checks  # noqa: F401 (imported before the patch: it binds zoo_notes)
    from pipelines.cli import main
    from pipelines.errors import PipelineError

    monkeypatch.setattr(simulate_checks, "zoo_notes", lambda name, entry: ["note: its file is now bbbb"])

    def refuse(name):
        raise PipelineError("weights do not fit the net")

    monkeypatch.setattr("predictors.registry.load_predictor", refuse)
    assert main(["export", "my_net_eth", "--out", str(tmp_path / "x.casadi")]) == 2
    err = capsys.readouterr().err
    assert err.index("note: its file is now bbbb") < err.index("weights do not fit the net"), err
