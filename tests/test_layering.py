"""The dependency rules of DESIGN.md, checked on the source: data flows one way, and the controller and the
simulator stay usable without the training stack."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def imported_roots(package: str) -> dict[str, set[str]]:
    """Top-level module names imported anywhere (also inside functions) by each file of ``package``."""
    found = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        names = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
        found[str(path.relative_to(ROOT))] = names
    return found


@pytest.mark.parametrize("package", ["mpc", "crowdsim"])
def test_no_lightning(package):
    offenders = {f: n & {"lightning", "pytorch_lightning"} for f, n in imported_roots(package).items()}
    assert not {f: n for f, n in offenders.items() if n}


def test_crowdsim_imports_nothing_else_from_the_project():
    offenders = {f: n & {"mpc", "predictors", "pipelines"} for f, n in imported_roots("crowdsim").items()}
    assert not {f: n for f, n in offenders.items() if n}


def test_the_library_packages_do_not_import_the_pipelines():
    for package in ("mpc", "predictors"):
        offenders = {f: n & {"pipelines"} for f, n in imported_roots(package).items()}
        assert not {f: n for f, n in offenders.items() if n}, package


# The ORCA-ground-truth oracle predicts with the simulator's own human update: the one exception.
# predictors/base.py names the observation hook's argument types (under TYPE_CHECKING only).
SIMULATOR_READERS = {
    "predictors/oracle.py": {"crowdsim.env", "crowdsim.orca"},
    "predictors/base.py": {"crowdsim.env"},
}


def test_the_library_packages_take_only_the_world_facts_from_the_simulator():
    """mpc and predictors share tau, L and the robot bounds through crowdsim.world (one source), and nothing
    else of the simulator (but the oracle, which is the simulator's rule)."""
    for package in ("mpc", "predictors"):
        for path in sorted((ROOT / package).rglob("*.py")):
            allowed = {"crowdsim.world"} | SIMULATOR_READERS.get(str(path.relative_to(ROOT)), set())
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    modules = (
                        [node.module]
                        if node.module != "crowdsim"
                        else [f"crowdsim.{a.name}" for a in node.names]
                    )
                elif isinstance(node, ast.Import):
                    modules = [a.name for a in node.names]
                else:
                    continue
                bad = [m for m in modules if m.split(".")[0] == "crowdsim" and m not in allowed]
                assert not bad, f"{path.relative_to(ROOT)} imports {bad}"
