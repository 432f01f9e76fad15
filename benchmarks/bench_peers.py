"""pecli's PettingZoo env inside other multi-agent libraries: env-steps/s in each library's own sampling loop.

    python benchmarks/bench_peers.py envs                  # the run recorded in docs/benchmarks/peers.md
    python benchmarks/bench_peers.py envs --quick          # a short smoke run

Needs the ``peers`` extra (``pip install -e ".[peers]"``); a library that is missing is skipped. Each figure is
env-steps per CPU-second (``time.process_time`` of this process, one torch thread), the median of ``--repeats``
timed blocks after one warm-up block. An env-step moves both players once; finished episodes restart inside
each loop, so resets are part of the cost. The plain loop is the reference: ``parallel_env`` stepped with random
actions, as ``bench_sim.py`` does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
import warnings
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pecli.game.pettingzoo_env import parallel_env  # noqa: E402


def rate(block: Callable[[], int], repeats: int) -> float:
    """Median env-steps per CPU-second of ``block()`` (which returns the steps it made), after a warm-up run."""
    block()
    rates = []
    for _ in range(repeats):
        start = time.process_time()
        steps = block()
        rates.append(steps / (time.process_time() - start))
    return statistics.median(rates)


def plain(scenario: str, steps: int) -> Callable[[], int]:
    """``parallel_env`` in a plain loop with random actions, resetting when the episode ends."""
    env = parallel_env(scenario)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    samples = {agent: rng.uniform(-1, 1, (64, 2)).astype(np.float32) for agent in env.possible_agents}

    def block() -> int:
        for i in range(steps):
            if not env.agents:
                env.reset()
            env.step({agent: samples[agent][i % 64] for agent in env.agents})
        return steps

    return block


def rllib(scenario: str, steps: int, random_actions: bool) -> Callable[[], int]:
    """RLlib's ``MultiAgentEnvRunner.sample``: random actions, or one untrained PPO module per agent."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env

    register_env("pecli", lambda config: ParallelPettingZooEnv(parallel_env(config["scenario"])))
    config = (
        PPOConfig()
        .environment("pecli", env_config={"scenario": scenario})
        .env_runners(num_env_runners=0)
        .multi_agent(policies={"pursuer", "evader"}, policy_mapping_fn=lambda agent_id, episode, **kwargs: agent_id)
        .debugging(seed=0)
    )
    runner = MultiAgentEnvRunner(config=config)

    def block() -> int:
        episodes = runner.sample(num_timesteps=steps, random_actions=random_actions)
        return sum(episode.env_steps() for episode in episodes)

    return block


def torchrl_rollout(scenario: str, steps: int) -> Callable[[], int]:
    """TorchRL's ``PettingZooWrapper.rollout`` with random actions (the action specs' ``rand``)."""
    from torchrl.envs import PettingZooWrapper

    env = PettingZooWrapper(env=parallel_env(scenario), return_state=True, seed=0)

    def block() -> int:
        return env.rollout(steps, break_when_any_done=False).numel()

    return block


def torchrl_collector(scenario: str, steps: int) -> Callable[[], int]:
    """TorchRL's ``Collector`` over the wrapper with random actions, one batch of ``steps`` frames per block."""
    from torchrl.collectors import Collector
    from torchrl.envs import PettingZooWrapper

    collector = Collector(
        lambda: PettingZooWrapper(env=parallel_env(scenario), return_state=True, seed=0),
        policy=None,
        frames_per_batch=steps,
        total_frames=-1,
    )
    batches = iter(collector)

    def block() -> int:
        return next(batches).numel()

    return block


def versions() -> str:
    found = []
    for package in ("pettingzoo", "gymnasium", "numpy", "torch", "ray", "torchrl", "tensordict", "benchmarl"):
        try:
            found.append(f"{package} {version(package)}")
        except PackageNotFoundError:
            pass
    return ", ".join(found)


def envs(args: argparse.Namespace) -> None:
    import torch

    torch.set_num_threads(1)
    warnings.filterwarnings("ignore")
    scale = 0.1 if args.quick else 1.0
    n = {key: max(50, int(value * scale)) for key, value in {"plain": 4000, "random": 2000, "module": 1000}.items()}
    loops: list[tuple[str, Callable[[], Callable[[], int]]]] = [
        ("parallel_env, plain loop, random actions", lambda: plain(args.config, n["plain"])),
        ("RLlib MultiAgentEnvRunner.sample, random actions", lambda: rllib(args.config, n["random"], True)),
        ("RLlib MultiAgentEnvRunner.sample, untrained PPO modules", lambda: rllib(args.config, n["module"], False)),
        ("TorchRL PettingZooWrapper.rollout, random actions", lambda: torchrl_rollout(args.config, n["random"])),
        ("TorchRL Collector, random actions", lambda: torchrl_collector(args.config, n["random"])),
    ]
    results: dict[str, float] = {}
    for name, make in loops:
        try:
            block = make()
        except ImportError as error:
            print(f"{name}: skipped ({error})")
            continue
        results[name] = rate(block, args.repeats)

    if args.json:
        print(json.dumps(results, indent=2))
        return
    reference = results.get(loops[0][0])
    print(f"scenario {args.config}, {platform.processor() or platform.machine()}, median of {args.repeats}")
    print(versions())
    print("| sampling loop | env-steps per CPU-second | CPU per env-step | the env's share |")
    print("| --- | ---: | ---: | ---: |")
    for name, value in results.items():
        share = f"{100 * value / reference:.1f} %" if reference else "-"  # the plain loop's time over this loop's
        print(f"| {name} | {value:,.0f} | {1e6 / value:,.0f} us | {share} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    envs_parser = commands.add_parser("envs", help="env-steps/s in each library's sampling loop")
    envs_parser.add_argument("--config", default="paper", help="the scenario")
    envs_parser.add_argument("--repeats", type=int, default=3)
    envs_parser.add_argument("--quick", action="store_true", help="fewer steps, for a smoke test")
    envs_parser.add_argument("--json", action="store_true", help="print the results as JSON")
    envs_parser.set_defaults(run=envs)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
