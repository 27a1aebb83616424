"""crowdsim.world is the one source of the shared facts: the other packages name its values, not copies."""

import ast
import inspect
from dataclasses import fields
from pathlib import Path

from crowdsim import env, env_config, gym_env, metrics, plotting, replay, world
from mpc import config
from pipelines.experiments import synth
from predictors import real_data
from predictors.data import ewap_checks, trajnet_scenes


def test_table_i_values():
    assert (world.DT, world.RADIUS, world.D_MIN, world.D_FLOCK) == (0.4, 0.3, 0.8, 1.2)
    assert (world.HORIZON, world.PAPER_ROBOTS) == (4, 3)


def test_the_other_packages_read_world():
    assert metrics.COLLISION_DISTANCE is world.D_MIN
    assert config.PAPER_ROBOTS is world.PAPER_ROBOTS
    assert config.MPCConfig().horizon == world.HORIZON
    assert real_data.HORIZON == world.HORIZON
    assert config.GUIDANCE_MODES == ("none", "standing")


def test_defaults_follow_world():
    assert inspect.signature(env.CrowdEnv.reset).parameters["n_robots"].default == world.PAPER_ROBOTS
    assert inspect.signature(plotting.plot_episode).parameters["radius"].default == world.RADIUS
    assert gym_env.CrowdNavEnv.metadata["render_fps"] == 1.0 / world.DT == 2.5


def test_the_recorded_step_is_held_once():
    """BIWI's 0.4 s annotation step (2.5 fps) is crowdsim.world's: the replays, the raw files' checks, the
    scene files' "fps" and the synthetic scenes name it, none writes its own 0.4 or 2.5."""
    assert (world.RECORDED_DT, world.RECORDED_FPS) == (0.4, 2.5)
    assert world.WorldFacts().dt is world.RECORDED_DT  # Table I's tau is the recorded step
    assert replay.RECORDED_DT is env_config.RECORDED_DT is ewap_checks.RECORDED_DT is world.RECORDED_DT
    assert trajnet_scenes.RECORDED_FPS is synth.RECORDED_FPS is world.RECORDED_FPS
    assert {f.name: f.default for f in fields(trajnet_scenes.SceneSpec)}["fps"] is world.RECORDED_FPS
    root = Path(__file__).resolve().parents[2]
    written = []
    for path in sorted(
        p for package in ("crowdsim", "predictors", "pipelines") for p in (root / package).rglob("*.py")
    ):
        for node in ast.parse(path.read_text(), str(path)).body:
            if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(node.value, ast.Constant):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names = [t.id for t in targets if isinstance(t, ast.Name)]
                if node.value.value in (0.4, 2.5) and any(
                    n.endswith(("DT", "FPS", "SECONDS")) for n in names
                ):
                    written += [f"{path.relative_to(root)}:{n}" for n in names]
    assert written == ["crowdsim/world.py:RECORDED_DT"]
