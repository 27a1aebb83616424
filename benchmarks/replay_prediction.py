"""The predictors among a replayed crowd, open loop: how far off each one's next steps are for the people a
robot's tracker would hand it, as the MPC hands them over.

At every ``--every``-th row of the recording (``--crowd``, crowdsim.replay), each person tracked there and at
the next ``--horizon`` rows is predicted from the last ``obs_len`` rows of everyone tracked now, a short track
extended back at its mean velocity (``predictors.backfill``, what the MPC does with ``obs.human_observed``),
every mask True, no robot. Prints the average displacement error over the horizon (the MPC's 4 steps by
default) and at its last step, for the people tracked for at least TrajNet++'s 9 rows, for 2 to 8 (come into
view lately: part of their history is filled in) and for 1 (just come: nothing is known of their motion, so
every predictor has them stand), the same people for every predictor.

    nice -n 10 .venv/bin/python benchmarks/replay_prediction.py --crowd eth_test
    nice -n 10 .venv/bin/python benchmarks/replay_prediction.py --crowd hotel_test \\
        --predictors constant_velocity social_lstm_eth --every 4
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from crowdsim.replay import REPLAYED, Recording, track_lengths
from crowdsim.world import HORIZON, OBS_LEN

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, predictor_name, run_main  # noqa: E402

# Rows tracked: a whole TrajNet++ history, a track come into view lately (part filled in), one just come.
GROUPS = {
    f">= {OBS_LEN}": (OBS_LEN, 10**9),
    f"2..{OBS_LEN - 1}": (2, OBS_LEN - 1),
    "1": (1, 1),
    "all": (1, 10**9),
}
SHIPPED = ("constant_velocity", "vanilla_lstm_eth", "social_lstm_eth", "social_gan_eth", "social_lstm_synth")


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


def errors(predictor, cases_: list, horizon: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per scored person: ADE and FDE over the horizon (m), and its track length."""
    from predictors.backfill import backfill

    ade, fde, run = [], [], []
    for history, observed, future in cases_:
        filled = backfill(history, np.maximum(observed, 1))
        mask = np.ones(filled.shape[:2], dtype=bool)
        predicted = predictor.rollout(filled, mask, None, np.arange(filled.shape[1]), horizon=horizon)
        whole = np.isfinite(future[..., 0]).all(axis=0)  # tracked through the horizon: scored
        gap = np.linalg.norm(predicted - future, axis=-1)[:, whole]
        ade += gap.mean(axis=0).tolist()
        fde += gap[-1].tolist()
        run += observed[whole].tolist()
    return np.array(ade), np.array(fde), np.array(run)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--crowd", default="eth_test", choices=REPLAYED)
    parser.add_argument("--predictors", nargs="+", type=predictor_name, default=list(SHIPPED))
    parser.add_argument("--horizon", type=count_in("horizon", 1, 12), default=HORIZON)
    parser.add_argument("--every", type=count_in("every", 1), default=1, help="evaluate every k-th row")
    args = parser.parse_args()
    from pipelines.loop.replay_data import recording
    from predictors.registry import load_predictor

    rec = recording(args.crowd)
    print(
        f"{args.crowd}: {args.horizon} steps ahead, every {args.every} row(s); ADE / FDE (m) by rows tracked"
    )
    print(f"{'predictor':22s}" + "".join(f"{name:>16s}" for name in GROUPS))
    for name in args.predictors:
        predictor = load_predictor(name)
        # one window for every predictor (TrajNet++'s 9 rows, more for a net that reads more): each scores
        # the same people at the same rows
        length = max(OBS_LEN, predictor.obs_len)
        ade, fde, run = errors(predictor, cases(rec, length, args.horizon, args.every), args.horizon)
        cells = [
            f"{ade[chosen].mean():.3f} / {fde[chosen].mean():.3f}" if chosen.any() else "-"
            for chosen in (in_group(run, group) for group in GROUPS.values())
        ]
        print(f"{name:22s}" + "".join(f"{cell:>16s}" for cell in cells))
    counts = (int(in_group(run, group).sum()) for group in GROUPS.values())
    print("people scored: " + ", ".join(f"{name} {n}" for name, n in zip(GROUPS, counts, strict=True)))


def in_group(run: np.ndarray, group: tuple[int, int]) -> np.ndarray:
    """The scored people whose track length lies in ``group`` (inclusive bounds)."""
    return (run >= group[0]) & (run <= group[1])


if __name__ == "__main__":
    sys.exit(run_main(main))
