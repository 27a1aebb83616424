"""ORCA's neighbor_dist has a least value, the world's least length (``crowdsim.orca.LEAST_NEIGHBOR_DIST``):
"> 0" took 5e-324, whose square is 0, so no agent was ever a neighbour, and the records held it. Refused where
a run was given it and by orca_velocities, while a sweep folder that ran less still reads back."""

import numpy as np
import pytest

from crowdsim import orca
from crowdsim.errors import SimulationError
from crowdsim.orca import OrcaParams, orca_velocities
from crowdsim.world import LEAST
from pipelines.cli import main
from tests.cli_calls import one_line
from tests.cli_calls import run_cli as run

SIMULATE = ["simulate", "--controller", "orca", "--episodes", "1", "--humans", "2"]


@pytest.mark.parametrize("value", ["5e-324", "1e-300", "1e-07"])
def test_simulate_refuses_a_neighbour_distance_below_its_least_where_it_was_given(capsys, tmp_path, value):
    code, _, err = run(capsys, "--set", f"env.orca.neighbor_dist={value}", *SIMULATE)
    said = f"--set env.orca.neighbor_dist: must be at least 1e-06 m, got {float(value)!r}"
    assert code == 2 and one_line(err) == f"crowdmpc simulate: error: {said}"
    config = tmp_path / "run.toml"
    config.write_text(f"[env.orca]\nneighbor_dist = {value}\n")
    code, _, err = run(capsys, "--config", str(config), *SIMULATE)
    said = f"{config}: env.orca.neighbor_dist: must be at least 1e-06 m, got {float(value)!r}"
    assert code == 2 and one_line(err) == f"crowdmpc simulate: error: {said}"


def test_orca_refuses_it_from_python_and_runs_at_it():
    assert orca.LEAST_NEIGHBOR_DIST == LEAST["radius"][0]  # the world's least length
    positions = np.array([[-2.0, 0.0], [2.0, 0.0]])
    args = (positions, np.zeros((2, 2)), np.array([[1.0, 0.0], [-1.0, 0.0]]), 0.3, 1.0)
    orca_velocities(*args, OrcaParams(neighbor_dist=orca.LEAST_NEIGHBOR_DIST), 0.4)
    with pytest.raises(SimulationError) as exc:
        orca_velocities(*args, OrcaParams(neighbor_dist=5e-324), 0.4)
    assert str(exc.value) == "orca_velocities: OrcaParams.neighbor_dist must be at least 1e-06 m, got 5e-324"


def test_a_sweep_that_ran_less_still_reports_and_is_not_run_again(tmp_path, capsys, monkeypatch):
    out = tmp_path / "sweep"
    options = ["--experiment", "controllers", "--controllers", "orca", "--humans", "2", "--robots", "1"]
    options += ["--episodes-per-cell", "1", "--set", "env.time_limit=2", "--backend", "inline"]
    options += ["--no-progress", "--set", "env.orca.neighbor_dist=1e-12"]
    with monkeypatch.context() as before:  # the code before the least value
        before.setattr(orca, "LEAST_NEIGHBOR_DIST", 0.0)
        assert main(["sweep", *options, "--out", str(out)]) == 0
    (out / "table.md").unlink()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    assert "orca.neighbor_dist = 1e-12" in (out / "table.md").read_text()  # the report written again
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    assert "\nneighbor_dist = 1e-12 " in capsys.readouterr().out
    assert main(["sweep", *options, "--episodes-per-cell", "2", "--out", str(out)]) == 2
    assert one_line(capsys.readouterr().err) == (
        "crowdmpc sweep: error: --set env.orca.neighbor_dist: ORCA's neighbor_dist must be at least 1e-06 m, "
        f"got 1e-12; {out} ran with env.orca.neighbor_dist = 1e-12 before that bound: no more of it runs, "
        f"and `crowdmpc sweep --report-only --out {out}` still reports it"
    )
