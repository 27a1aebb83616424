"""The benchmarks that compile (jit) do so into a private compile cache, never into the user's."""

import collections
import os
import sys
from pathlib import Path

import pytest

from mpc.compile_cache import CACHE_ENV
from tests.benchmark_modules import load_benchmark


def _report(_args):
    return {"machine": {"cpus": 2, "load_average": [0.0] * 3, "python": "3"}, "settings": {}, "errors": {}}


# (script, the function its main measures by, what that returns, its arguments)
MEASURED = [
    (
        "sweep_floor",
        "measure",
        lambda _episodes: [{"cell": "a", "wall_s": 0.1}],
        ["--episodes-per-cell", "2"],
    ),
    ("ibr_solves", "measure", lambda *_: collections.defaultdict(lambda: 1.0), ["--jit", "--episodes", "1"]),
    ("run_all", "run", _report, ["--sections", "ibr"]),
]


@pytest.mark.parametrize("script, name, result, argv", MEASURED, ids=[m[0] for m in MEASURED])
def test_a_compiling_benchmark_measures_with_an_empty_cache_of_its_own(
    script, name, result, argv, tmp_path, monkeypatch, capsys
):
    """sweep_floor.py, run_all.py's episodes and ibr_solves.py --jit compiled into $CROWDMPC_CACHE (or
    ~/.cache/crowdmpc): they filled the user's cache with every size they tried and timed what it held."""
    module = load_benchmark(script)
    user = tmp_path / "user-cache"
    monkeypatch.setenv(CACHE_ENV, str(user))
    seen = []

    def measured(*args):
        folder = Path(os.environ[CACHE_ENV])
        seen.append((folder, folder.is_dir() and not any(folder.iterdir())))
        return result(*args)

    monkeypatch.setattr(module, name, measured)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])
    assert module.main(argv) == 0
    capsys.readouterr()
    ((folder, empty),) = seen
    assert folder != user and empty
    assert not folder.exists()  # removed at the end
    assert os.environ[CACHE_ENV] == str(user) and not user.exists()
