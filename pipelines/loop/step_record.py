"""What an MPC step planned with beyond the paper, as its records carry it (pipelines.loop.mpc's
``ControlOutput.extra``, MCAP ``/mpc/solver``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from mpc.nlp import StepData


def allowances_record(data: StepData) -> dict[str, Any]:
    """What the step planned with beyond the paper, for records (MCAP ``/mpc/solver`` extra): the robots
    released from flocking (stalled, mpc/stall.py), the parked robots' yield slack (m, mpc/parked.py), each
    human's margins ``(H, N_h)`` (per-class modes) and the robots whose Eq. 8 reference was guided, with
    targets."""
    out: dict[str, Any] = {}
    if data.flocking is not None and not np.all(data.flocking):
        out["unflocked"] = np.flatnonzero(~np.asarray(data.flocking, dtype=bool)).tolist()
    if data.goal_slack is not None and np.any(data.goal_slack > 0):
        slack = np.asarray(data.goal_slack)
        out["yielding"] = {int(i): round(float(slack[i]), 4) for i in np.flatnonzero(slack > 0)}
    if data.human_margins is not None:
        out["human_margins"] = np.round(data.human_margins, 4).tolist()
    if data.targets is not None:
        guided = np.flatnonzero(np.any(data.targets != data.goals, axis=1))
        if guided.size:
            out["guided"] = {int(i): np.round(data.targets[i], 4).tolist() for i in guided}
    return out
