"""Training speed and learning quality of ``pecli train``.

    python benchmarks/bench_train.py speed                  # env-steps/s: pecli train vs plain SB3, one run
    python benchmarks/bench_train.py optimizer              # CPU time per gradient step with each kind of Adam
    python benchmarks/bench_train.py device                 # transitions/s with --device cpu and cuda, per belief
    python benchmarks/bench_train.py curves --minutes 10    # capture rate vs greedy over CPU time, 3 seeds
    python benchmarks/bench_train.py report                 # table + plot from finished curve runs

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

``curves`` runs ``pecli train pursuer`` for each seed with a budget of ``--max-steps``
transitions (the curriculum of paper.yaml spans its first 30 %) and an evaluation against the
greedy evader (200 batched episodes) every ``--eval-every`` transitions, until each run has used
``--minutes`` of CPU time or its budget; ``--jobs 2`` runs two seeds at a time on a 2-core machine.
``--resume`` continues stopped runs until they have used ``--minutes`` in all. Each run
writes ``eval_pursuer.csv`` (steps, CPU seconds, capture rate) in its zoo folder. ``report``
takes each seed's best evaluation within each budget of ``--at`` (default 10 and 30 CPU-minutes),
prints their medians, and draws ``docs/learning_curves_<belief>.png`` (``learning_curves_<config>_<belief>.png``
for another config than paper). ``--belief`` picks the
actor's belief (runs are named ``<config>-<belief>-s<seed>``).

``selfplay`` runs ``pecli selfplay`` for each config of ``--configs`` (default: tuned and paper) and each seed
until it has used ``--minutes`` of CPU time (or finished its rounds), stopping it with SIGTERM (finished turns
are kept; ``--resume`` continues them to the same cap), then plays each pair of configs' final
checkpoints against each other, ``--episodes`` games: the first config's pursuer against the second's
evader and vice versa.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CURVES = ROOT / "runs" / "bench_train"


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


def curves(args: argparse.Namespace) -> None:
    """Start the curve runs, ``--jobs`` at a time, each stopped after ``--minutes`` of CPU time."""
    pending = list(args.seeds)
    running: list[tuple[int, subprocess.Popen]] = []
    CURVES.mkdir(parents=True, exist_ok=True)
    while pending or running:
        while pending and len(running) < args.jobs:
            seed = pending.pop(0)
            name = f"{args.label or args.config}-{args.belief}-s{seed}"
            command = [sys.executable, "-m", "pecli", "train", "pursuer", "--zoo", str(CURVES), "--name", name, "-q"]
            if args.resume:  # the run's own settings and budget; its CPU time continues from its checkpoint
                command += ["--resume"]
            else:
                command += [
                    "-c",
                    args.config,
                    "--seed",
                    str(seed),
                    "--steps",
                    str(args.max_steps),
                    "--belief",
                    args.belief,
                    "--set",
                    f"eval_every={args.eval_every}",
                    *sum((["--set", s] for s in args.set), []),
                ]
            print("started:", " ".join(command[1:]), flush=True)
            running.append((seed, subprocess.Popen(command, cwd=ROOT)))
        time.sleep(5)
        for seed, process in list(running):
            csv_path = CURVES / f"{args.label or args.config}-{args.belief}-s{seed}" / "eval_pursuer.csv"
            used = _last_cpu_seconds(csv_path)
            if process.poll() is not None or used >= 60 * args.minutes:
                if process.poll() is None:
                    process.terminate()  # the run has had its CPU budget; SIGTERM saves last.zip
                    process.wait()
                print(f"seed {seed}: stopped at {used / 60:.1f} CPU-minutes", flush=True)
                running.remove((seed, process))


def _read(csv_path: Path) -> tuple[np.ndarray, np.ndarray]:
    with csv_path.open() as handle:
        rows = list(csv.DictReader(handle))
    cpu = np.array([float(r["cpu_seconds"]) for r in rows]) / 60
    rate = np.array([float(r["capture_rate"]) for r in rows])
    return cpu, rate


def _last_cpu_seconds(csv_path: Path) -> float:
    if not csv_path.is_file():
        return 0.0
    cpu, _ = _read(csv_path)
    return float(cpu[-1] * 60) if cpu.size else 0.0


def report(args: argparse.Namespace) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    main = args.label or args.config
    groups = {name: sorted(CURVES.glob(f"{name}-{args.belief}-s*/eval_pursuer.csv")) for name in (main, *args.compare)}
    for name, runs in groups.items():
        if not runs:
            sys.exit(f"no curve runs {name}-{args.belief}-s* in {CURVES}: run the 'curves' step first")
    fig, ax = plt.subplots(figsize=(6, 4))
    for colour, (name, runs) in zip(plt.rcParams["axes.prop_cycle"].by_key()["color"], groups.items()):
        at: dict[float, list[float]] = {float(m): [] for m in args.at}
        for i, path in enumerate(runs):
            cpu, rate = _read(path)
            ax.plot(cpu, rate, marker=".", color=colour, alpha=max(0.3, 1.0 - 0.25 * i), label=path.parent.name)
            finished = (path.parent / "pursuer" / "final.zip").is_file()  # spent its whole budget sooner
            for minutes in at:
                if cpu.size and (cpu <= minutes).any() and (cpu[-1] >= minutes or finished):
                    at[minutes].append(float(np.max(rate[cpu <= minutes])))  # best evaluation so far
        for minutes, values in at.items():
            shown = ", ".join(f"{v:.2f}" for v in values) or "no run got that far"
            median = f"{statistics.median(values):.2f}" if values else "-"
            print(f"{name}: best capture rate within {minutes:g} CPU-min: median {median} ({shown})")
    ax.axhline(0.95, color="0.6", ls="--", lw=0.8)
    ax.set_xlabel("CPU minutes (one torch thread)")
    ax.set_ylabel("capture rate vs greedy (200 episodes)")
    ax.set_ylim(0, 1)
    ax.set_title(f"pecli train pursuer, {' vs '.join(groups)}, belief {args.belief}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    out = args.out or ROOT / "docs" / (
        f"learning_curves_{args.belief}.png"
        if args.config == "paper" and not args.label
        else f"learning_curves_{'_vs_'.join(groups)}_{args.belief}.png"
    )
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


SELFPLAY = Path(os.environ.get("PECLI_BENCH_SELFPLAY", ROOT / "runs" / "bench_train_selfplay"))


def _process_cpu_seconds(pid: int) -> float:
    """CPU time (user + system) of a running process, from /proc (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _turns(run: Path) -> list[dict]:
    state = run / "selfplay.json"
    return json.loads(state.read_text())["turns"] if state.is_file() else []


def _done(run: Path, minutes: float) -> bool:
    """Whether ``run`` played all its rounds, or was stopped at a cap of ``minutes`` or more (its ``done`` file)."""
    marker = run / "done"
    if not marker.is_file():
        return False
    text = marker.read_text().strip()
    try:
        return float(text) >= minutes
    except ValueError:  # "all rounds" (or an empty marker of an older benchmark)
        return True


def selfplay(args: argparse.Namespace) -> None:
    """Self-play per config and seed to a CPU cap, then the configs' final players against each other."""
    SELFPLAY.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        for config in args.configs:
            run = SELFPLAY / f"{Path(config).stem}-s{seed}"
            before = sum(t["cpu_seconds"] for t in _turns(run))  # earlier processes' finished turns
            if before >= 60 * args.minutes or _done(run, args.minutes):
                continue
            command = [sys.executable, "-m", "pecli", "selfplay", "--zoo", str(SELFPLAY), "--name", run.name, "-q"]
            command += ["--resume"] if (run / "selfplay.json").exists() else ["-c", config, "--seed", str(seed)]
            print("started:", " ".join(command[1:]), flush=True)
            process = subprocess.Popen(command, cwd=ROOT)
            capped = False
            while process.poll() is None:
                time.sleep(5)
                if process.poll() is None and before + _process_cpu_seconds(process.pid) >= 60 * args.minutes:
                    process.send_signal(signal.SIGTERM)  # keeps the finished turns
                    process.wait()
                    capped = True
            if process.returncode == 0 or capped:
                # played all its rounds, or reached the cap (its finished turns may sum to a little less:
                # a later call with the same cap must not resume it, or it would train past it bit by bit)
                (run / "done").write_text("all rounds\n" if process.returncode == 0 else f"{args.minutes}\n")
            used = sum(t["cpu_seconds"] for t in _turns(run))
            print(f"{run.name}: {len(_turns(run)) // 2} rounds in {used / 60:.1f} CPU-minutes (turns)", flush=True)
    print(
        f"| seed | {args.configs[0]} pursuer vs {args.configs[1]} evader | {args.configs[1]} pursuer vs "
        f"{args.configs[0]} evader | rounds |"
    )
    print("| ---: | ---: | ---: | --- |")
    for seed in args.seeds:
        final = {}
        for config in args.configs[:2]:
            run = SELFPLAY / f"{Path(config).stem}-s{seed}"
            final[config] = {t["role"]: run / t["checkpoint"] for t in _turns(run)}
        if any(set(f) != {"pursuer", "evader"} for f in final.values()):
            print(f"| {seed} | - | - | a run has no finished round yet |")
            continue
        a, b = args.configs[:2]
        rates = [
            _capture_rate(final[x]["pursuer"], final[y]["evader"], args.episodes, seed) for x, y in ((a, b), (b, a))
        ]
        rounds = " / ".join(str(len(_turns(SELFPLAY / f"{Path(c).stem}-s{seed}")) // 2) for c in (a, b))
        print(f"| {seed} | {rates[0]:.3f} | {rates[1]:.3f} | {rounds} |", flush=True)


def _capture_rate(pursuer: Path, evader: Path, episodes: int, seed: int) -> float:
    command = [
        sys.executable,
        "-m",
        "pecli",
        "play",
        "--pursuer",
        str(pursuer),
        "--evader",
        str(evader),
        "--episodes",
        str(episodes),
        "--seed",
        str(10_000 + seed),
        "--json",
    ]
    output = subprocess.run(command, cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return float(json.loads(output)["capture_rate"])


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
    c = sub.add_parser("curves")
    c.add_argument("--config", default="paper")
    c.add_argument("--belief", default="none")
    c.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    c.add_argument("--minutes", type=float, default=10.0, help="CPU minutes per seed")
    c.add_argument("--jobs", type=int, default=2)
    c.add_argument("--eval-every", type=int, default=25000)
    c.add_argument(
        "--max-steps",
        type=int,
        default=600_000,
        help="the training budget; the curriculum spans its first 30 %% (paper.yaml)",
    )
    c.add_argument("--set", action="append", default=[], help="extra training settings, KEY=VALUE")
    c.add_argument("--label", help="names the runs instead of --config (for a variant made with --set)")
    c.add_argument(
        "--resume",
        action="store_true",
        help="continue stopped runs (pecli train --resume) until --minutes of their CPU time in all",
    )
    r = sub.add_parser("report")
    r.add_argument("--config", default="paper")
    r.add_argument("--belief", default="none")
    r.add_argument("--at", type=float, nargs="+", default=[10.0, 30.0], help="CPU budgets to report (minutes)")
    r.add_argument("--out", type=Path, default=None, help="the plot (default: docs/learning_curves_...png)")
    r.add_argument("--label", help="the --label the curves were run with")
    r.add_argument(
        "--compare",
        nargs="+",
        default=[],
        metavar="LABEL",
        help="other curves to draw on the same plot, each in its colour (their --label or --config)",
    )
    p = sub.add_parser("selfplay")
    p.add_argument("--configs", nargs=2, default=["tuned", "paper"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--minutes", type=float, default=10.0, help="CPU minutes per self-play run")
    p.add_argument("--episodes", type=int, default=500)
    args = parser.parse_args()
    steps = {
        "speed": speed,
        "optimizer": optimizer,
        "device": device,
        "curves": curves,
        "report": report,
        "selfplay": selfplay,
    }
    steps[args.step](args)


if __name__ == "__main__":
    main()
