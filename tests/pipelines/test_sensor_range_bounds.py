"""A sensor range's least and greatest values (``crowdsim.world.SENSOR_RANGE``): "> 0" took 5e-324, a sensor
that saw nobody, and 1e300, whose dashed ring simulate --plot drew for good. Refused where the run was given
it and by the sensor itself, while a sweep folder that ran beyond them still reads back."""

import math

import pytest

from crowdsim import world
from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.sensing import RangeLimited
from tests.cli_calls import one_line
from tests.cli_calls import run_cli as run

SIMULATE = ["simulate", "--controller", "straight", "--episodes", "1", "--humans", "1", "--robots", "1"]


@pytest.mark.parametrize(
    "given, said",
    [
        (
            ["--sensor-range", "5e-324"],
            "--sensor-range: the sensor range must be at least 1e-06 m, got 5e-324",
        ),
        (["--sensor-range", "1e300"], "--sensor-range: the sensor range must be at most 1000 m, got 1e+300"),
        (["--sensor-range", "1000.5"], "--sensor-range: the sensor range must be at most 1000 m, got 1000.5"),
        (
            ["--set", "simulate.sensor_range=1e-12"],
            "--set simulate.sensor_range: the sensor range must be at least 1e-06 m, got 1e-12",
        ),
    ],
)
def test_simulate_refuses_a_sensor_range_beyond_its_bounds_where_it_was_given(capsys, given, said):
    code, _, err = run(capsys, *SIMULATE, *given)
    assert code == 2 and one_line(err) == f"crowdmpc simulate: error: {said}"


def test_simulate_runs_at_the_bounds(capsys, tmp_path):
    least, most = world.SENSOR_RANGE
    assert least == world.LEAST["radius"][0]  # the world's least length
    for value in (least, most):
        code, _, err = run(
            capsys, *SIMULATE, "--sensor-range", repr(value), "--plot", str(tmp_path / "p.png")
        )
        assert code == 0, err


@pytest.mark.parametrize("radius", [5e-324, 1e-300, 1e300])
def test_the_sensor_refuses_them_from_python(radius):
    inner = make_controller(ControllerSpec("straight"))
    with pytest.raises(PipelineError) as exc:
        RangeLimited(inner, radius)
    side, bound = ("least", "1e-06") if radius < 1 else ("most", "1000")
    assert str(exc.value) == f"sensor radius must be at {side} {bound} m, got {radius!r}"
    RangeLimited(inner, math.inf)  # a replay's tracked humans: no sensor


def test_a_sweep_that_ran_beyond_them_still_reports_and_is_not_run_again(tmp_path, capsys, monkeypatch):
    out = tmp_path / "sweep"
    options = ["--experiment", "controllers", "--controllers", "cmpc", "--humans", "1", "--robots", "1"]
    options += ["--episodes-per-cell", "1", "--set", "env.time_limit=2", "--backend", "inline"]
    options += ["--no-progress", "--jit", "off", "--sensor-range", "2000"]
    with monkeypatch.context() as before:  # the code before the bound
        before.setattr(world, "SENSOR_RANGE", (0.0, math.inf))
        assert main(["sweep", *options, "--out", str(out)]) == 0
    (out / "table.md").unlink()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    assert "cmpc" in (out / "table.md").read_text()
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    assert "\nsensor_range = 2000.0 " in capsys.readouterr().out
    assert main(["sweep", *options, "--episodes-per-cell", "2", "--out", str(out)]) == 2
    assert one_line(capsys.readouterr().err) == (
        "crowdmpc sweep: error: --sensor-range: the sensor range must be at most 1000 m, got 2000.0; "
        f"{out} ran with simulate.sensor_range = 2000.0 before that bound: no more of it runs, and "
        f"`crowdmpc sweep --report-only --out {out}` still reports it"
    )


def test_a_calibration_behind_a_sensor_is_refused_them_as_it_is_planned():
    from pipelines.experiments.calibrate import ClosedLoopPlan

    with pytest.raises(PipelineError) as exc:
        ClosedLoopPlan("constant_velocity", sensor_range=1e300)
    assert str(exc.value) == "--sensor-range: the sensor range must be at most 1000 m, got 1e+300"
    assert ClosedLoopPlan("constant_velocity", sensor_range=1000.0).sensor_range == 1000.0


def test_simulate_and_calibrate_refuse_them_in_a_sweeps_words(capsys, tmp_path):
    """calibrate said "--sensor-range must be at most 1000 m, got 2000.0" and simulate "--sensor-range: must
    be at most 1000 m, ..." where a sweep says "--sensor-range: the sensor range must be at most ...": all
    three now take crowdsim.world.sensor_range_refused's words. Other settings' refusals read as before."""
    calibrate = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--no-progress"]
    sweep = ["sweep", "--experiment", "baselines", "--humans", "1", "--episodes-per-cell", "1", "--dry-run"]
    sweep += ["--out", str(tmp_path / "sweep")]
    said = {}
    for command, extra in ((calibrate, ["--dry-run"]), (calibrate, []), (sweep, []), (SIMULATE, [])):
        code, _, err = run(capsys, *command, *extra, "--sensor-range", "2000")
        assert code == 2
        said[(command[0], *extra)] = one_line(err).split(": error: ", 1)[1]
    assert set(said.values()) == {"--sensor-range: the sensor range must be at most 1000 m, got 2000.0"}
    code, _, err = run(capsys, *SIMULATE, "--set", "env.orca.neighbor_dist=1e-9")
    assert code == 2 and one_line(err).startswith(
        "crowdmpc simulate: error: --set env.orca.neighbor_dist: must be at least"
    )
