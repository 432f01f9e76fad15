"""pecli against other multi-agent libraries on its own game: their sampling speed, and their players' strength.

    python benchmarks/bench_peers.py envs                  # the run recorded in docs/benchmarks/peers.md
    python benchmarks/bench_peers.py envs --quick          # a short smoke run
    python benchmarks/bench_peers.py train --peers rllib-ppo benchmarl-masac --seeds 0 1 2 --cpu-hours 1
    python benchmarks/bench_peers.py match --pecli runs/league-s0 runs/league-s1 runs/league-s2 --episodes 500

``train`` trains both roles of the ``paper`` game with each peer library (``benchmarks/peers/``) until the CPU
time of the training process and its children reaches ``--cpu-hours``, then exports each role's deterministic
actor with :func:`pecli.export.network.export_network` to ``<zoo>/<peer>-s<seed>/{pursuer,evader}.onnx``; a
run whose exports exist is skipped, and a run stopped midway continues from its last checkpoint (saved every
5 CPU-minutes), its budget counting the CPU spent before. ``match`` plays one tournament (cached in
``<zoo>/tournament``) of pecli's handed-over players (``<run>/<role>/average.zip``, one run per seed, paired
with the peers' runs of the same seed by order), the peers' players, the scripted players and the adversarial
evaders, and prints the swap targets: pecli's pursuer against a peer's evader beside the peer's own pursuer, and
pecli's evader against a peer's pursuer beside the peer's own evader.

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
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pecli.game.pettingzoo_env import parallel_env  # noqa: E402
from pecli.scenario import load_scenario  # noqa: E402
from pecli.stats import difference_interval  # noqa: E402
from pecli.tournament import PairingResult  # noqa: E402

# a peer: (its module in benchmarks/peers/, keyword arguments of its train function)
PEERS: dict[str, tuple[str, dict[str, str]]] = {
    "rllib-ppo": ("rllib_ppo", {}),
    "benchmarl-masac": ("benchmarl_run", {"algorithm": "masac"}),
    "benchmarl-maddpg": ("benchmarl_run", {"algorithm": "maddpg"}),
}


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


def batched(scenario: str, steps: int, n: int = 256) -> Callable[[], int]:
    """pecli's batched ``Game`` of ``n`` games with random actions (finished games restart): game-steps."""
    from pecli.game import Game

    game = Game(load_scenario(scenario), n=n, seed=0, auto_reset=True)
    rng = np.random.default_rng(0)
    actions = [(rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2))) for _ in range(16)]
    rounds = max(1, steps // n)

    def block() -> int:
        for i in range(rounds):
            game.step(*actions[i % 16])
        return rounds * n

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
        ("pecli Game, 256 games batched, random actions", lambda: batched(args.config, 100 * n["plain"])),
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
        library = not name.startswith("pecli Game")  # the batched game is no sampling loop
        share = f"{100 * value / reference:.1f} %" if reference and library else "-"  # the plain loop/this loop
        print(f"| {name} | {value:,.0f} | {1e6 / value:,.0f} us | {share} |")


def train(args: argparse.Namespace) -> None:
    import importlib
    import sys

    from pecli.export.exporter import NEEDS_ONNX, export_available
    from pecli.export.network import export_network
    from pecli.io import atomic_write_json

    if not export_available():  # before an hour of training, not after it
        raise SystemExit(NEEDS_ONNX)
    sys.path.insert(0, str(Path(__file__).parent))
    scenario = load_scenario(args.config)
    for peer in args.peers:
        module_name, kwargs = PEERS[peer]
        module = importlib.import_module(f"peers.{module_name}")
        for seed in args.seeds:
            out = args.zoo / f"{peer}-s{seed}"
            if all((out / f"{role}.onnx").is_file() for role in ("pursuer", "evader")):
                print(f"{out}: trained and exported already")
                continue
            out.mkdir(parents=True, exist_ok=True)
            print(f"{peer}, seed {seed}: {args.cpu_hours:g} CPU-h into {out}", flush=True)
            run = module.train(args.config, args.cpu_hours * 3600, seed, out, **kwargs)
            for role, actor in run.actors.items():
                result = export_network(
                    actor, role, scenario, out / f"{role}.onnx", algo=peer, run=out.name, seed=seed,
                    steps=run.steps, episodes=run.episodes,
                )  # fmt: skip
                print(f"  {role}: {result.model} (parity {result.parity.max_action_difference:.1e})")
            record = {
                "peer": peer, "library": run.library, "seed": seed, "cpu_seconds": run.cpu_seconds,
                "steps": run.steps, "episodes": run.episodes, "iterations": run.iterations,
                "settings": run.settings, "versions": versions(),
            }  # fmt: skip
            atomic_write_json(out / "peer.json", record)
            if hasattr(module, "discard_checkpoint"):
                module.discard_checkpoint(out)


def pecli_players(run: Path) -> dict[str, str]:
    """A pecli self-play run's handed-over players."""
    from pecli.zoo import AVERAGE_FILE

    players = {role: run / role / AVERAGE_FILE for role in ("pursuer", "evader")}
    missing = [str(path) for path in players.values() if not path.is_file()]
    if missing:
        raise SystemExit(f"{run} is not a finished self-play run: no {missing[0]}")
    return {role: str(path) for role, path in players.items()}


def match(args: argparse.Namespace) -> None:
    from pecli.experiment.compare import ADVERSARIES, HEURISTIC_EVADERS
    from pecli.tournament import pairing_results, player_spec

    scenario = load_scenario(args.config)
    teams: dict[str, list[dict[str, str]]] = {"pecli": [pecli_players(run) for run in args.pecli]}
    for peer in PEERS:
        runs = sorted(args.zoo.glob(f"{peer}-s*/pursuer.onnx"), key=lambda r: int(r.parent.name.rsplit("-s", 1)[1]))
        if runs:
            teams[peer] = [{role: str(r.parent / f"{role}.onnx") for role in ("pursuer", "evader")} for r in runs]
    fixed_evaders = [*HEURISTIC_EVADERS, *ADVERSARIES]
    pursuers = [p["pursuer"] for team in teams.values() for p in team] + ["pure-pursuit"]
    evaders = [p["evader"] for team in teams.values() for p in team] + fixed_evaders
    print(f"{len(pursuers)} pursuers x {len(evaders)} evaders, {args.episodes} games a pairing", flush=True)
    grid = pairing_results(scenario, pursuers, evaders, args.episodes, [0], args.zoo / "tournament", args.workers)

    def result(pursuer: str, evader: str) -> PairingResult:
        return grid[(player_spec(pursuer), player_spec(evader))]

    def rate(pursuer: str, evader: str) -> float:
        return result(pursuer, evader).capture_rate

    print("\n| team | seeds | pursuer vs scripted and adversarial evaders | evader vs pure pursuit (escapes) |")
    print("| --- | ---: | ---: | ---: |")
    for name, team in teams.items():
        chase = [statistics.mean(rate(p["pursuer"], e) for e in fixed_evaders) for p in team]
        escape = [1 - rate("pure-pursuit", p["evader"]) for p in team]
        print(f"| {name} | {len(team)} | {spread(chase)} | {spread(escape)} |")

    print("\n| peer | seed | pecli's pursuer catches the peer's evader | the peer's pursuer does | lead (95 %) |"
          " pecli's evader escapes the peer's pursuer | the peer's evader does | lead (95 %) |")  # fmt: skip
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    ours = teams["pecli"]
    for peer, team in teams.items():
        if peer == "pecli":
            continue
        for theirs, mine in zip(team, ours):
            own = result(theirs["pursuer"], theirs["evader"])
            chase = swap(result(mine["pursuer"], theirs["evader"]), own, escapes=False)
            flee = swap(result(theirs["pursuer"], mine["evader"]), own, escapes=True)
            print(f"| {peer} | {Path(theirs['pursuer']).parent.name} | {chase} | {flee} |")
    print("\ntargets: each difference >= +0.10; pecli ahead of every peer in the first table")


def swap(pecli: PairingResult, peer: PairingResult, escapes: bool) -> str:
    """Table cells: pecli's player in the peer's place, the peer's own, and pecli's lead with its 95 % interval
    (in captures for pursuers, in escapes for evaders)."""
    a, b = (peer, pecli) if escapes else (pecli, peer)  # pecli's evader leads when the peer's pursuer catches less
    low, high = difference_interval(a.captures, a.episodes, b.captures, b.episodes)
    rates = [1 - pecli.capture_rate, 1 - peer.capture_rate] if escapes else [pecli.capture_rate, peer.capture_rate]
    lead = a.capture_rate - b.capture_rate
    return f"{rates[0]:.3f} | {rates[1]:.3f} | {lead:+.3f} [{low:+.2f}, {high:+.2f}]"


def spread(values: list[float]) -> str:
    """Median and range over seeds."""
    if len(values) == 1:
        return f"{values[0]:.3f}"
    return f"{statistics.median(values):.3f} ({min(values):.3f}-{max(values):.3f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    envs_parser = commands.add_parser("envs", help="env-steps/s in each library's sampling loop")
    envs_parser.add_argument("--config", default="paper", help="the scenario")
    envs_parser.add_argument("--repeats", type=int, default=3)
    envs_parser.add_argument("--quick", action="store_true", help="fewer steps, for a smoke test")
    envs_parser.add_argument("--json", action="store_true", help="print the results as JSON")
    envs_parser.set_defaults(run=envs)
    train_parser = commands.add_parser("train", help="train both roles with each peer library and export them")
    train_parser.add_argument("--peers", nargs="+", default=list(PEERS), choices=list(PEERS))
    train_parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    train_parser.add_argument("--cpu-hours", type=float, default=1.0)
    train_parser.add_argument("--config", default="paper", help="the scenario")
    train_parser.add_argument("--zoo", type=Path, default=Path("runs/peers"))
    train_parser.set_defaults(run=train)
    match_parser = commands.add_parser("match", help="one tournament of pecli's, the peers' and the fixed players")
    match_parser.add_argument("--pecli", nargs="+", type=Path, required=True, help="pecli self-play runs, by seed")
    match_parser.add_argument("--zoo", type=Path, default=Path("runs/peers"))
    match_parser.add_argument("--config", default="paper", help="the scenario")
    match_parser.add_argument("--episodes", type=int, default=500)
    match_parser.add_argument("--workers", type=int, default=2)
    match_parser.set_defaults(run=match)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
