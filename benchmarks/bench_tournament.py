"""Tournament speed: episodes/s of batched pairings vs the same episodes one game at a time.

    python benchmarks/bench_tournament.py                       # built-in players, paper scenario
    python benchmarks/bench_tournament.py --zoo runs/bench_train --episodes 500

The batched side is what ``pecli tournament`` runs: each pairing's episodes as one batched
``Game`` with both policies acting on the whole batch. The reference plays the same pairings and
the same number of episodes one at a time through the PettingZoo env, each policy acting on a
batch of one (what a loop over a single-game env gives you). Both run on one process and one
torch thread in the same run; the reference plays ``--reference-episodes`` per pairing and its
rate is what is compared. ``--grid`` adds a timing of a full tournament with ``--workers`` worker
processes, for the target (8 x 8 players, 1500 episodes per pairing, <= 10 minutes).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

from pecli.game.pettingzoo_env import parallel_env  # noqa: E402
from pecli.match import policy_seeds  # noqa: E402
from pecli.policies import resolve_policy  # noqa: E402
from pecli.scenario import load_scenario  # noqa: E402
from pecli.tournament import find_players, play_pairing, run_tournament, schedule  # noqa: E402


def one_at_a_time(scenario, pursuer_spec: str, evader_spec: str, episodes: int, seed: int) -> float:
    """Seconds to play ``episodes`` games one by one through the PettingZoo env."""
    env = parallel_env(scenario)
    pursuer_seed, evader_seed = policy_seeds(seed)
    pursuer = resolve_policy(pursuer_spec, "pursuer", scenario, seed=pursuer_seed)
    evader = resolve_policy(evader_spec, "evader", scenario, seed=evader_seed)
    start = time.perf_counter()
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed * 100_000 + episode)
        pursuer.reset(1)
        evader.reset(1)
        while env.agents:
            actions = {
                "pursuer": pursuer.act(obs["pursuer"][None])[0],
                "evader": evader.act(obs["evader"][None])[0],
            }
            obs, *_ = env.step(actions)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="paper")
    parser.add_argument("--zoo", nargs="*", default=[], help="zoo folders whose checkpoints join the baselines")
    parser.add_argument("--episodes", type=int, default=500, help="batched episodes per pairing")
    parser.add_argument("--reference-episodes", type=int, default=20, help="one-at-a-time episodes per pairing")
    parser.add_argument("--players", type=int, default=2, help="players per side taken for the comparison")
    parser.add_argument("--grid", action="store_true", help="also time a full tournament of every player found")
    parser.add_argument("--grid-episodes", type=int, default=500)
    parser.add_argument("--grid-seeds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    scenario = load_scenario(args.config)
    found = find_players(args.zoo, scenario, baselines=True).players
    chosen = {role: players[-args.players :] for role, players in found.items()}
    pairings = schedule(chosen)

    batched_time = reference_time = 0.0
    batched_episodes = reference_episodes = 0
    for pursuer, evader in pairings:
        start = time.perf_counter()
        play_pairing(scenario, pursuer, evader, args.episodes, [0])
        batched_time += time.perf_counter() - start
        batched_episodes += args.episodes
        reference_time += one_at_a_time(scenario, pursuer.spec, evader.spec, args.reference_episodes, seed=0)
        reference_episodes += args.reference_episodes
    batched_rate = batched_episodes / batched_time
    reference_rate = reference_episodes / reference_time
    names = ", ".join(f"{p.name} vs {e.name}" for p, e in pairings)
    print(f"{scenario.name}: {len(pairings)} pairings ({names}), one process, one torch thread")
    print("| how | episodes | episodes/s | ratio |")
    print("| --- | ---: | ---: | ---: |")
    print(
        f"| batched pairings (pecli tournament) | {batched_episodes} | {batched_rate:,.1f} | "
        f"{batched_rate / reference_rate:.0f}x |"
    )
    print(f"| one game at a time (PettingZoo env) | {reference_episodes} | {reference_rate:,.1f} | 1x |")

    if args.grid:
        grid = schedule(found)
        seeds = list(range(args.grid_seeds))
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            run_tournament(scenario, found, grid, args.grid_episodes, seeds, Path(out), workers=args.workers)
            elapsed = time.perf_counter() - start
        total = len(grid) * args.grid_episodes * len(seeds)
        print(
            f"\nfull grid: {len(found['pursuer'])} pursuers x {len(found['evader'])} evaders, "
            f"{args.grid_episodes} x {len(seeds)} episodes per pairing, {args.workers} workers: "
            f"{elapsed:.1f} s, {total / elapsed:,.0f} episodes/s"
        )
        print(
            f"an 8 x 8 grid of 1500 episodes per pairing would take about {64 * 1500 / (total / elapsed) / 60:.1f} min"
        )


if __name__ == "__main__":
    main()
