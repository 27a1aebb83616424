"""The top-k figures ``crowdmpc train`` stores in NAME.metrics.json (and `zoo list` shows) are the ones
``crowdmpc evaluate --top-k K`` prints for the same weights, whatever --seed the net was trained with."""

import argparse

import numpy as np
import pytest

from pipelines.commands.train_report import evaluate_splits
from predictors.constant_velocity import ConstantVelocity
from predictors.evaluate import EvalConfig, evaluate
from tests.predictors.samples import write_walk_file


class NoisySampler(ConstantVelocity):
    """Samples that depend on the generator: the top-k figures change with its seed."""

    name = "noisy_sampler"

    def sample(self, history, mask, robots_future, humans, horizon, k, rng):
        base = self.rollout(history, mask, robots_future, humans, horizon)
        return base[None] + rng.normal(0.0, 1.0, size=(k, *base.shape))


@pytest.mark.parametrize("train_seed", [0, 7])
def test_train_top_k_is_what_evaluate_prints(tmp_path, train_seed):
    path = write_walk_file(tmp_path / "walk.ndjson")
    args = argparse.Namespace(seed=train_seed, no_progress=True)
    stored = evaluate_splits(args, NoisySampler(), {"val": [path], "test": [path]}, None, 3)
    printed = evaluate(NoisySampler(), [path], EvalConfig(top_k=3), progress=False)["overall"]
    for split in ("val", "test"):
        assert stored[split]["topk_ade"] == printed["topk_ade"]
        assert stored[split]["topk_fde"] == printed["topk_fde"]


def test_the_sampler_depends_on_the_seed(tmp_path):
    # otherwise the test above could not tell one evaluation seed from another
    path = write_walk_file(tmp_path / "walk.ndjson")
    tops = [
        evaluate(NoisySampler(), [path], EvalConfig(top_k=3, seed=s), progress=False)["overall"]["topk_ade"]
        for s in (0, 7)
    ]
    assert not np.isclose(tops[0], tops[1])
