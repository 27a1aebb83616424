"""A config file's key and section, as the schema (``pipelines.config.schema``) declares them, and the bounds
on numbers that size the work: the vocabulary every section's table is written in."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal

from crowdsim.env_config import ENV_BOUNDS
from crowdsim.orca import MAX_NEIGHBORS
from crowdsim.world import MOST_OBS_LEN
from mpc.sizes import MAX_HORIZON, MOST_IBR_ITERATIONS, MOST_SOLVER_ITER, MOST_STEP_TIME

Kind = Literal["int", "float", "bool", "str", "ints", "strs"]


@dataclass(frozen=True)
class Key:
    name: str
    kind: Kind
    default: Any  # None: no single default (printed commented out, with `example`)
    note: str  # the comment `config show` prints: symbol, unit, equation, Table I value, CLI option
    example: Any = None  # the commented-out value of a key without a default
    most: float | None = None  # an upper bound on a number that sizes work (MOST)


@dataclass(frozen=True)
class Section:
    name: str  # "mpc", "env.orca"
    doc: str  # the comment above the section
    keys: tuple[Key, ...]
    # values (every key: default or chosen) and the sections built before -> the validated object
    build: Callable[[dict[str, Any], Mapping[str, Any]], Any]
    elsewhere: Mapping[str, str] = dataclasses.field(default_factory=dict)  # refused key -> where it goes

    def key(self, name: str) -> Key | None:
        return next((k for k in self.keys if k.name == name), None)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(k.name for k in self.keys)


def kind_of(value: Any) -> Kind:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "float"
    if isinstance(value, str):
        return "str"
    raise TypeError(f"no config kind for {value!r}")


# Numbers that size the work (NLP size, iterations, history rows, ORCA neighbours, episode length) are
# bounded before anything runs, so that the refusal names the key. Far above any sensible value. They are the
# dataclasses' own bounds, read from crowdsim and mpc.sizes, which refuse the same values from Python (the
# episode's steps too: EnvConfig, crowdsim.world.MOST_EPISODE_STEPS). (Numbers whose huge or tiny values
# overflow the arithmetic are bounded by their dataclass alone, for every caller: crowdsim.env_config's
# ENV_BOUNDS, OrcaParams' neighbor_dist and time_horizon; mpc.config's MPC_BOUNDS and MPC_LEAST by the NLP
# as it is built, mpc.nlp.check_solvable.)
MOST: Final[Mapping[str, float]] = {
    "world.obs_len": MOST_OBS_LEN,
    "env.time_limit": ENV_BOUNDS["time_limit"][0],  # s
    "env.orca.max_neighbors": MAX_NEIGHBORS,
    "mpc.horizon": MAX_HORIZON,
    "mpc.j_max": MOST_IBR_ITERATIONS,
    "mpc.solver_max_iter": MOST_SOLVER_ITER,
    "mpc.time_limit_s": MOST_STEP_TIME,
}


def keys_of(obj: Any, names: tuple[str, ...], notes: Mapping[str, str], section: str) -> tuple[Key, ...]:
    return tuple(
        Key(
            name,
            kind_of(getattr(obj, name)),
            getattr(obj, name),
            notes[name],
            most=MOST.get(f"{section}.{name}"),
        )
        for name in names
    )
