"""The /scene channel: each step's foxglove.SceneUpdate as JSON text, from templates fixed per episode.

Agents are spheres, goals small spheres, plans and predictions line strips, coloured as the plots colour them
(``crowdsim.plotting.ROBOT_COLORS``), so that Foxglove's 3D panel and ``crowdmpc review --plot`` agree. The
schema is ``pipelines.logs.foxglove``'s; the recorder (``pipelines.logs.recording``) writes the messages.
"""

from __future__ import annotations

import functools
import json
from typing import Any, Final

import numpy as np

from pipelines.plain_json import plain

FRAME_ID: Final[str] = "world"

# crowdsim.plotting.ROBOT_COLORS (Okabe and Ito's colour-blind-safe palette, then four more) as RGB, so that
# the 3D panel and the plots colour robot i alike (copied: importing the plotting module costs half a second;
# a test keeps the two equal).
ROBOT_RGB: Final[tuple[tuple[float, float, float], ...]] = (
    (0.000, 0.447, 0.698),
    (0.902, 0.624, 0.000),
    (0.000, 0.620, 0.451),
    (0.800, 0.475, 0.655),
    (0.337, 0.706, 0.914),
    (0.835, 0.369, 0.000),
    (0.941, 0.894, 0.259),
    (0.000, 0.000, 0.000),
    (0.549, 0.337, 0.294),
    (0.533, 0.133, 0.333),
    (0.600, 0.600, 0.200),
    (0.200, 0.133, 0.533),
)
HUMAN_RGB: Final[tuple[float, float, float]] = (0.45, 0.45, 0.45)


def _color(rgb: tuple[float, float, float], alpha: float) -> dict[str, float]:
    return {"r": rgb[0], "g": rgb[1], "b": rgb[2], "a": alpha}


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"))


# The hot path formats JSON text from templates: one %-format call per array instead of json.dumps over
# hundreds of small dicts and shortest-repr floats (on_step for 3 robots, 7 humans, H = 12: ~0.9 -> ~0.4 ms).
PLAN_DECIMALS: Final = 6  # /mpc/plan and /mpc/prediction: 1 µm, far below any solver tolerance
SCENE_DECIMALS: Final = 3  # /scene is for the eye: 1 mm
_SCENE_XY: Final = f'"x":%.{SCENE_DECIMALS}f,"y":%.{SCENE_DECIMALS}f'


@functools.lru_cache(maxsize=256)
def _array_template(shape: tuple[int, ...], number: str) -> str:
    """JSON text of a nested array of ``shape`` with ``number`` (a %-format) as each entry."""
    if not shape:
        return number
    inner = _array_template(shape[1:], number)
    return "[" + ",".join([inner] * shape[0]) + "]"


def array_json(values: np.ndarray, decimals: int) -> str:
    """``values`` as JSON nested lists with ``decimals`` fixed decimals; NaN/inf (never expected) as null."""
    if not np.isfinite(values).all():
        return _dumps(plain(np.round(values, decimals)))
    return _array_template(values.shape, f"%.{decimals}f") % tuple(values.ravel().tolist())


