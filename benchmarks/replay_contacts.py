"""Who walks into whom among a replayed crowd: each contact's speeds and where it happens.

Replayed people do not react to the robots (crowdsim.replay), so a contact is either a robot that drove into
someone or someone who walked into a robot that could not get away; a reactive replay's people
(``--crowd eth_test_reactive``, crowdsim.reaction) yield as ORCA's humans do, and the contacts left are
those both sides failed to avoid. Among a reactive crowd it also says how far the robots pushed people off
their tracks (against the plain replay's same episodes, whose people are the recording's).

For the closest robot-human pair of each episode with contact (< 0.6 m, among tracked people), at the state
where it is closest: the person's speed and the robot's over the step before (the person's only where they
were tracked then: someone whose track begins there has none), and the robot's distance from its start and
its goal.

    nice -n 10 .venv/bin/python benchmarks/replay_contacts.py --crowd hotel_test --humans 10 --episodes 20
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from crowdsim.env import EnvConfig
from crowdsim.reaction import reacts
from crowdsim.replay import REACTIVE, REPLAYED, recorded
from crowdsim.scenarios import MAX_HUMANS
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.episode import EpisodeResult, run_episodes
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import count_in, episode_count, predictor_name, run_main, seed_number  # noqa: E402

CONTACT: float = 0.6  # m, the sum of the radii
STANDING: float = 0.2  # m/s: a person slower than this over the step stands


def contact_at(result: EpisodeResult) -> tuple[float, float, float, float, float] | None:
    """Person's and robot's speed (m/s), the robot's distance from its start and goal (m) at the closest
    robot-human approach of ``result`` among tracked people, and 1.0 where the person's track began (after
    the first state) within contact of a robot, else 0.0: someone the recording shows first on top of a robot,
    whom no controller could have seen coming; None without contact."""
    present = result.human_present
    d = np.linalg.norm(result.human_positions[:, None] - result.robot_positions[:, :, None], axis=-1)
    d = np.where(present[:, None, :], d, np.inf)
    if d.min() >= CONTACT:
        return None
    k, i, j = np.unravel_index(np.argmin(d), d.shape)
    before = max(int(k) - 1, 0)
    dt = 0.4
    # NaN where they were not tracked the step before (their track begins at k): the row there is padding,
    # which read as someone standing (0 m/s)
    moved = float(np.linalg.norm(result.human_positions[k, j] - result.human_positions[before, j])) / dt
    human = moved if k > 0 and present[before, j] else math.nan
    robot = float(np.linalg.norm(result.robot_positions[k, i] - result.robot_positions[before, i])) / dt
    start = float(np.linalg.norm(result.robot_positions[k, i] - result.robot_positions[0, i]))
    goal = float(np.linalg.norm(result.robot_positions[k, i] - result.robot_goals[i]))
    untracked = np.flatnonzero(~present[: k + 1, j])
    first = int(untracked[-1]) + 1 if len(untracked) else 0  # the row this track began
    appeared = first > 0 and bool(
        np.linalg.norm(result.robot_positions[first] - result.human_positions[first, j], axis=1).min()
        < CONTACT
    )
    return human, robot, start, goal, float(appeared)


def deflection(result: EpisodeResult, plain: EpisodeResult) -> float:
    """The farthest (m) any tracked person of ``result`` (a reactive replay) was from where ``plain`` (the
    same episode replayed plainly: the recording) has them, over the steps both ran."""
    steps = min(len(result.human_positions), len(plain.human_positions))
    off = np.linalg.norm(result.human_positions[:steps] - plain.human_positions[:steps], axis=-1)
    return float(np.where(result.human_present[:steps], off, 0.0).max(initial=0.0))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--crowd", default="eth_test", choices=(*REPLAYED, *REACTIVE))
    # at least one: an empty crowd has no closest approach to look at
    parser.add_argument(
        "--humans", type=count_in("humans", 1, MAX_HUMANS), default=10, help="people who come by (at least 1)"
    )
    parser.add_argument("--episodes", type=episode_count, default=20, help="per scenario")
    parser.add_argument("--seed", type=seed_number, default=0)
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    args = parser.parse_args()
    config = EnvConfig(crowd=args.crowd)
    people = f"{args.humans} {'person' if args.humans == 1 else 'people'} of {args.crowd}"
    print(f"CMPC with {args.predictor} among {people}, {counted(args.episodes, 'episode')} each")
    for scenario in ("circle", "perpendicular"):
        spec = ControllerSpec("cmpc", args.predictor)
        results = run_episodes(
            spec, episodes=args.episodes, seed=args.seed, scenario=scenario, n_humans=args.humans,
            env_config=config, progress=False,
        )  # fmt: skip
        if reacts(args.crowd):
            plain_config = EnvConfig(crowd=str(recorded(args.crowd)))
            plain = run_episodes(
                spec, episodes=args.episodes, seed=args.seed, scenario=scenario, n_humans=args.humans,
                env_config=plain_config, progress=False,
            )  # fmt: skip
            pushed = np.array([deflection(r, p) for r, p in zip(results, plain, strict=True)])
            print(
                f"{scenario:13s} people pushed off their tracks: by more than 0.1 m in "
                f"{int((pushed > 0.1).sum())} of {counted(len(pushed), 'episode')}; the farthest, median "
                f"{np.median(pushed):.2f} m, "
                f"largest {pushed.max():.2f} m"
            )
        rows = np.array([c for c in map(contact_at, results) if c is not None]).reshape(-1, 5)
        line = f"{scenario:13s} contact in {len(rows)} of {counted(len(results), 'episode')}"
        if len(rows):
            _, robot, start, goal, _ = np.median(rows, axis=0)
            speeds = rows[np.isfinite(rows[:, 0]), 0]  # those tracked the step before
            human = f"{np.median(speeds):.2f} m/s" if len(speeds) else "-"
            line += (
                f"; medians: person {human} (of the {len(speeds)} tracked the step before), robot "
                f"{robot:.2f} m/s, {start:.1f} m from its start and "
                f"{goal:.1f} m from its goal; person standing in {int((rows[:, 0] < STANDING).sum())}, robot "
                f"within 1 m of its goal in {int((rows[:, 3] < 1.0).sum())}; the person appearing in contact "
                f"in {int(rows[:, 4].sum())}"
            )
        print(line)


if __name__ == "__main__":
    sys.exit(run_main(main))
