"""Simulator speed: game-steps/s of the batched game and of the PettingZoo env, next to MPE simple_tag_v3.

    python benchmarks/bench_sim.py                 # the full run recorded in docs/benchmarks/simulator.md
    python benchmarks/bench_sim.py --quick         # a short smoke run

Everything is measured in one process, on one thread, in the same run, so the ratios hold
on a shared, noisy machine. Each figure is the median of ``--repeats`` timed blocks.
Actions are random and fixed per block; finished games restart (auto-reset), so resets
are part of the cost.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pecli.game import Game  # noqa: E402
from pecli.game.pettingzoo_env import parallel_env  # noqa: E402
from pecli.scenario import load_scenario  # noqa: E402


def timed(block, repeats: int) -> float:
    """Median seconds of ``block()`` over ``repeats`` runs, after one warm-up run."""
    block()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        block()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def batched(scenario, n: int, steps: int, repeats: int) -> float:
    """Game-steps/s of ``Game`` with ``n`` games."""
    game = Game(scenario, n=n, seed=0, auto_reset=True)
    rng = np.random.default_rng(0)
    actions = [(rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2))) for _ in range(16)]

    def block() -> None:
        for i in range(steps):
            game.step(*actions[i % 16])

    return n * steps / timed(block, repeats)


def pettingzoo_steps(make_env, steps: int, repeats: int) -> float:
    """Env-steps/s of a PettingZoo parallel env with random actions, resetting when the episode ends."""
    env = make_env()
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    samples = {
        agent: rng.uniform(-1, 1, (64, *env.action_space(agent).shape)).astype(np.float32)
        for agent in env.possible_agents
    }
    low = {agent: env.action_space(agent).low for agent in env.possible_agents}
    high = {agent: env.action_space(agent).high for agent in env.possible_agents}
    samples = {agent: np.clip(np.abs(samples[agent]), low[agent], high[agent]) for agent in samples}

    def block() -> None:
        for i in range(steps):
            if not env.agents:
                env.reset()
            env.step({agent: samples[agent][i % 64] for agent in env.agents})

    return steps / timed(block, repeats)


def simple_tag():
    from mpe2 import simple_tag_v3

    return simple_tag_v3.parallel_env(continuous_actions=True, max_cycles=25)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="paper")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="fewer steps, for a smoke test")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0
    scenario = load_scenario(args.config)

    results: dict[str, float] = {}
    for n, steps in ((1, 4000), (64, 2000), (1024, 400), (4096, 150)):
        results[f"game N={n}"] = batched(scenario, n, max(10, int(steps * scale)), args.repeats)
    results["pettingzoo (1 game)"] = pettingzoo_steps(lambda: parallel_env(scenario), int(4000 * scale), args.repeats)
    try:
        results["mpe2 simple_tag_v3"] = pettingzoo_steps(simple_tag, int(1000 * scale), args.repeats)
    except ImportError:
        print("mpe2 is not installed (pip install mpe2): simple_tag_v3 skipped")

    if args.json:
        print(json.dumps(results, indent=2))
        return
    reference = results.get("mpe2 simple_tag_v3")
    print(
        f"scenario {scenario.name}, {platform.processor() or platform.machine()}, numpy {np.__version__}, "
        f"median of {args.repeats}"
    )
    print("| what | steps/s | vs simple_tag_v3 |")
    print("| --- | ---: | ---: |")
    for name, rate in results.items():
        ratio = f"{rate / reference:.1f}x" if reference else "-"
        print(f"| {name} | {rate:,.0f} | {ratio} |")


if __name__ == "__main__":
    main()
