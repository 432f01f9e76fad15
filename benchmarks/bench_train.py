"""Training speed of ``pecli train``: against plain SB3, per Adam implementation, per device.

    python benchmarks/bench_train.py speed                  # env-steps/s: pecli train vs plain SB3, one run
    python benchmarks/bench_train.py optimizer              # CPU time per gradient step with each kind of Adam
    python benchmarks/bench_train.py device                 # transitions/s with --device cpu and cuda, per belief

``speed`` trains the pursuer on the paper scenario twice with the same hyperparameters (8 envs,
2 gradient steps per vector step, batch 512, one torch thread): once through pecli's batched
frozen-opponent view with the centralised critic, once as plain SB3 TD3 ``MlpPolicy`` on the
same game through ``DummyVecEnv`` of single-game envs (the learner's observation only). It
reports learner transitions per second of each and their ratio, median of ``--repeats``.

``device`` builds ``pecli train``'s learner (the pursuer against greedy, ``--config``'s settings) for each
belief of ``--beliefs`` on each device of ``--devices``, fills its replay buffer and the BiMDN's warm-up, then
times ``--steps`` learner transitions (gradient steps, belief fits and the belief features of each transition
included) in wall-clock seconds: transitions per second on each device, and each device's ratio to the CPU
(one torch thread, as pecli trains). Run it where there is a GPU; without one it measures the CPU alone.

Learning curves over CPU time (``curves``, ``report``): ``bench_train_curves.py``; self-play of two configs to a
CPU cap, then against each other (``selfplay``): ``bench_train_selfplay.py``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def speed(args: argparse.Namespace) -> None:
    import torch as th
    from gymnasium.wrappers import FilterObservation, FlattenObservation
    from stable_baselines3 import TD3
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import DummyVecEnv

    from pecli.policies import resolve_policy
    from pecli.rl.train import TrainJob, make_model
    from pecli.scenario import load_scenario
    from wrappers.frozen_opponent import FrozenOpponentEnv, FrozenOpponentVecEnv

    th.set_num_threads(1)
    scenario = load_scenario(args.config)
    t = scenario.training
    steps = args.steps

    def ours() -> float:
        env = FrozenOpponentVecEnv(scenario, "pursuer", resolve_policy("greedy", "evader", scenario), n=t.n_envs)
        job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="bench")
        model = make_model(job, env, tensorboard=None)
        model.learning_starts = 1000
        start = time.perf_counter()
        model.learn(steps)
        return steps / (time.perf_counter() - start)

    def plain() -> float:
        def make():
            env = FrozenOpponentEnv(scenario, "pursuer", resolve_policy("greedy", "evader", scenario))
            return FlattenObservation(FilterObservation(env, ["obs"]))

        env = DummyVecEnv([make] * t.n_envs)
        model = TD3(
            "MlpPolicy",
            env,
            learning_rate=t.learning_rate,
            buffer_size=t.buffer_size,
            learning_starts=1000,
            batch_size=t.batch_size,
            tau=t.tau,
            gamma=t.gamma,
            train_freq=(t.train_freq, "step"),
            gradient_steps=t.gradient_steps,
            action_noise=NormalActionNoise(np.zeros(2), t.action_noise * np.ones(2)),
            policy_kwargs={"net_arch": list(t.net_arch)},
            device="cpu",
            verbose=0,
        )
        start = time.perf_counter()
        model.learn(steps)
        return steps / (time.perf_counter() - start)

    results: dict[str, list[float]] = {"pecli train": [], "SB3 TD3 MlpPolicy + DummyVecEnv": []}
    for _ in range(args.repeats):
        results["pecli train"].append(ours())
        results["SB3 TD3 MlpPolicy + DummyVecEnv"].append(plain())
    reference = statistics.median(results["SB3 TD3 MlpPolicy + DummyVecEnv"])
    print(
        f"{scenario.name}: {steps} transitions, {t.n_envs} envs, {t.gradient_steps} gradient steps per vector step, "
        f"batch {t.batch_size}, 1 torch thread, median of {args.repeats}"
    )
    print("| trainer | transitions/s | ratio |")
    print("| --- | ---: | ---: |")
    for name, rates in results.items():
        rate = statistics.median(rates)
        print(f"| {name} | {rate:,.0f} | {rate / reference:.2f}x |")


def optimizer(args: argparse.Namespace) -> None:
    """CPU time of one gradient step of pecli's learner with each of Adam's implementations."""
    import torch as th

    from pecli.policies import resolve_policy
    from pecli.rl.train import TrainJob, make_model
    from pecli.scenario import load_scenario
    from wrappers.frozen_opponent import FrozenOpponentVecEnv

    th.set_num_threads(1)
    scenario = load_scenario(args.config)
    t = scenario.training
    env = FrozenOpponentVecEnv(scenario, "pursuer", resolve_policy("greedy", "evader", scenario), n=t.n_envs)
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="bench")
    model = make_model(job, env, tensorboard=None)
    model.learning_starts = 2000
    model.learn(2000 + 16 * t.n_envs)  # a filled buffer, every network built
    variants = {
        "for-loop (torch's CPU default)": {"foreach": False},
        "foreach": {"foreach": True},
        "fused": {"fused": True},
    }
    results: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.repeats):
        for name, kwargs in variants.items():
            for net in (model.actor, model.critic):
                net.optimizer = th.optim.Adam(net.parameters(), lr=t.learning_rate, **kwargs)
            start = time.process_time()
            model.train(gradient_steps=args.steps, batch_size=t.batch_size)
            results[name].append((time.process_time() - start) / args.steps)
    reference = statistics.median(results["for-loop (torch's CPU default)"])
    print(
        f"{scenario.name}: {t.algo}, batch {t.batch_size}, net {list(t.net_arch)}, {args.steps} gradient steps, "
        f"1 torch thread, median of {args.repeats}"
    )
    print("| Adam | ms per gradient step | ratio |")
    print("| --- | ---: | ---: |")
    for name, times in results.items():
        step = statistics.median(times)
        print(f"| {name} | {1000 * step:.2f} | {step / reference:.2f}x |")


def device(args: argparse.Namespace) -> None:
    """Wall-clock learner transitions per second of ``pecli train`` on each device, per belief."""
    import torch as th

    from pecli.policies import resolve_policy
    from pecli.rl.train import TrainJob, make_learner, with_overrides
    from pecli.scenario import load_scenario

    th.set_num_threads(1)
    devices = [d for d in args.devices if d == "cpu" or th.cuda.is_available()]
    if devices != args.devices:
        print(f"torch {th.__version__} sees no CUDA device: measuring {', '.join(devices)} only")
    base = load_scenario(args.config)
    rates: dict[tuple[str, str], float] = {}
    for belief in args.beliefs:
        scenario = with_overrides(base, {"belief": belief}, source="bench")
        t = scenario.training
        warm = max(t.learning_starts, t.belief_settings.warmup if belief != "none" else 0) + 16 * t.n_envs
        for name in devices:
            job = TrainJob(
                role="pursuer", scenario=scenario, opponent="greedy", zoo=Path("unused"), name="bench", device=name
            )
            _, model, fit = make_learner(job, resolve_policy("greedy", "evader", scenario), seed=0)
            model.learn(warm, callback=fit)  # a filled buffer, the BiMDN past its warm-up, every kernel built
            if name.startswith("cuda"):
                th.cuda.synchronize()
            start = time.perf_counter()
            model.learn(args.steps, callback=fit, reset_num_timesteps=False)
            if name.startswith("cuda"):
                th.cuda.synchronize()
            rates[belief, name] = args.steps / (time.perf_counter() - start)
            print(f"{belief} on {name}: {rates[belief, name]:,.0f} transitions/s", flush=True)
    print(
        f"{base.name}: the pursuer against greedy, {args.steps} transitions after a warm-up, {base.training.n_envs} "
        f"envs, {base.training.gradient_steps} gradient steps per vector step, batch {base.training.batch_size}, "
        f"1 torch thread on the CPU"
    )
    print("| belief | device | transitions/s | ratio to cpu |")
    print("| --- | --- | ---: | ---: |")
    for (belief, name), rate in rates.items():
        cpu = rates.get((belief, "cpu"))
        print(f"| {belief} | {name} | {rate:,.0f} | {f'{rate / cpu:.2f}x' if cpu else '-'} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    s = sub.add_parser("speed")
    s.add_argument("--config", default="paper")
    s.add_argument("--steps", type=int, default=6000)
    s.add_argument("--repeats", type=int, default=3)
    o = sub.add_parser("optimizer")
    o.add_argument("--config", default="tuned")
    o.add_argument("--steps", type=int, default=1000)
    o.add_argument("--repeats", type=int, default=5)
    d = sub.add_parser("device")
    d.add_argument("--config", default="tuned")
    d.add_argument("--beliefs", nargs="+", default=["none", "bimdn"])
    d.add_argument("--devices", nargs="+", default=["cpu", "cuda"])
    d.add_argument("--steps", type=int, default=8000, help="timed learner transitions per belief and device")
    args = parser.parse_args()
    steps = {
        "speed": speed,
        "optimizer": optimizer,
        "device": device,
    }
    steps[args.step](args)


if __name__ == "__main__":
    main()
