"""The [mpc] keys a controller does not read (``unread_because``): a CMPC column per value of DMPC's update
rule ran the same episodes again under new cell keys (a sweep refuses or skips them, simulate refuses them
given on the command line), and a comparison of two runs that differ only in them differs in nothing their
episodes ran with (``unread_keys``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from pipelines.loop.controllers import ControllerSpec

# The [mpc] keys of the flocking term (Eq. 15) alone: a method without it (table3's NF) keeps one column, not
# a column per value that would run the same episodes again.
FLOCKING_KEYS: Final[frozenset[str]] = frozenset({"w_floc", "d_flock", "flocking_weight"})
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
    }
)
CMPC_KEYS: Final[frozenset[str]] = frozenset({"xi"})  # Algorithm 1's threshold; DMPC stops by epsilon
COUPLED_KEYS: Final[frozenset[str]] = frozenset({"coupled_mode"})  # the coupled NLP's (coupling nlp)


def reads_setting(spec: ControllerSpec, key: str) -> bool:
    """Whether ``spec``'s controller plans with the ``[mpc]`` ``key`` (or the margins): ``unread_because``."""
    return unread_because(spec, key) is None


def unread_because(spec: ControllerSpec, key: str) -> str | None:
    """Why ``spec``'s controller does not read the ``[mpc]`` ``key``, as said of methods ("plan with no MPC"),
    None where it does: ORCA and the straight line have no MPC, a method without flocking (table3's NF,
    w_floc = 0) no flocking term to weigh, CMPC none of DMPC's settings nor DMPC CMPC's, and IBR none of the
    coupled NLP's, so a value of theirs would only run the same episodes again under a new cell key. A
    plugin reads what it likes."""
    if not spec.kind.uses_predictor:
        return "plan with no MPC"
    if key in FLOCKING_KEYS and not spec.flocking:
        return f"plan without the flocking term (NF), which {key} shapes"
    if key in DMPC_KEYS and spec.controller == "cmpc":
        return f"are centralized (CMPC), and {key} is DMPC's"
    if key in CMPC_KEYS and spec.controller == "dmpc":
        return f"are distributed (DMPC), and {key} is CMPC's"
    if key in COUPLED_KEYS and spec.coupling != "nlp":
        return f"couple by {spec.coupling}, and {key} is the coupled NLP's (coupling nlp)"
    return None


def unread_keys(controller: str, coupling: str, flocking: bool) -> frozenset[str]:
    """The [mpc] keys a shipped MPC controller (``cmpc``, ``dmpc``) with this coupling and flocking does not
    read, as a record names them (``unread_because``'s rule; none for another controller, which reads what
    it likes or has no MPC)."""
    if controller not in ("cmpc", "dmpc"):
        return frozenset()
    unread = DMPC_KEYS if controller == "cmpc" else CMPC_KEYS
    if coupling != "nlp":
        unread |= COUPLED_KEYS
    return unread if flocking else unread | FLOCKING_KEYS


def record_unread(record: dict[str, Any]) -> frozenset[str]:
    """``unread_keys`` of an episode record's controller, coupling and flocking (``crowdmpc compare``: a
    CMPC's DMPC settings, recorded by simulate from a file, at Table I's by a sweep of the same episodes)."""
    config = record.get("config")
    if not isinstance(config, dict):
        config = {}
    coupling, flocking = config.get("coupling", "ibr"), config.get("flocking", True)
    return unread_keys(str(record.get("controller")), str(coupling), flocking is not False)
