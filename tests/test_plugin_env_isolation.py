"""tests/conftest.py keeps the plugin variables of one test from the next (``_private_user_zoo``). The two
tests below run in this order: the first does what tests/pipelines/test_cli_plugins.py's
test_the_sweep_refuses_a_plugin_model_whose_plugin_is_not_registered does (``--plugin`` sets
CROWDMPC_PLUGINS, then the test deletes it through monkeypatch, as a new process without ``--plugin``), and
the second looks at the variable after ``monkeypatch.undo()``, as test_review's
test_compare_names_the_code_that_recorded_each_run does mid-test."""

import os

from predictors.models import PLUGINS_ENV

TOY = "tests.plugins.toy_predictor:ToyNet"


def test_a_plugin_variable_set_then_deleted_by_a_test(monkeypatch):
    os.environ[PLUGINS_ENV] = TOY  # what register_plugins (``crowdmpc --plugin``) does
    monkeypatch.delenv(PLUGINS_ENV)


def test_the_next_test_never_finds_it_again(monkeypatch):
    """The test's own delenv was undone after the fixture's clean-up had run: the variable came back and
    stayed for the rest of the session, hidden by each test's delenv but put back by any test's
    ``monkeypatch.undo()``, whose commands then registered the plugin and whose recordings named its code
    ("plugins tests.plugins.toy_predictor:ToyNet ..." where test_review expected the commit)."""
    assert PLUGINS_ENV not in os.environ
    monkeypatch.undo()
    assert PLUGINS_ENV not in os.environ
