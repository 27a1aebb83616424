"""How often ORCA crowds overlap: physical contact (< 0.6 m) between ANY two agents, humans included.

Seeded episodes (episode i uses seed + i) with ORCA-driven robots, as ``crowdmpc simulate --controller orca``
runs them; per episode the smallest centre distance over all pairs and steps, split into robot-robot,
robot-human and human-human. Also: how many episodes a human needed RVO2's 3-D linear program (the
infeasible case, where ORCA itself gives up collision-freedom), and whether contacts happen only then.

    nice -n 10 .venv/bin/python benchmarks/orca_contacts.py --scenario circle --humans 9 --episodes 200
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from crowdsim.baselines import OrcaController
from crowdsim.env import CrowdEnv
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import episode_bar, episode_count, human_count, robot_count, run_main, seed_number  # noqa: E402

CONTACT: float = 0.6  # m, sum of the radii


def pair_distances(positions: np.ndarray) -> np.ndarray:
    """(T, P) centre distances of every pair of agents in ``positions (T, A, 2)``."""
    d = np.linalg.norm(positions[:, :, None] - positions[:, None], axis=-1)
    iu = np.triu_indices(positions.shape[1], 1)
    return d[:, iu[0], iu[1]]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenario", default="circle", choices=("circle", "perpendicular"))
    parser.add_argument("--humans", type=human_count, default=9)
    parser.add_argument("--robots", type=robot_count, default=3)
    parser.add_argument("--episodes", type=episode_count, default=200)
    parser.add_argument("--seed", type=seed_number, default=0)
    args = parser.parse_args()
    if args.robots + args.humans < 2:  # no pair of agents: no distance to take a minimum of
        parser.error(f"--robots {args.robots} and --humans {args.humans}: at least two agents make a pair")

    env, controller = CrowdEnv(), OrcaController()
    m = args.robots
    minima = {"any": [], "robot-robot": [], "robot-human": [], "human-human": []}
    lp3_episodes = contact_without_lp3 = timeouts = 0
    for i in episode_bar(args.episodes, f"ORCA {args.scenario} M={m} N={args.humans}"):
        obs = env.reset(args.seed + i, args.scenario, args.humans, m)
        controller.reset(obs)
        done, lp3 = False, [0]  # lp3[k]: humans on the 3-D program in the step that produced row k
        while not done:
            obs, done, info = env.step(controller.act(obs).accelerations)
            lp3.append(info["orca_lp3"])
        timeouts += bool(info["timeout"])
        traj = env.trajectory()
        p = np.concatenate([traj.robot_positions, traj.human_positions], axis=1)
        d = pair_distances(p)
        kind = np.array([
            "robot-robot" if b < m else ("robot-human" if a < m else "human-human")
            for a, b in zip(*np.triu_indices(p.shape[1], 1), strict=True)
        ])  # fmt: skip
        minima["any"].append(d.min())
        for name in ("robot-robot", "robot-human", "human-human"):
            minima[name].append(d[:, kind == name].min() if (kind == name).any() else np.inf)
        lp3_episodes += any(lp3)
        rows = np.flatnonzero(d.min(axis=1) < CONTACT)
        contact_without_lp3 += bool(len(rows)) and not any(lp3[r] for r in rows)

    n = args.episodes
    episodes = counted(n, "episode")
    print(f"{episodes}, {args.scenario} crossing, {counted(args.humans, 'human')}, "
          f"{counted(m, 'ORCA robot')}, seeds "
          f"{args.seed}..{args.seed + n - 1}")  # fmt: skip
    for name, values in minima.items():
        v = np.array(values)
        if not np.isfinite(v).any():  # one robot: no robot-robot pair (it printed "inf m")
            print(f"  {name:<12} no pair of this kind")
            continue
        print(f"  {name:<12} contact (< {CONTACT} m) in {int((v < CONTACT).sum()):>3} / {episodes};"
              f" smallest distance {v.min():.3f} m")  # fmt: skip
    print(f"  episodes where some human needed the 3-D linear program: {lp3_episodes} / {n}")
    print(f"  episodes with a contact at a step where no human needed the 3-D program: {contact_without_lp3}")
    print(f"  episodes that hit the {env.config.time_limit:g} s time limit: {timeouts} / {n}")


if __name__ == "__main__":
    raise SystemExit(run_main(main))
