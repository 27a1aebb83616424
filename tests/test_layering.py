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


# pipelines/ in rooms, each importing only the rooms before it: the closed loop, the plugins it runs, its
# logs, the experiments built on them, the config files that name all of these, then the command line on
# top. The shared leaves import no room.
ROOMS = ("loop", "plugins", "logs", "experiments", "config", "commands")
LEAVES = ("errors", "plain_json", "version", "whole_files")


def project_imports() -> dict[str, set[str]]:
    """Each project module's project-module imports (anywhere in the file, lazy and TYPE_CHECKING ones too:
    a cycle through a function-level import is still two modules that need each other)."""
    paths = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
        for package in ("crowdsim", "mpc", "predictors", "pipelines")
        for p in (ROOT / package).rglob("*.py")
    }

    def module_of(name: str) -> str | None:
        while name and name not in paths:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for module, path in paths.items():
        names = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names += [f"{node.module}.{a.name}" for a in node.names]
        found = {module_of(n) for n in names} - {None, module}
        graph[module] = {m for m in found if not module.startswith(m + ".")}  # a package's own __init__
    return graph


def test_no_import_cycles_anywhere():
    graph = project_imports()
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for dep in sorted(graph[module]):
            if state.get(dep) == 1:
                cycle = path[path.index(dep) :] + [dep]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if dep not in state:
                visit(dep, [*path, dep])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])


def test_the_pipelines_rooms_import_one_way():
    graph = project_imports()
    for module, deps in graph.items():
        parts = module.split(".")
        if parts[0] != "pipelines" or len(parts) < 2:
            continue
        room = parts[1]
        inner = {d.split(".")[1] for d in deps if d.startswith("pipelines.") and d.count(".") >= 1}
        if room in LEAVES:
            assert not inner, f"{module} is a shared leaf but imports {sorted(inner)}"
        elif room in ROOMS:
            later = set(ROOMS[ROOMS.index(room) + 1 :]) | {"cli"}
            assert not inner & later, f"{module} imports the later room(s) {sorted(inner & later)}"


def test_the_cycle_check_finds_a_cycle(tmp_path, monkeypatch):
    """The cycle test can fail: a hand-made graph with a loop is caught."""
    import tests.test_layering as layering

    monkeypatch.setattr(layering, "project_imports", lambda: {"a": {"b"}, "b": {"c"}, "c": {"a"}})
    with pytest.raises(pytest.fail.Exception, match="a -> b -> c -> a"):
        layering.test_no_import_cycles_anywhere()


# STYLE: modules small and named for what they hold. A module past this moves a cohesive piece into a module
# of its own (train_net, simulate_table, experiments/methods, crowdsim/distances): the subcommands were
# checked first, as they grow with every option; five modules of the packages had passed 400 unchecked.
MAX_MODULE_LINES = 400


def test_the_modules_stay_small():
    sizes = {
        str(path.relative_to(ROOT)): len(path.read_text().splitlines())
        for package in ("crowdsim", "mpc", "predictors", "pipelines")
        for path in sorted((ROOT / package).rglob("*.py"))
    }
    assert len(sizes) > 150  # every module of the four packages, subpackages included
    assert not {name: n for name, n in sizes.items() if n > MAX_MODULE_LINES}
