"""JSON schemas of the recorded channels: ours (``crowdmpc.*``) and Foxglove's SceneUpdate, by topic.

Every channel is JSON-encoded with a JSON schema (MCAP's ``jsonschema`` encoding). The ``crowdmpc.*`` schemas
are ours and strict (``required``, no extra properties). ``foxglove.SceneUpdate`` is Foxglove's published
schema, built in ``pipelines.logs.foxglove``; here it only gets its name, so that Foxglove's 3D panel
recognises the channel. Messages are checked against these schemas by ``pipelines.logs.jsonschema``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Final

from pipelines.errors import PipelineError
from pipelines.logs import foxglove

SCHEMA_ENCODING: Final[str] = "jsonschema"  # MCAP's well-known schema encoding for JSON schemas
MESSAGE_ENCODING: Final[str] = "json"
# An episode file's layout, in its "crowdmpc" metadata; bump when a channel's meaning changes; 2:
# /episode/metrics is the EpisodeRecord (pipelines/loop/record.py); 3: log times are wall clock, episode
# start_time_ns + simulation time (before: simulation time from 0). The reader flags a file of another.
EPISODE_FORMAT: Final[str] = "crowdmpc-episode/3"
# The library its header names, as every recording since the first: the reader tells another program's
# MCAP file by it (or, where a header is damaged, by the "crowdmpc" metadata record and our schemas).
LIBRARY: Final[str] = "crowdmpc"
# The start of our schemas' names ("crowdmpc.Robots"), which no other program's schema has.
SCHEMA_PREFIX: Final[str] = "crowdmpc."


@dataclass(frozen=True, eq=False)
class MessageSchema:
    """A named JSON schema, serialised once: the recorder compares and writes ``data``, never the dict."""

    name: str  # e.g. "crowdmpc.Robots", "foxglove.SceneUpdate"
    schema: dict[str, Any]
    data: bytes = field(init=False, repr=False)

    def __post_init__(self):
        if not self.name:
            raise PipelineError("a message schema needs a non-empty name")
        object.__setattr__(self, "data", json.dumps(self.schema, sort_keys=True).encode())

    def same_as(self, other: MessageSchema) -> bool:
        return self is other or (self.name == other.name and self.data == other.data)


# ------------------------------------------------------------------------------------------------------------
# crowdmpc channels. Points are [x, y] in metres in the "world" frame; times are s since the episode start.
# ------------------------------------------------------------------------------------------------------------

_NUMBER: Final = {"type": "number"}
_POINT2: Final = {"type": "array", "items": _NUMBER, "minItems": 2, "maxItems": 2}
_POINTS: Final = {"type": "array", "items": _POINT2}  # (K, 2)
_TRACKS: Final = {"type": "array", "items": _POINTS}  # (A, H, 2) or (H, N, 2)
# (H, N, 2) predicted positions, null for a human not predicted (out of a controller's view)
_PREDICTED_POINT: Final = {
    "type": "array",
    "items": {"type": ["number", "null"]},
    "minItems": 2,
    "maxItems": 2,
}
_PREDICTED: Final = {"type": "array", "items": {"type": "array", "items": _PREDICTED_POINT}}


def _record(title: str, properties: dict[str, Any], optional: tuple[str, ...] = ()) -> dict[str, Any]:
    """A strict object schema: every property required except ``optional``, nothing else allowed."""
    return {
        "title": title,
        "type": "object",
        "properties": properties,
        "required": [name for name in properties if name not in optional],
        "additionalProperties": False,
    }


_STAMP: Final = {
    "time": {"type": "number", "minimum": 0, "description": "s since episode start"},
    "step": {"type": "integer", "minimum": 0},
}

ROBOTS = MessageSchema(
    "crowdmpc.Robots",
    _record(
        "crowdmpc.Robots",
        {
            **_STAMP,
            "positions": {**_POINTS, "description": "(M, 2) m"},
            "velocities": {**_POINTS, "description": "(M, 2) m/s"},
            "goals": {**_POINTS, "description": "(M, 2) m"},
            "actions": {
                "type": ["array", "null"],
                "items": _POINT2,
                "description": "(M, 2) m/s^2 applied (clipped) from this state on; null at the end",
            },
            "commanded": {
                "type": ["array", "null"],
                "items": _POINT2,
                "description": "(M, 2) m/s^2 the controller's command, before clipping; null at the end",
            },
            "reached": {"type": "array", "items": {"type": "boolean"}},
        },
    ),
)

HUMANS = MessageSchema(
    "crowdmpc.Humans",
    _record(
        "crowdmpc.Humans",
        {
            **_STAMP,
            "positions": {**_POINTS, "description": "(N, 2) m"},
            "velocities": {**_POINTS, "description": "(N, 2) m/s"},
            "goals": {**_POINTS, "description": "(N, 2) m"},
            "present": {
                "type": "array",
                "items": {"type": "boolean"},
                "description": "(N,) a replayed crowd's humans tracked now; absent: every human is there",
            },
        },
        optional=("present",),
    ),
)

PLAN = MessageSchema(
    "crowdmpc.Plan",
    _record(
        "crowdmpc.Plan",
        {
            **_STAMP,
            "positions": {**_TRACKS, "description": "(M, H, 2) m, each robot's plan at t+1..t+H (to 1e-6 m)"},
        },
    ),
)

PREDICTION = MessageSchema(
    "crowdmpc.Prediction",
    _record(
        "crowdmpc.Prediction",
        {
            **_STAMP,
            "positions": {
                **_PREDICTED,
                "description": "(H, N_h, 2) m, used by the final solve (to 1e-6 m); null: a human not "
                "predicted (out of the controller's view)",
            },
            "iterations": {
                "type": "array",
                "items": _PREDICTED,
                "description": "(H, N_h, 2) per IBR iteration; empty unless iterations are recorded",
            },
        },
    ),
)

SOLVER = MessageSchema(
    "crowdmpc.Solver",
    _record(
        "crowdmpc.Solver",
        {
            **_STAMP,
            "status": {"type": "string"},
            "solve_time_s": {"type": "number", "minimum": 0},
            "iterations": {"type": "integer", "minimum": 0},
            "potential": {"type": ["number", "null"], "description": "F_t, Eq. (16)"},
            "fallback": {
                "type": ["string", "null"],
                "description": 'null, or the fallback used: the MPCs\' "shifted" or "brake", a plugin\'s own',
            },
            "extra": {"type": "object"},
        },
    ),
)

_COUNTS: Final = {"type": "object", "additionalProperties": {"type": "integer", "minimum": 0}}
_SOLVER_STATS: Final = _record(
    "crowdmpc.SolverStats",
    {
        "steps": {"type": "integer", "minimum": 0},
        "total_ms": {"type": ["number", "null"]},
        **{name: {"type": ["number", "null"]} for name in ("median_ms", "p95_ms", "max_ms")},
        "mean_iterations": {"type": ["number", "null"]},
        "max_iterations": {"type": ["integer", "null"]},
        "fallback_steps": {"type": "integer", "minimum": 0},
        "statuses": _COUNTS,
        "fallbacks": _COUNTS,
    },
)

EPISODE_METRICS = MessageSchema(
    "crowdmpc.EpisodeRecord",
    _record(
        "crowdmpc.EpisodeRecord",
        {
            "seed": {"type": ["integer", "null"], "description": "null: no seed drew it (a gym layout)"},
            "scenario": {"type": "string"},
            "n_humans": {"type": "integer", "minimum": 0},
            "n_robots": {"type": "integer", "minimum": 1},
            "controller": {"type": "string"},
            "predictor": {"type": ["string", "null"]},
            "predictor_sha256": {"type": ["string", "null"]},
            "metrics": {
                "type": "object",
                "description": "crowdsim.metrics.EpisodeMetrics fields; NaN written as null",
                "additionalProperties": {"type": ["number", "boolean", "string", "null", "array"]},
            },
            "solver": _SOLVER_STATS,
        },
    ),
)

SCENE_UPDATE = MessageSchema("foxglove.SceneUpdate", foxglove.SCENE_UPDATE)

# Topic -> schema of every channel an episode recording holds.
CHANNELS: Final[dict[str, MessageSchema]] = {
    "/robots": ROBOTS,
    "/humans": HUMANS,
    "/mpc/plan": PLAN,
    "/mpc/prediction": PREDICTION,
    "/mpc/solver": SOLVER,
    "/scene": SCENE_UPDATE,
    "/episode/metrics": EPISODE_METRICS,
}
