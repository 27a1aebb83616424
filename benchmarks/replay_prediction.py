"""The predictors among a replayed crowd, open loop: how far off each one's next steps are for the people a
robot's tracker would hand it, as the MPC hands them over.

At every ``--every``-th row of the recording (``--crowd``, crowdsim.replay), each person tracked there and at
the next ``--horizon`` rows is predicted from the last ``obs_len`` rows of everyone tracked now, a short track
extended back at its mean velocity (``predictors.backfill``, what the MPC does with ``obs.human_observed``),
every mask True, no robot. Prints the average displacement error over the horizon (the MPC's 4 steps by
default) and at its last step, for the people tracked for at least TrajNet++'s 9 rows, for 2 to 8 (come into
view lately: part of their history is filled in) and for 1 (just come: nothing is known of their motion, so
every predictor has them stand), the same people for every predictor. ``--by speed`` groups the people
tracked for 9 rows or more by their speed over the last row instead, and prints beside the ADE how much
farther than they went each predictor had them go by the horizon (m; negative: not as far): constant
velocity's guess for people who slow down or speed up, the nets' learned one.

    nice -n 10 .venv/bin/python benchmarks/replay_prediction.py --crowd eth_test
    nice -n 10 .venv/bin/python benchmarks/replay_prediction.py --crowd hotel_test \\
        --predictors constant_velocity social_lstm_eth --every 4
    nice -n 10 .venv/bin/python benchmarks/replay_prediction.py --crowd eth_test --by speed
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdsim.replay import REPLAYED, Recording, track_lengths
from crowdsim.world import HORIZON, OBS_LEN

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import check_distinct, count_in, predictor_name, run_main  # noqa: E402

# Rows tracked: a whole TrajNet++ history, a track come into view lately (part filled in), one just come.
GROUPS = {
    f">= {OBS_LEN}": (OBS_LEN, 10**9),
    f"2..{OBS_LEN - 1}": (2, OBS_LEN - 1),
    "1": (1, 1),
    "all": (1, 10**9),
}
# m/s over the last observed row, for --by speed (the people tracked for OBS_LEN rows or more)
SPEEDS = {"< 0.5": (0.0, 0.5), "0.5..1": (0.5, 1.0), "1..1.5": (1.0, 1.5), ">= 1.5": (1.5, np.inf)}
SHIPPED = ("constant_velocity", "vanilla_lstm_eth", "social_lstm_eth", "social_gan_eth", "social_lstm_synth")


def recording_predictor(text: str) -> str:
    """An argparse ``type``: a predictor ``crowdmpc`` knows that predicts from positions alone; the ORCA
    oracle reads the simulator's state, which a recording has none of."""
    from predictors.oracle import ORACLE_PREDICTOR

    name = predictor_name(text)
    if name == ORACLE_PREDICTOR:
        raise argparse.ArgumentTypeError(
            f"{name} predicts the simulator's humans from its ORCA state, not a recording's people: "
            "name a predictor that reads positions"
        )
    return name


