"""The user-facing errors cross process boundaries: a pool's worker sends the exception its job raised back
pickled, so each must rebuild from its pickle as it was."""

from __future__ import annotations

import pickle

import pytest

from pipelines.errors import EpisodeFailed, PipelineError
from pipelines.loop.spec import UnknownController
from predictors.errors import CheckpointMismatch, DatasetFormatError, UnknownPredictor
from predictors.export.errors import ExportError
from predictors.models import UnknownModel

ERRORS = [
    DatasetFormatError("scenes/biwi_eth.ndjson", 3, "not JSON"),
    DatasetFormatError("raw/obsmat.txt", None, "8 columns expected"),
    UnknownPredictor("social_lstm_ethh", ["constant_velocity", "social_lstm_eth"]),
    CheckpointMismatch("zoo/net.pt", "a" * 64, "b" * 64),
    UnknownModel("social_lsmt", ["social_lstm"]),
    UnknownModel("my_nets:Net", ["social_lstm"]),
    ExportError("unsupported operation torch.sort", "ranker"),
    ExportError("unsupported operation torch.sort", "ranker", "the supported operations are listed in ..."),
    UnknownController("cmcp", ["cmpc", "dmpc"]),
    UnknownController("my_controller:GoStraight", ["cmpc"]),
    EpisodeFailed(12, "circle", PipelineError("controller 'go': act() raised ValueError: boom")),
]


@pytest.mark.parametrize("error", ERRORS, ids=lambda e: type(e).__name__)
def test_an_error_survives_a_trip_through_pickle(error):
    """Errors that take their facts as arguments could not be unpickled (``__init__() missing 1 required
    positional argument: 'choices'``): a typo'd predictor name in one job of a user's ProcessPoolExecutor
    ended in BrokenProcessPool ("terminated abruptly"), the pool unusable, instead of UnknownPredictor."""
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error)
    assert str(back) == str(error)
    assert vars(back) == vars(error)


def test_an_unknown_predictor_of_the_wrong_kind_says_what_it_needs():
    """A weights file or a net class given as --predictor was only "unknown", as a typo is."""
    assert str(UnknownPredictor("runs/x/net.pt", ["constant_velocity"])).endswith(
        "(a weights file joins the zoo first: `crowdmpc zoo add FILE.pt`, then its name)"
    )
    assert str(UnknownPredictor("mine:Net", ["constant_velocity"])).endswith(
        "(module:Class names a net to train, not a trained model: train it, zoo add it, use its name)"
    )
    assert str(UnknownPredictor("socal_lstm_eth", ["social_lstm_eth"])) == (
        "unknown predictor 'socal_lstm_eth'; choose from ['social_lstm_eth']"
    )
