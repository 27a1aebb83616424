"""The explicit registry of predictors: exact names, no string matching.

``PREDICTORS`` maps a name to a factory for predictors that need no trained weights (constant velocity, and
the ORCA-ground-truth oracle of ``predictors.oracle``). Trained models are
named entries of the model zoo (``checkpoints/manifest.json``, see ``predictors.zoo``) and are loaded by
``load_predictor`` as well, after their files' sha256 are checked against the manifest.
"""

from __future__ import annotations

from collections.abc import Callable

from predictors import zoo
from predictors.base import Predictor
from predictors.constant_velocity import ConstantVelocity
from predictors.errors import UnknownPredictor


def _orca_oracle() -> Predictor:
    from predictors.oracle import OrcaOracle  # loads the simulator's ORCA: only when asked for

    return OrcaOracle()


PREDICTORS: dict[str, Callable[[], Predictor]] = {
    "constant_velocity": ConstantVelocity,
    "orca_oracle": _orca_oracle,
}


def available() -> list[str]:
    """Every name ``load_predictor`` accepts: the registered predictors, then the zoo entries."""
    return sorted(PREDICTORS) + [name for name in zoo.zoo_names() if name not in PREDICTORS]


def checkpoint_sha256(name: str | None) -> str | None:
    """The zoo's sha256 of a trained predictor's weights; None for predictors without weights (or no name)."""
    if name is None or name in PREDICTORS:
        return None
    entry = zoo.read_manifest().get(name)
    return entry.sha256 if entry is not None else None


def load_predictor(name: str) -> Predictor:
    if name in PREDICTORS:
        return PREDICTORS[name]()
    if name in zoo.zoo_names():
        return zoo.load_zoo(name)
    raise UnknownPredictor(name, available())