def cases(
    rec: Recording, obs_len: int, horizon: int, every: int
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per evaluated row: the history ``(obs_len, N, 2)`` of everyone tracked there (held before their
    track), their track lengths ``(N,)`` and the true future ``(horizon, N, 2)`` (NaN where not tracked)."""
    tracked = np.isfinite(rec.positions[..., 0])
    run = track_lengths(tracked)
    out = []
    for t in range(obs_len - 1, len(rec.frames) - horizon, every):
        span = rec.frames[t + horizon] - rec.frames[t - obs_len + 1]
        if span != (obs_len - 1 + horizon) * rec.frame_step:  # the grid jumps inside the window
            continue
        people = np.flatnonzero(tracked[t])
        if len(people) == 0:
            continue
        rows = rec.positions[t - obs_len + 1 : t + 1, people].copy()
        for j in range(len(people)):  # before its track: held at its first tracked position in the window
            first = obs_len - min(int(run[t, people[j]]), obs_len)
            rows[:first, j] = rows[first, j]
        out.append((rows, run[t, people], rec.positions[t + 1 : t + 1 + horizon, people]))
    return out


@dataclass(frozen=True)
class Scores:
    """Per scored person (tracked through the horizon), in the order of the cases."""

    ade: np.ndarray  # m, over the horizon
    fde: np.ndarray  # m, at its last step
    run: np.ndarray  # rows tracked up to the predicted row
    speed: np.ndarray  # m/s over the last observed row (0 for a person just come)
    overshoot: np.ndarray  # m, predicted minus true distance from now to the horizon's last position


def errors(predictor, cases_: list, horizon: int, dt: float = 0.4) -> Scores:
    """Each scored person's errors, track length and speed (``Scores``); ``dt``: the recording's step."""
    from predictors.backfill import backfill

    columns: list[list[float]] = [[], [], [], [], []]
    for history, observed, future in cases_:
        filled = backfill(history, np.maximum(observed, 1))
        mask = np.ones(filled.shape[:2], dtype=bool)
        predicted = predictor.rollout(filled, mask, None, np.arange(filled.shape[1]), horizon=horizon)
        whole = np.isfinite(future[..., 0]).all(axis=0)  # tracked through the horizon: scored
        gap = np.linalg.norm(predicted - future, axis=-1)[:, whole]
        now = filled[-1, whole]
        went = np.linalg.norm(future[-1, whole] - now, axis=-1)
        speed = np.linalg.norm(filled[-1] - filled[-2], axis=-1)[whole] / dt
        overshoot = np.linalg.norm(predicted[-1, whole] - now, axis=-1) - went
        for column, values in zip(
            columns, (gap.mean(axis=0), gap[-1], observed[whole], speed, overshoot), strict=True
        ):
            column += values.tolist()
    return Scores(*(np.array(column) for column in columns))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--crowd", default="eth_test", choices=REPLAYED)
    parser.add_argument("--predictors", nargs="+", type=recording_predictor, default=list(SHIPPED))
    parser.add_argument("--horizon", type=count_in("horizon", 1, 12), default=HORIZON)
    parser.add_argument("--every", type=count_in("every", 1), default=1, help="evaluate every k-th row")
    parser.add_argument("--by", choices=("track", "speed"), default="track", help="group by (docstring)")
    args = parser.parse_args()
    check_distinct(parser, "--predictors", args.predictors)  # a repeat scored and printed its row twice
    from pipelines.loop.replay_data import recording
    from predictors.registry import load_predictor

    rec = recording(args.crowd)
    groups = GROUPS if args.by == "track" else SPEEDS
    what = "ADE / FDE (m) by rows tracked"
    if args.by == "speed":
        what = f"ADE / overshoot (m) by speed (m/s) of the people tracked >= {OBS_LEN} rows"
    print(f"{args.crowd}: {args.horizon} steps ahead, every {args.every} row(s); {what}")
    print(f"{'predictor':22s}" + "".join(f"{name:>16s}" for name in groups))
    for name in args.predictors:
        predictor = load_predictor(name)
        # one window for every predictor (TrajNet++'s 9 rows, more for a net that reads more): each scores
        # the same people at the same rows
        length = max(OBS_LEN, predictor.obs_len)
        scores = errors(predictor, cases(rec, length, args.horizon, args.every), args.horizon, rec.dt)
        chosen = [grouped(scores, args.by, group) for group in groups.values()]
        second, sign = (scores.fde, "") if args.by == "track" else (scores.overshoot, "+")
        cells = [
            f"{scores.ade[c].mean():.3f} / {second[c].mean():{sign}.3f}" if c.any() else "-" for c in chosen
        ]
        print(f"{name:22s}" + "".join(f"{cell:>16s}" for cell in cells))
    counts = (int(c.sum()) for c in chosen)
    print("people scored: " + ", ".join(f"{name} {n}" for name, n in zip(groups, counts, strict=True)))


def grouped(scores: Scores, by: str, group: tuple[float, float]) -> np.ndarray:
    """The scored people of ``group``: track lengths within its bounds (inclusive), or, among those tracked
    for ``OBS_LEN`` rows or more, speeds in ``[low, high)``."""
    if by == "track":
        return in_group(scores.run, (int(group[0]), int(group[1])))
    return (scores.run >= OBS_LEN) & (scores.speed >= group[0]) & (scores.speed < group[1])


def in_group(run: np.ndarray, group: tuple[int, int]) -> np.ndarray:
    """The scored people whose track length lies in ``group`` (inclusive bounds)."""
    return (run >= group[0]) & (run <= group[1])


if __name__ == "__main__":
    sys.exit(run_main(main))
