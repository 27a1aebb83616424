"""A pedestrian tracked for fewer steps than the predictor reads: three fills of the rows before the track.

A robot's tracker sees people come into view, and the MPC's predictor reads ``obs_len`` positions of each.
On ETH's real scenes (the paper protocol's val and test files: every primary pedestrian observed throughout
its window), the primary is made to look tracked for only its last ``k`` positions, the rows before filled
by each of:

* ``standing``: its first tracked position repeated (what a history padded like the simulator's says);
* ``backfill``: its track extended back at the track's mean velocity (``predictors.backfill``, what the MPC
  does with a tracker's ``obs.human_observed``);
* ``mask``: the rows marked unobserved (``mask`` False), as a dataset's late neighbours are.

Prints the primary's ADE and FDE over ``--horizon`` steps (the MPC's by default) for each ``k`` and each
fill, beside the same scenes with all ``obs_len`` positions observed. Every other agent is as recorded.

    nice -n 5 .venv/bin/python benchmarks/partial_history.py
    nice -n 5 .venv/bin/python benchmarks/partial_history.py --predictor vanilla_lstm_eth --horizon 12 \\
        --tracked 2 5 --json partial.json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    check_distinct,
    count_in,
    json_on_stdout,
    output_file,
    predictor_name,
    run_main,
    write_json,
)

FILLS = ("standing", "backfill", "mask")


def primary_errors(predictor, xy: np.ndarray, tracked: int | None, fill: str) -> tuple[float, float]:
    """ADE and FDE (m) of agent 0 in one scene ``(obs_len + H, N, 2)`` (NaN = absent), tracked for its last
    ``tracked`` observed positions (None: all), the rows before filled by ``fill``."""
    from predictors.backfill import backfill
    from predictors.evaluate import observed_history

    length = predictor.obs_len
    history, mask, agents = observed_history(xy, length)  # as `crowdmpc evaluate` hands a scene over
    if tracked is not None:
        gap = length - tracked
        if fill == "standing":
            history[:gap, 0] = history[gap, 0]
        elif fill == "backfill":
            counts = np.where(np.arange(len(agents)) == 0, tracked, length)
            history[:, 0] = backfill(history, counts)[:, 0]
        else:
            history[:gap, 0], mask[:gap, 0] = 0.0, False
    horizon = len(xy) - length
    prediction = predictor.rollout(history, mask, None, np.arange(len(agents)), horizon=horizon)[:, 0]
    errors = np.linalg.norm(prediction - xy[length:, 0], axis=-1)
    return float(errors.mean()), float(errors[-1])


def whole_primaries(predictor, splits: list[str], horizon: int) -> list[np.ndarray]:
    """The scenes of ``splits`` cut to ``obs_len + horizon`` steps whose primary is present at every one."""
    from predictors.data.locate import protocol_files
    from predictors.evaluate import EvalConfig, load_eval_scenes

    files = protocol_files(None, "paper")
    config = EvalConfig(obs_len=predictor.obs_len, pred_len=horizon)
    paths = [path for split in splits for path in files[split]]
    scenes = [scene.xy for path in paths for scene in load_eval_scenes(path, config)]
    return [xy for xy in scenes if not np.isnan(xy[:, 0]).any()]


def checked_tracked(parser: argparse.ArgumentParser, name: str, predictor, values: list[int]) -> list[int]:
    """``--tracked``'s values, sorted and once each, for a predictor that reads dataset scenes, else the
    parser's one-line error. The ORCA oracle predicts from the simulator's goals and velocities, which a
    dataset scene lacks (its one observed position left no k to try, and that was all it was told); a k of
    ``obs_len`` or more is no partial track, and leaving it out printed a table without the row asked for."""
    from predictors.errors import PredictorError
    from predictors.evaluate import check_dataset_predictor

    try:
        check_dataset_predictor(predictor)
    except PredictorError as exc:
        parser.error(f"--predictor {name}: {exc}")
    check_distinct(parser, "--tracked", values)
    length = predictor.obs_len
    for k in values:
        if k >= length:
            parser.error(
                f"--tracked {k}: {name} reads {length} positions, so a partial track is 1..{length - 1}"
            )
    return sorted(values)


def main() -> None:
    from predictors.registry import load_predictor

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--predictor", type=predictor_name, default="social_lstm_eth")
    parser.add_argument("--horizon", type=count_in("horizon", 1, 12), default=4)
    parser.add_argument(
        "--tracked", type=count_in("tracked positions", 1), nargs="+", default=[1, 2, 3, 5, 7]
    )
    parser.add_argument("--splits", nargs="+", choices=("train", "val", "test"), default=["val", "test"])
    parser.add_argument("--json", type=output_file, help="write the figures to this file ('-': stdout)")
    args = parser.parse_args()
    predictor = load_predictor(args.predictor)
    tracked = checked_tracked(parser, args.predictor, predictor, args.tracked)
    with json_on_stdout(args.json):
        from tqdm import tqdm

        scenes = whole_primaries(predictor, args.splits, args.horizon)
        rows: dict[str, dict[str, list[float]]] = {"all": {"all": []}}
        rows |= {str(k): {fill: [] for fill in FILLS} for k in tracked}
        for xy in tqdm(scenes, desc="scenes", file=sys.stderr, leave=False):
            rows["all"]["all"].append(primary_errors(predictor, xy, None, "all"))
            for k in tracked:
                for fill in FILLS:
                    rows[str(k)][fill].append(primary_errors(predictor, xy, k, fill))
        table = {k: {f: np.mean(e, axis=0).tolist() for f, e in fills.items()} for k, fills in rows.items()}
        splits = "+".join(args.splits)
        print(f"{args.predictor}, {len(scenes)} scenes ({splits}), primary's ADE / FDE (m) over "
              f"{args.horizon} steps")  # fmt: skip
        whole = table["all"]["all"]
        print(f"  all {predictor.obs_len} observed: {whole[0]:.3f} / {whole[1]:.3f}")
        print("  tracked  " + "".join(f"{fill:>16}" for fill in FILLS))
        for k in tracked:
            print(f"  {k:>7}  " + "".join(f"{a:>9.3f} /{f:>5.2f}" for a, f in table[str(k)].values()))
    if args.json:
        write_json(
            args.json,
            {"predictor": args.predictor, "horizon": args.horizon, "splits": args.splits,
             "scenes": len(scenes), "ade_fde_m": table},
        )  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(run_main(main))
