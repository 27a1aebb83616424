"""The rules between ``MPCConfig``'s fields: a setting that only one value of another field reads, refused
under the others where it is not its default (``check_combinations``, from ``MPCConfig.__post_init__``).

Such a value changes nothing that runs: ``--set mpc.dmpc_relaxation=0.3`` under Jacobi's update planned as
0.5 does, and a sweep's ``--vary mpc.dmpc_relaxation=0.3,0.7`` ran the same episodes twice under two cell
keys. Each message names the field, its value and the one that would read it."""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from mpc.errors import MPCConfigError

# ``cfg`` below is an ``mpc.config.MPCConfig`` (typed Any: that module imports this one, without a cycle)


def check_combinations(cfg: Any) -> None:
    """``MPCConfigError`` for a field set where the other fields leave it unread, or that needs another."""
    if cfg.dmpc_order != "index" and cfg.dmpc_update != "gauss_seidel":
        raise MPCConfigError(
            f"dmpc_order {cfg.dmpc_order!r} orders gauss_seidel's rounds; dmpc_update is {cfg.dmpc_update!r}"
        )
    if cfg.dmpc_pairs and not cfg.stall_release_s:
        raise MPCConfigError(
            "dmpc_pairs moves stalled robots, and stall_release_s = 0 marks none stalled: set "
            "stall_release_s > 0"
        )
    if _changed(cfg, "dmpc_relaxation") and cfg.dmpc_update != "relaxed":
        raise MPCConfigError(
            f"dmpc_relaxation = {cfg.dmpc_relaxation!r} sizes the relaxed update's step; dmpc_update is "
            f'{cfg.dmpc_update!r}, which does not read it (set dmpc_update = "relaxed", or leave it out)'
        )


def _changed(cfg: Any, name: str) -> bool:
    """Whether ``cfg``'s field ``name`` differs from its default (MPCConfig's own)."""
    return bool(getattr(cfg, name) != _default(cfg, name))


def _default(cfg: Any, name: str) -> Any:
    return next(f.default for f in fields(cfg) if f.name == name)
