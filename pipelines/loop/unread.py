"""The [mpc] keys a controller does not read (``unread_because``), or reads only under another key's value
(``READ_UNDER``: dmpc_relaxation under the relaxed update): a CMPC column per value of DMPC's update
rule ran the same episodes again under new cell keys (a sweep refuses or skips them, simulate refuses them
given on the command line), and a comparison of two runs that differ only in them differs in nothing their
episodes ran with (``record_unread``)."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Final

from mpc.config import MPCConfig

if TYPE_CHECKING:
    from pipelines.loop.controllers import ControllerSpec

# The [mpc] keys of the flocking term (Eq. 15) alone: a method without it (table3's NF) keeps one column, not
# a column per value that would run the same episodes again.
FLOCKING_KEYS: Final[frozenset[str]] = frozenset(
    {"w_floc", "d_flock", "flocking_weight", "flock_distance", "flock_range"}
)
# The [mpc] keys one controller reads and the other does not (mpc/dmpc*.py, mpc/cmpc.py, mpc/coupled.py): a
# CMPC column per value of DMPC's update rule ran the same episodes again under new cell keys.
DMPC_KEYS: Final[frozenset[str]] = frozenset(
    {
        "epsilon",
        "dmpc_parallel",
        "dmpc_update",
        "dmpc_relaxation",
        "dmpc_stop",
        "dmpc_start",
        "dmpc_order",
        "dmpc_pairs",
        "dmpc_conflicts",
    }
)
CMPC_KEYS: Final[frozenset[str]] = frozenset({"xi"})  # Algorithm 1's threshold; DMPC stops by epsilon
COUPLED_KEYS: Final[frozenset[str]] = frozenset({"coupled_mode"})  # the coupled NLP's (coupling nlp)
# The [mpc] keys an MPC reads only under another key's value: (that key, the value). The relaxed step of
# mpc/dmpc_keep.py, Gauss-Seidel's order (mpc/dmpc.py), the restart from braking past restart_penalty
# (mpc/nlp.py, mpc/dmpc.py) and the discs of guidance "standing" (pipelines/loop/mpc.py): a --vary over
# dmpc_relaxation under Jacobi ran the same episodes once a value under new cell keys.
READ_UNDER: Final[Mapping[str, tuple[str, Any]]] = MappingProxyType(
    {
        "dmpc_relaxation": ("dmpc_update", "relaxed"),
        "dmpc_order": ("dmpc_update", "gauss_seidel"),
        "restart_penalty": ("multi_start", True),
        "guidance_clearance": ("guidance", "standing"),
    }
)
_TABLE_I: Final[Mapping[str, Any]] = MappingProxyType(
    {
        field.name: field.default
        for field in dataclasses.fields(MPCConfig)
        if field.name in dict(READ_UNDER.values())
    }
)


def reads_setting(spec: ControllerSpec, key: str, *, by_values: bool = True) -> bool:
    """Whether ``spec``'s controller plans with the ``[mpc]`` ``key`` (or the margins): ``unread_because``."""
    return unread_because(spec, key, by_values=by_values) is None


def unread_because(spec: ControllerSpec, key: str, *, by_values: bool = True) -> str | None:
    """Why ``spec``'s controller does not read the ``[mpc]`` ``key``, as said of methods ("plan with no MPC"),
    None where it does: ORCA and the straight line have no MPC, a method without flocking (table3's NF,
    w_floc = 0) no flocking term to weigh, CMPC none of DMPC's settings nor DMPC CMPC's, and IBR none of the
    coupled NLP's, so a value of theirs would only run the same episodes again under a new cell key. A
    plugin reads what it likes. ``by_values``: a shipped MPC's ``READ_UNDER`` keys too, under the values of
    ``spec.mpc_overrides`` (Table I's where absent); without, the controller alone decides, as it did the
    cell keys of a file's values before (a folder swept with such a file keeps its cells)."""
    if not spec.kind.uses_predictor:
        return "plan with no MPC"
    why = _unread(spec.controller, spec.coupling, spec.flocking, key)
    if why is None and by_values and spec.controller in ("cmpc", "dmpc"):
        return unread_under(dict(spec.mpc_overrides), key)
    return why


def unread_under(values: Mapping[str, Any], key: str) -> str | None:
    """Why an MPC planning with the ``[mpc]`` ``values`` (Table I's where absent) does not read ``key``
    (``READ_UNDER``), None where it does."""
    if key not in READ_UNDER:
        return None
    other, needed = READ_UNDER[key]
    value = values.get(other, _TABLE_I[other])
    if value == needed:
        return None
    shown, read = json.dumps(value), json.dumps(needed)
    return f"plan with {other} = {shown}, and {key} is read under {other} = {read} only"


def _unread(controller: str, coupling: str, flocking: bool, key: str) -> str | None:
    """``unread_because``'s rule for a controller that plans with an MPC."""
    if key in FLOCKING_KEYS and not flocking:
        return f"plan without the flocking term (NF), which {key} shapes"
    if key in DMPC_KEYS and controller == "cmpc":
        return f"are centralized (CMPC), and {key} is DMPC's"
    if key in CMPC_KEYS and controller == "dmpc":
        return f"are distributed (DMPC), and {key} is CMPC's"
    if key in COUPLED_KEYS and coupling != "nlp":
        return f"couple by {coupling}, and {key} is the coupled NLP's (coupling nlp)"
    return None


def record_unread(record: dict[str, Any]) -> frozenset[str]:
    """The [mpc] keys an episode record's controller does not read, by ``unread_because``'s rule, for a
    shipped MPC controller (cmpc, dmpc; none for another, which reads what it likes or has no MPC):
    ``crowdmpc compare``'s, where a CMPC's DMPC settings were recorded by simulate from a file and at
    Table I's by a sweep of the same episodes."""
    controller = str(record.get("controller"))
    if controller not in ("cmpc", "dmpc"):
        return frozenset()
    config = record.get("config")
    if not isinstance(config, dict):
        config = {}
    coupling, flocking = str(config.get("coupling", "ibr")), config.get("flocking", True) is not False
    values = config.get("mpc")
    values = values if isinstance(values, dict) else {}
    keys = FLOCKING_KEYS | DMPC_KEYS | CMPC_KEYS | COUPLED_KEYS | READ_UNDER.keys()
    return frozenset(
        key
        for key in keys
        if _unread(controller, coupling, flocking, key) is not None or unread_under(values, key) is not None
    )
