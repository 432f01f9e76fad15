"""What a step of self-play's opponent pool costs: its learned members deciding one by one, or stacked.

    python benchmarks/bench_opponents.py [--config tuned] [--belief bimdn] [--set belief_settings.hidden=64] \\
        [--role evader] [--members 1 2 4 8 16] [--games 16] [--steps 400] [--repeats 3]
    python benchmarks/bench_opponents.py --checkpoints 'runs/x/zoo/RUN/evader/round-*.zip' --role evader

Self-play's opponent is a :class:`~pecli.policies.mixed.MixedPolicy` over the pool, each of the ``n_envs`` games
played by the member drawn for it, so a step holds many learned members with a game or two each. This plays K
members (uniform draws) against random actions of the other side in the scenario's batched game and times
``MixedPolicy.act`` per game step (CPU time of this process, one torch thread): members deciding one by one
(each its own network call) against members of one network shape stacked (:mod:`pecli.policies.stacked`).
The two modes alternate within each repeat and the medians are printed with their ratio.

The members are fresh networks of the config's shape (``--belief``, ``--set`` for sizes): what a member costs
depends on its shape, not its weights. ``--checkpoints`` takes trained ones instead (reused in turn if fewer
than K). Each mode also checks that the two give the same actions on the same observations (up to 1e-4).
"""

from __future__ import annotations

import argparse
import copy
import glob
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch as th  # noqa: E402

from pecli.errors import PecliError  # noqa: E402
from pecli.game.game import Game  # noqa: E402
from pecli.policies.learned import LearnedPolicy  # noqa: E402
from pecli.policies.mixed import MixedPolicy  # noqa: E402
from pecli.policies.registry import resolve_policy  # noqa: E402
from pecli.roles import opponent_of  # noqa: E402
from pecli.scenario import Scenario, load_scenario  # noqa: E402


def fresh_members(scenario: Scenario, role: str, count: int) -> list[LearnedPolicy]:
    """``count`` untrained learned players of ``scenario``'s network shape (seeds 0 .. count-1)."""
    from pecli.rl.train import TrainJob, checkpoint_meta, make_learner

    members = []
    with tempfile.TemporaryDirectory() as zoo:
        for seed in range(count):
            job = TrainJob(role=role, scenario=scenario, opponent="random-walk", zoo=Path(zoo), name="bench", seed=seed)
            other = resolve_policy("random-walk", opponent_of(role), scenario, seed=seed)
            _, model, _ = make_learner(job, other, seed)
            members.append(LearnedPolicy(model.policy.actor, role, scenario, checkpoint_meta(job, model, 0)))
    return members


def mixed(members: list[LearnedPolicy], stacked: bool, games: int) -> MixedPolicy:
    """A pool of copies of ``members`` (each pool keeps its own memories), drawn uniformly."""
    members = [copy.deepcopy(member) for member in members]
    policy = MixedPolicy(members[0].role, members, [f"m{i}" for i in range(len(members))], stack=stacked)
    policy.reset(games, seed=0)
    return policy


def play(policies: list[MixedPolicy], scenario: Scenario, steps: int, games: int) -> tuple[list[float], float]:
    """Step one game batch with ``policies`` all acting on the same observations (the first one's actions are
    played); CPU seconds of each per game step, and the largest difference between their actions."""
    role = policies[0].role
    game = Game(scenario, games, seed=0, auto_reset=True)
    obs = game.reset(seed=0)
    rng = np.random.default_rng(0)
    spent, worst = [0.0] * len(policies), 0.0
    for _ in range(steps):
        actions = []
        for j, policy in enumerate(policies):
            start = time.process_time()
            actions.append(policy.act(obs[role]))
            spent[j] += time.process_time() - start
        worst = max(worst, max(float(np.abs(a - actions[0]).max()) for a in actions))
        other = rng.uniform(-1, 1, (games, 2))
        result = game.step(*((actions[0], other) if role == "pursuer" else (other, actions[0])))
        obs = result.obs
        if result.done.any():
            for policy in policies:
                policy.reset(games, mask=result.done)
    return [s / steps for s in spent], worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="tuned")
    parser.add_argument("--belief", default="bimdn", help="the members' belief (fresh members)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a training setting of the fresh members, e.g. belief_settings.hidden=64",
    )
    parser.add_argument("--checkpoints", default=None, help="a glob of trained checkpoints instead of fresh members")
    parser.add_argument("--role", default="evader", choices=["pursuer", "evader"])
    parser.add_argument("--members", nargs="+", type=int, default=[1, 2, 4, 8, 16])
    parser.add_argument("--games", type=int, default=None, help="games in the batch (default: the config's n_envs)")
    parser.add_argument("--steps", type=int, default=400, help="game steps per measurement")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    th.set_num_threads(1)
    try:
        scenario = load_scenario(args.config)
        if args.checkpoints:
            paths = sorted(glob.glob(args.checkpoints))
            if not paths:
                sys.exit(f"--checkpoints {args.checkpoints}: no checkpoint there")
            pool = [
                resolve_policy(paths[i % len(paths)], args.role, scenario, seed=i) for i in range(max(args.members))
            ]
            what = f"{len(paths)} checkpoints of {args.checkpoints}"
        else:
            from pecli.rl.train import parse_overrides, with_overrides

            settings = {"belief": args.belief, **parse_overrides(args.overrides)}
            scenario = with_overrides(scenario, settings, source="options")
            pool = fresh_members(scenario, args.role, max(args.members))
            what = f"fresh {args.role}s, " + ", ".join(f"{k}={v}" for k, v in settings.items())
    except PecliError as error:
        sys.exit(str(error))
    games = args.games or scenario.training.n_envs
    print(f"{scenario.name}: {what}; {games} games, {args.steps} game steps, median of {args.repeats}\n")
    print("| members | distinct in the first draw | one by one, ms per game step | stacked | ratio |")
    print("| ---: | ---: | ---: | ---: | ---: |")
    for count in args.members:
        members = pool[:count]
        times: dict[bool, list[float]] = {False: [], True: []}
        for repeat in range(args.repeats):
            order = [False, True] if repeat % 2 == 0 else [True, False]
            policies = [mixed(members, stacked, games) for stacked in order]
            spent, worst = play(policies, scenario, args.steps, games)
            if worst > 1e-4:
                sys.exit(f"{count} members: stacked and one-by-one actions differ by {worst:.2g}")
            for stacked, seconds in zip(order, spent):
                times[stacked].append(1000 * seconds)
        distinct = len(np.unique(mixed(members, True, games).assignment))
        alone, together = statistics.median(times[False]), statistics.median(times[True])
        print(f"| {count} | {distinct} | {alone:.2f} | {together:.2f} | {together / alone:.2f} |", flush=True)


if __name__ == "__main__":
    main()
