"""The methods (columns) the shipped experiments compare: the predictors they plan with, the predictor-swap
ablation's default list, the controllers experiment's columns, and the method lists of the coupling, safety,
conventions and sensing ablations.

Apart from pipelines.experiments.cells, which holds what an experiment is (``Experiment``) and the registry
of those the project ships (``EXPERIMENTS``, built from these lists): the lists are facts about the study
(which models, which alphas, which sensor ranges), and change without touching what an experiment does.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from types import MappingProxyType
from typing import Final

from crowdsim.profiles import VISIBILITY
from pipelines.experiments.tasks import World
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import MarginSpec
from predictors.oracle import ORACLE_PREDICTOR

# Table II and III use the paper's predictor, Social-LSTM trained on ETH (grid pooling as in TrajNet++);
# `crowdmpc sweep --predictor constant_velocity` runs the same tables with the baseline.
PAPER_PREDICTOR: Final[str] = "social_lstm_eth"
# The coupled NLP needs a useful gradient of the prediction with respect to the robots' plan: soft pooling.
COUPLING_PREDICTOR: Final[str] = "social_lstm_soft_eth"
# The predictor-swap ablation: every zoo model the predictors issues train, the baseline, and the oracle.
# `crowdmpc sweep --experiment predictors --predictors a,b,c` swaps any others (a user zoo's, a plugin's).
SWAP_PREDICTORS: Final[tuple[str, ...]] = (
    "constant_velocity",
    "vanilla_lstm_eth",
    "social_lstm_eth",
    "social_lstm_soft_eth",
    "social_gan_eth",
    "social_gru_eth",
    "social_attention_eth",
    "social_lstm_synth",
    ORACLE_PREDICTOR,  # the upper bound: the humans' own ORCA (predictors/oracle.py)
)
# Models of the swap table that came after the first zoo (issue 13): in the default list once a zoo has them.
LATER_SWAP_PREDICTORS: Final[frozenset[str]] = frozenset({"social_gru_eth", "social_attention_eth"})


def swap_predictors(available: Collection[str] = ()) -> tuple[str, ...]:
    """The default swap table: ``SWAP_PREDICTORS``, less the later models not in ``available``."""
    return tuple(name for name in SWAP_PREDICTORS if name not in LATER_SWAP_PREDICTORS or name in available)


# The controllers experiment's default columns: the paper's two and the baselines.
SHIPPED_CONTROLLERS: Final[tuple[str, ...]] = ("cmpc", "dmpc", "orca", "straight")


def coupled_method(mode: str) -> ControllerSpec:
    """CMPC with the predictor inside the joint NLP, modelling the humans as ``mode`` (mpc/coupled.py)."""
    return ControllerSpec("cmpc", COUPLING_PREDICTOR, coupling="nlp", mpc_overrides=(("coupled_mode", mode),))


# The safety experiment: the paper's method (no margin), then conformal margins at decreasing alpha (more
# coverage, wider margins), one margin per step for everyone, one per motion class ("motion"), and one per
# motion class of the distance shortfall ("shortfall"), CMPC with the paper's predictor at the middle of the
# paper's range.
SAFETY_ALPHAS: Final[tuple[float, ...]] = (0.5, 0.2, 0.1, 0.05, 0.01)


def safety_methods() -> tuple[tuple[str, ControllerSpec], ...]:
    methods = [("none", ControllerSpec("cmpc", PAPER_PREDICTOR))]
    for mode, prefix in (
        ("conformal", ""),
        ("conformal-motion", "motion "),
        ("conformal-shortfall", "shortfall "),
    ):
        for alpha in SAFETY_ALPHAS:
            margins = MarginSpec(mode, alpha=alpha)  # type: ignore[arg-type]
            methods.append(
                (f"{prefix}alpha={alpha:g}", ControllerSpec("cmpc", PAPER_PREDICTOR, margins=margins))
            )
    return tuple(methods)


# How much of the gap to the paper's collision rates each convention explains: profile x visibility x
# margins, CMPC with the paper's predictor, the same seeds in every cell (the same crowds within a profile:
# the two profiles draw their humans differently, crowdsim.scenarios).
def convention_methods() -> tuple[tuple[tuple[str, ControllerSpec], ...], Mapping[str, World]]:
    methods, worlds = [], {}
    for profile in ("v1", "paper"):
        for visibility in VISIBILITY:
            for margins in (MarginSpec(), MarginSpec("conformal")):
                label = f"{profile}/{visibility}/{margins.label}"
                methods.append((label, ControllerSpec("cmpc", PAPER_PREDICTOR, margins=margins)))
                worlds[label] = World(profile, visibility)
    return tuple(methods), MappingProxyType(worlds)


CONVENTION_METHODS, CONVENTION_WORLDS = convention_methods()

# What a robot that sees a few metres loses: CMPC with the paper's predictor given every human, then only
# those within each range of some robot (each from when it came into view, its track length given, so the
# MPC extends a short track back: predictors.backfill), and at the middle range without the track lengths.
SENSOR_RANGES: Final[tuple[float, ...]] = (4.0, 3.0, 2.0)
UNTRACKED_RANGE: Final[float] = 3.0


def sensing_methods() -> tuple[tuple[tuple[str, ControllerSpec], ...], Mapping[str, World]]:
    spec = ControllerSpec("cmpc", PAPER_PREDICTOR)
    worlds = {f"{r:g} m": World().sensing(r) for r in SENSOR_RANGES}
    worlds[f"{UNTRACKED_RANGE:g} m untracked"] = World().sensing(UNTRACKED_RANGE, sensor_tracks=False)
    labels = ("full", *worlds)
    return tuple((label, spec) for label in labels), MappingProxyType(worlds)


SENSING_METHODS, SENSING_WORLDS = sensing_methods()
