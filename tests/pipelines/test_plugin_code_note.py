"""A zoo model of a plugin's net whose module file changed since training is noted where it is used: the
net's outputs may differ from the figures `zoo list` shows, and it loaded without a word."""

from __future__ import annotations

from types import SimpleNamespace

from pipelines.commands import simulate_checks


def _model(monkeypatch, trained: str, now: str | None) -> None:
    entry = SimpleNamespace(model="mine:Net", training={"code": {"plugins": {"mine:Net": trained}}})
    monkeypatch.setattr("predictors.zoo.locate", lambda name: SimpleNamespace(entry=entry))
    monkeypatch.setattr("pipelines.plugins.plugin_code", lambda: {} if now is None else {"mine:Net": now})


def test_a_changed_plugin_file_is_noted(monkeypatch):
    _model(monkeypatch, "a" * 64, "b" * 64)
    assert simulate_checks.plugin_code_note("my_net_eth") == (
        "note: 'my_net_eth' was trained with plugin mine:Net of sha256 aaaaaaaaaaaa, its file is now "
        "bbbbbbbbbbbb: if the net's code changed, so may its predictions (zoo list's figures are the "
        "trained code's)"
    )


def test_the_same_file_or_no_record_says_nothing(monkeypatch):
    _model(monkeypatch, "a" * 64, "a" * 64)
    assert simulate_checks.plugin_code_note("my_net_eth") is None
    _model(monkeypatch, "a" * 64, None)  # not registered here: loading it is refused elsewhere
    assert simulate_checks.plugin_code_note("my_net_eth") is None
    assert simulate_checks.plugin_code_note(None) is None
