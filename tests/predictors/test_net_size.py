"""The bound on a net's size is one value (predictors.net_size): the kinds' meta-device check and the
shipped configs' counted check read it, not copies of it."""

import ast
from pathlib import Path

from predictors import kinds, net_size
from predictors.nets import social_attention, social_gru, social_lstm

ROOT = Path(__file__).resolve().parents[2]


def assigned_at_module_level(name: str) -> list[str]:
    """The modules of the four packages that assign ``name`` at their top level."""
    found = []
    for package in ("crowdsim", "mpc", "predictors", "pipelines"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.parse(path.read_text(), str(path)).body:
                targets = (
                    node.targets
                    if isinstance(node, ast.Assign)
                    else [node.target]
                    if isinstance(node, ast.AnnAssign)
                    else []
                )
                if any(isinstance(t, ast.Name) and t.id == name for t in targets):
                    found.append(str(path.relative_to(ROOT)))
    return found


def test_max_parameters_is_written_once():
    assert assigned_at_module_level("MAX_PARAMETERS") == ["predictors/net_size.py"]


def test_every_check_reads_the_one_value():
    for module in (kinds, social_lstm, social_gru, social_attention):
        assert module.MAX_PARAMETERS is net_size.MAX_PARAMETERS, module.__name__
