"""The protocols and test sequences the commands' options offer are the data layer's: the options are
written in pipelines.commands.train_data (a parser does not import numpy), and were written again in
evaluate and zoo_metrics."""

from __future__ import annotations

import argparse

from pipelines.commands import evaluate, train, zoo_metrics
from pipelines.commands.train_data import DATASET_SUFFIX, DEFAULT_DATASET, DEFAULT_PROTOCOL, PROTOCOLS
from predictors.data import locate


def _choices(register, command: str) -> dict[str, tuple]:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    sub = parser._subparsers._group_actions[0].choices[command]  # type: ignore[union-attr]
    return {a.dest: tuple(a.choices) for a in sub._actions if a.dest in ("protocol", "dataset")}


def test_the_options_offer_the_data_layers_protocols_and_sequences():
    assert PROTOCOLS == locate.PROTOCOLS
    assert tuple(DATASET_SUFFIX) == locate.DATASETS
    assert DEFAULT_PROTOCOL in PROTOCOLS and DEFAULT_DATASET in DATASET_SUFFIX
    assert zoo_metrics.TRAJNET_PROTOCOLS == PROTOCOLS
    for register, command in ((evaluate.register, "evaluate"), (train.register, "train")):
        assert _choices(register, command) == {"protocol": PROTOCOLS, "dataset": tuple(DATASET_SUFFIX)}
