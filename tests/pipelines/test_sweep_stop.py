"""A sweep that stops part way (a worker's refusal of replaced weights, a lost Ray cluster) keeps the episodes
its other workers finish: the driver stopped at once and closed the backend, and those episodes ended
unrecorded, for a rerun to run again (pipelines.experiments.sweep_stop)."""

from __future__ import annotations

import time
import types
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.experiments import sweep_stop
from pipelines.experiments.log import EPISODES_FILE, ERRORS_FILE, EpisodeLog

FAILING = "tests.plugins.failing_controllers"


@pytest.fixture
def plugins(monkeypatch):
    """Register ``failing_controllers``' plugins here and for the workers; none left after."""
    from pipelines.loop import spec as registry

    monkeypatch.setattr(registry, "_PLUGINS", {})

    def register(*names: str) -> list[str]:
        specs = [f"{FAILING}:{name}" for name in names]
        registry.register_controller_plugins(specs)
        return specs

    return register


def _sweep(out: Path, controllers: list[str], backend: str) -> list[str]:
    """Two workers, an episode of each controller: the first one's worker refuses at once."""
    return ["sweep", "--experiment", "controllers", "--controllers", ",".join(controllers), "--humans", "1",
            "--episodes-per-cell", "1", "--workers", "2", "--backend", backend, "--jit", "off",
            "--no-progress", "--out", str(out)]  # fmt: skip


def _stopped_at(out: Path, recorded: str) -> str:
    return (
        "crowdmpc sweep: error: predictor 'mine': the weights were replaced (a stand-in refusal) (the sweep "
        f"stopped at the first episode that loaded them, {recorded})"
    )


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_stopped_sweep_records_the_episode_another_worker_finishes(backend, tmp_path, plugins, capsys):
    """`--workers 2`, weights replaced in the zoo while the other worker ran an episode of a cell it had built
    (on the weights checked): the refusal stopped the sweep and closed the backend at once, and that episode,
    back a moment later, was lost (met in a Table II sweep: 3 episodes in flight came back within 5 s)."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    refuses, slow = plugins("RefusesWeights", "TakesASecond")
    assert main(_sweep(tmp_path, [refuses, slow], backend)) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == _stopped_at(tmp_path, f"the 1 episode recorded in {tmp_path} kept")
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    assert [r["controller"] for r in records.values()] == ["takes_a_second"]
    assert not (tmp_path / ERRORS_FILE).exists()  # a refusal is no episode error
    assert "CPU per episode" in err and (tmp_path / "table.md").exists()  # the report has it


def test_a_stop_waits_a_bounded_time_and_says_how_many_episodes_it_cut(
    tmp_path, plugins, capsys, monkeypatch
):
    """An episode still running when the stop's wait ends is cut, unrecorded, and the stop's line says so:
    "rerun to resume" alone did not say that the episodes in flight were lost with the stop."""
    monkeypatch.setattr(sweep_stop, "STOP_WAIT_S", 0.5)
    refuses, sleeps = plugins("RefusesWeights", "SleepsInReset")  # a minute an episode
    start = time.monotonic()
    assert main(_sweep(tmp_path, [refuses, sleeps], "process")) == 2
    assert time.monotonic() - start < 45  # the pool's start, the wait, and its end: not the minute
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == _stopped_at(tmp_path, f"no episode of it is recorded in {tmp_path} yet") + (
        "; 1 episode in flight on the workers was cut unrecorded (a resume runs it)"
    )
    log = tmp_path / EPISODES_FILE
    assert not log.exists() or not log.read_text()


class _Refs:
    """A stand-in ``ray`` for RayBackend.finished: ``done`` the refs back, ``died`` those whose actor died."""

    def __init__(self, done: set[str], died: set[str]):
        self.done, self.died, self.timeouts = done, died, []
        self.exceptions = types.SimpleNamespace(RayActorError=RuntimeError)

    def wait(self, refs, num_returns, timeout):
        self.timeouts.append(timeout)
        return [r for r in refs if r in self.done], [r for r in refs if r not in self.done]

    def get(self, ref, timeout):
        if ref in self.died:
            raise RuntimeError("The actor died unexpectedly before finishing this task.")
        return f"outcome of {ref}"


@pytest.mark.parametrize("gcs_gone", [False, True])
def test_the_ray_backend_gives_back_what_its_actors_finished_and_counts_the_rest(gcs_gone):
    """Without Ray: the episodes back are given, those of a dead actor and those still out are cut; once the
    cluster's GCS is gone (nothing came back for GCS_GONE_S) it takes only those back already, waiting
    none."""
    from pipelines.experiments.backends import RayBackend

    backend = RayBackend.__new__(RayBackend)  # its state alone: no Ray started
    backend._ray = _Refs(done={"a", "b"}, died={"b"})
    backend._gcs_gone = gcs_gone
    backend._owner = {"a": None, "b": None, "c": None}
    assert backend.finished(7.0) == (["outcome of a"], 2)
    assert backend._ray.timeouts == [0.0 if gcs_gone else 7.0]
    assert backend.finished(7.0) == ([], 0)  # given once