_IDENTITY: Final = _dumps({"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0})
_ORIGIN: Final = '{"position":{"x":0.0,"y":0.0,"z":0.0},"orientation":' + _IDENTITY + "}"
_LINE_Z: Final = 0.02  # m, just above the ground so lines are not hidden by it
_POINT: Final = "{" + _SCENE_XY + ',"z":' + repr(_LINE_Z) + "}"
_ENTITY_IDS: Final = ("robots", "humans", "goals", "plans", "predictions", "sensors")
_RING_POINTS: Final = 32  # a sensor's range drawn as a closed strip of this many segments


class SceneBuilder:
    """The per-step foxglove.SceneUpdate as JSON text; colours, sizes and templates fixed once per episode.

    Entities: "robots" and "humans" (spheres of the agents' diameter standing on the ground), "goals" (flat
    discs in the robots' colours), "plans" (a line strip per robot from its position through its plan) and
    "predictions" (a line strip per human through its predicted positions), all in the "world" frame; behind
    a sensor (``sensor_range`` m), "sensors": a ring of that radius per robot, in its colour.
    """

    def __init__(self, n_robots: int, n_humans: int, radius: float, sensor_range: float | None = None):
        diameter = 2.0 * radius
        agent = {"x": diameter, "y": diameter, "z": diameter}
        rgb = [ROBOT_RGB[i % len(ROBOT_RGB)] for i in range(n_robots)]
        self._robots = self._sphere_template([_color(c, 1.0) for c in rgb], agent, radius)
        self._humans = self._sphere_template([_color(HUMAN_RGB, 0.8)] * n_humans, agent, radius)
        self._agent, self._radius = agent, radius
        self._tracked: dict[int, str] = {}  # humans tracked -> their template (replayed crowds)
        self._goals = self._sphere_template(
            [_color(c, 0.6) for c in rgb], {"x": 0.25, "y": 0.25, "z": 0.05}, 0.025
        )
        self._plan_colors = [_dumps(_color(c, 0.9)) for c in rgb]
        self._sensor_colors = [_dumps(_color(c, 0.5)) for c in rgb]
        angles = np.linspace(0.0, 2.0 * np.pi, _RING_POINTS + 1)  # the last point closes the ring
        self._ring = (
            None
            if sensor_range is None
            else sensor_range * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        )
        self._prediction_colors = [_dumps(_color(HUMAN_RGB, 0.6))] * n_humans
        self._lines: dict[tuple[str, int, int], str] = {}  # (kind, points per strip, strips) -> template
        # Each entity: a head before its timestamp, a middle before its spheres, one before its lines, a tail.
        self._entity_parts = {
            eid: (
                '{"timestamp":',
                f',"frame_id":"{FRAME_ID}","id":"{eid}","lifetime":{{"sec":0,"nsec":0}},"frame_locked":false,'
                '"metadata":[],"arrows":[],"cubes":[],"spheres":[',
                '],"cylinders":[],"lines":[',
                '],"triangles":[],"texts":[],"models":[]}',
            )
            for eid in _ENTITY_IDS
        }

    @staticmethod
    def _sphere_template(colors: list[dict], size: dict, z: float) -> str:
        return ",".join(
            '{"pose":{"position":{' + _SCENE_XY + ',"z":' + repr(float(z)) + '},"orientation":' + _IDENTITY
            + '},"size":' + _dumps(size) + ',"color":' + _dumps(color) + "}"
            for color in colors
        )  # fmt: skip

    def _line_template(self, kind: str, colors: list[str], thickness: float, n_points: int) -> str:
        key = (kind, n_points, len(colors))
        if key not in self._lines:
            points = ",".join([_POINT] * n_points)
            self._lines[key] = ",".join(
                '{"type":0,"pose":' + _ORIGIN + ',"thickness":' + repr(thickness)
                + ',"scale_invariant":false,"points":[' + points + '],"color":' + color
                + ',"colors":[],"indices":[]}'
                for color in colors
            )  # fmt: skip
        return self._lines[key]

    def _human_spheres(self, positions: np.ndarray, present: np.ndarray | None) -> str:
        """The humans' spheres: every one, or those a replayed crowd tracks now (the others are not there)."""
        if present is None:
            return self._humans % tuple(positions.ravel().tolist())
        shown = positions[np.asarray(present, dtype=bool)]
        if len(shown) not in self._tracked:
            colors = [_color(HUMAN_RGB, 0.8)] * len(shown)
            self._tracked[len(shown)] = self._sphere_template(colors, self._agent, self._radius)
        return self._tracked[len(shown)] % tuple(shown.ravel().tolist())

    def _entity(self, eid: str, stamp: str, spheres: str = "", lines: str = "") -> str:
        head, before_spheres, before_lines, tail = self._entity_parts[eid]
        return head + stamp + before_spheres + spheres + before_lines + lines + tail

    def update(
        self,
        log_time_ns: int,
        robot_positions: np.ndarray,  # (M, 2)
        robot_goals: np.ndarray,  # (M, 2)
        human_positions: np.ndarray,  # (N, 2)
        plan: np.ndarray | None,  # (M, H, 2)
        prediction: np.ndarray | None,  # (H, N, 2)
        human_present: np.ndarray | None = None,  # (N,) a replayed crowd's humans tracked now
    ) -> bytes:
        sec, nsec = divmod(log_time_ns, 1_000_000_000)
        stamp = f'{{"sec":{sec},"nsec":{nsec}}}'
        plan_lines = prediction_lines = ""
        if plan is not None and np.isfinite(plan).all():
            # each strip starts at the robot so that the plan reads as "from here"
            tracks = np.concatenate([robot_positions[:, None, :], plan], axis=1)
            template = self._line_template("plan", self._plan_colors, 0.05, tracks.shape[1])
            plan_lines = template % tuple(tracks.ravel().tolist())
        if prediction is not None:
            # the humans predicted (a controller behind a sensor, or among a replayed crowd, predicts those
            # in view: NaN for the others)
            predicted = np.flatnonzero(np.isfinite(prediction).all(axis=(0, 2)))
            tracks = np.concatenate(
                [human_positions[predicted, None, :], np.swapaxes(prediction[:, predicted], 0, 1)], axis=1
            )
            colors = self._prediction_colors[: len(predicted)]
            template = self._line_template("prediction", colors, 0.03, tracks.shape[1])
            prediction_lines = template % tuple(tracks.ravel().tolist())
        # Every entity is sent at every step (also those that do not move): after a seek, Foxglove only shows
        # what was published near the new time.
        parts = [
            self._entity("robots", stamp, self._robots % tuple(robot_positions.ravel().tolist())),
            self._entity("humans", stamp, self._human_spheres(human_positions, human_present)),
            self._entity("goals", stamp, self._goals % tuple(robot_goals.ravel().tolist())),
            self._entity("plans", stamp, lines=plan_lines),
            self._entity("predictions", stamp, lines=prediction_lines),
        ]
        if self._ring is not None:  # a run that sees everyone sends no such entity
            rings = robot_positions[:, None, :] + self._ring[None]
            template = self._line_template("sensor", self._sensor_colors, 0.02, rings.shape[1])
            parts.append(self._entity("sensors", stamp, lines=template % tuple(rings.ravel().tolist())))
        entities = ",".join(parts)
        return ('{"deletions":[],"entities":[' + entities + "]}").encode()
