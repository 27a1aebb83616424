"""A small fixed batch of closed-loop episodes whose outcome must not change when the code is reorganised.

``python -m tests.pipelines.behaviour`` writes ``tests/data/behaviour.json`` from the code as it stands;
``test_behaviour.py`` runs the same batch and compares. Regenerate only for a change that is meant to alter
behaviour, and say so in the commit.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

from crowdsim.profiles import make_env_config
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.margins import parse_margins

STORED = Path(__file__).resolve().parents[1] / "data" / "behaviour.json"

# name: (spec, scenario, seed, humans, robots); short problems so the batch takes seconds
CASES: dict[str, tuple[ControllerSpec, str, int, int, int]] = {
    "cmpc_cv": (ControllerSpec("cmpc", "constant_velocity"), "circle", 3, 4, 3),
    "dmpc_cv": (ControllerSpec("dmpc", "constant_velocity"), "perpendicular", 5, 4, 3),
    "coupled_lstm": (ControllerSpec("cmpc", "social_lstm_soft_eth", coupling="nlp"), "circle", 1, 3, 2),
    "oracle_cmpc": (ControllerSpec("cmpc", "orca_oracle"), "perpendicular", 2, 4, 3),
    "cmpc_margins": (
        ControllerSpec("cmpc", "constant_velocity", margins=parse_margins("fixed:0.1,0.2,0.3,0.4")),
        "circle",
        4,
        4,
        3,
    ),
}
RECORDED = "cmpc_cv"  # the case whose MCAP messages are compared too
# keys whose values are wall-clock, not behaviour ("timestamp": /scene's stamps, its wall-clock log time)
TIMING = ("time_s", "_ms", "solve_time", "wall", "timestamp")


def _numbers(value: Any, key: str = "") -> tuple[float, int]:
    """Sum of |x| and count over the numeric leaves of a decoded message, wall-clock fields left out."""
    if any(t in key for t in TIMING):
        return 0.0, 0
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return 0.0, 0
    if isinstance(value, int | float):
        return (abs(float(value)), 1) if math.isfinite(value) else (0.0, 1)
    items = value.items() if isinstance(value, dict) else ((key, v) for v in value)
    total, count = 0.0, 0
    for k, v in items:
        s, c = _numbers(v, k)
        total, count = total + s, count + c
    return total, count


def mcap_digest(path: Path) -> dict[str, list[float]]:
    """Per topic: messages, numeric leaves and the sum of their magnitudes."""
    out: dict[str, list[float]] = {}
    with path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            total, count = _numbers(json.loads(message.data))
            row = out.setdefault(channel.topic, [0, 0, 0.0])
            row[0] += 1
            row[1] += count
            row[2] += total
    return out


def run_batch(mcap_dir: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    env = make_env_config("paper")
    for name, (spec, scenario, seed, humans, robots) in CASES.items():
        controller = make_controller(spec, env)
        observers = []
        if name == RECORDED:
            observers.append(McapEpisodeRecorder(mcap_dir))
        try:
            result = run_episode(
                controller,
                seed=seed,
                scenario=scenario,
                n_humans=humans,
                n_robots=robots,
                env_config=env,
                observers=observers,
            )
        finally:
            close = getattr(controller, "close", None)
            if close is not None:
                close()
        out[name] = {
            "metrics": {k: v for k, v in result.metrics.as_dict().items()},
            "steps": len(result.solve_times_s),
            "iterations": int(np.sum(result.iterations)),
            "fallbacks": dict(Counter(f for f in result.fallbacks if f is not None)),
            "robot_path_sum": float(np.abs(result.robot_positions).sum()),
            "human_path_sum": float(np.abs(result.human_positions).sum()),
        }
    (path,) = sorted(mcap_dir.glob("*.mcap"))
    out["mcap"] = mcap_digest(path)
    return out


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        batch = run_batch(Path(tmp))
    STORED.write_text(json.dumps(batch, indent=1, sort_keys=True) + "\n")
    print(f"wrote {STORED}")
