"""The explicit registry of predictors: exact names, no string matching.

``PREDICTORS`` maps a name to a factory for predictors that need no trained weights (constant velocity, and
the ORCA-ground-truth oracle of ``predictors.oracle``). Trained models are named entries of the model zoos
(the shipped ``checkpoints/manifest.json``, then the user zoo ``$CROWDMPC_ZOO``; see ``predictors.zoo``) and
are loaded by ``load_predictor`` as well, after their files' sha256 are checked against their manifest. A
zoo entry of a plugin's model kind loads once the plugin is registered (``predictors.models``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from contextvars import ContextVar

from predictors import zoo
from predictors.base import PRED_LEN, Predictor
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
    """Every name ``load_predictor`` accepts: the registered predictors, then the entries of both zoos."""
    return sorted(PREDICTORS) + [name for name in zoo.zoo_names() if name not in PREDICTORS]


def checkpoint_sha256(name: str | None) -> str | None:
    """The zoo's sha256 of a trained predictor's weights; None for predictors without weights (or no name)."""
    if name is None or name in PREDICTORS:
        return None
    located = zoo.locate(name)
    return located.entry.sha256 if located is not None else None


def loaded_sha256(predictor: Predictor) -> str | None:
    """The sha256 of the weights ``predictor`` holds: for one ``load_checkpoint`` read (a zoo entry's), that
    of the bytes it loaded, which the entry records (the manifest, read again, may name weights a `zoo add
    --replace` put in since); else ``checkpoint_sha256`` of its name (None: a predictor without weights)."""
    sha256 = getattr(predictor, "weights_sha256", None)  # a LearnedPredictor's; any Predictor may come here
    return sha256 if isinstance(sha256, str) else checkpoint_sha256(predictor.name)


def trained_prediction_length(name: str | None) -> int | None:
    """Steps ahead a zoo model was trained to predict: its manifest's ``training.pred_len``, else
    ``PRED_LEN`` (TrajNet++'s 12, the only length ``crowdmpc train`` trained before it recorded one); None for
    predictors that learned nothing (constant velocity, the oracle) and names in no zoo."""
    if name is None or name in PREDICTORS:
        return None
    located = zoo.locate(name)
    return None if located is None else entry_prediction_length(located.entry)


def entry_prediction_length(entry: zoo.ZooEntry) -> int:
    """``trained_prediction_length`` of the zoo entry ``entry``, for a caller that has located it already."""
    value = entry.training.get("pred_len", PRED_LEN)
    # a manifest is a file anyone can edit: a value that is no length reads as the one train uses
    return value if isinstance(value, int) and not isinstance(value, bool) and value >= 1 else PRED_LEN


def never_loads(located: zoo.Located) -> str | None:
    """Why user zoo entry ``located`` is never what its name loads, else None: a built-in predictor or a
    shipped model of that name loads first. ``zoo add`` refuses both names; an entry written by hand, or
    added before the shipped zoo took its name, has one all the same."""
    if located.source != zoo.USER:
        return None
    if located.entry.name in PREDICTORS:
        return zoo.never_loads_line(located, f"the built-in predictor {located.entry.name!r}")
    return zoo.never_loads_line(located, "a shipped model") if zoo.shadowed(located) else None


# the zoo entries a command located already, by name, which ``load_predictor`` loads within ``handing``
_HANDED: ContextVar[Mapping[str, zoo.Located] | None] = ContextVar("handed_zoo_entries", default=None)


@contextlib.contextmanager
def handing(located: zoo.Located | None) -> Iterator[None]:
    """Within the block, ``load_predictor`` of ``located``'s name loads ``located`` (its files checked against
    it, as ``zoo.load_located`` checks them) without reading the manifests again; None hands nothing. A plugin
    controller loading the run's predictor itself located it again after simulate had, for its notes: the
    manifest read twice, and a `zoo add --replace` between had the notes describe another model."""
    handed = dict(_HANDED.get() or {})
    if located is not None:
        handed[located.entry.name] = located
    token = _HANDED.set(handed)
    try:
        yield
    finally:
        _HANDED.reset(token)


def load_predictor(name: str) -> Predictor:
    if not isinstance(name, str):  # a list was "unhashable type: 'list'"
        raise UnknownPredictor(name, available())
    if name in PREDICTORS:
        return PREDICTORS[name]()
    located = (_HANDED.get() or {}).get(name) or zoo.locate(name)
    if located is not None:
        return zoo.load_located(located)
    raise UnknownPredictor(name, available())
