"""Exported models: per-command latency on the robot path against the PyTorch policy, and file sizes.

    python benchmarks/bench_export.py                       # robots scenario, beliefs none and bimdn
    python benchmarks/bench_export.py --kinds none bimdn ukf --decisions 2000 --rounds 5

For each belief kind a pursuer with the paper's sizes (actor 2 x 128; BiMDN 128 per direction, FC 32)
is built (untrained: latency does not depend on the weights), saved as a checkpoint and exported.
Then, at batch 1 and on one thread each (ONNX Runtime ``intra_op_num_threads=1``,
``torch.set_num_threads(1)``), the same game is replayed through four paths, alternating in
``--rounds`` rounds so that load on a shared machine hits them alike; only ticks at which the
player decides (every ``frame_skip``-th) are timed:

``runtime``    :meth:`pecli.runtime.Controller.step`: SI state estimates in, SI command out, the
               frame stack and history window kept in NumPy, the graph in ONNX Runtime (the robot's path)
``onnx graph`` :meth:`pecli.runtime.ExportedModel.run` alone on the same inputs
``torch``      :meth:`pecli.policies.learned.LearnedPolicy.act`: the checkpoint in eager PyTorch, as it
               plays in simulation (normalised observations, its own frame stack and window)
``torch net``  the checkpoint's ``deterministic_actor(actor)(actor.features_extractor(...))`` alone, under ``no_grad``

It prints p50 and p99 in milliseconds, the speed-up of the runtime over the torch policy, and the
sizes of the ``.onnx`` file and of the checkpoint (which also holds the critic and optimiser).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch as th  # noqa: E402


def build(kind: str, config: str, zoo: Path) -> tuple[Path, Path]:
    """A paper-sized pursuer checkpoint of belief ``kind`` in ``zoo``, and its export."""
    from pecli.export import export_checkpoint
    from pecli.policies import resolve_policy
    from pecli.rl.train import TrainJob, checkpoint_meta, make_env, make_model, with_overrides
    from pecli.scenario import load_scenario
    from pecli.zoo import Run

    scenario = with_overrides(load_scenario(config), {"belief": kind})
    job = TrainJob(role="pursuer", scenario=scenario, opponent="greedy", zoo=zoo, name=kind)
    env = make_env(job, resolve_policy("greedy", "evader", scenario), seed=0)
    model = make_model(job, env, tensorboard=None)
    checkpoint = Run.create(zoo, kind, scenario, {"command": "bench_export"}).save(
        model, "pursuer", "final", checkpoint_meta(job, model, 0)
    )
    return checkpoint, export_checkpoint(checkpoint, episodes=2).model


def game(config: str, steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A pursuer's SI states ``(steps, k + m)`` and normalised observations ``(steps, dim)`` of one game with
    random actions (restarted when it ends)."""
    from pecli.game import Game
    from pecli.scenario import load_scenario

    g = Game(load_scenario(config), n=1, seed=seed, auto_reset=True)
    obs = g.reset()
    rng = np.random.default_rng(seed)
    states, observations = [], []
    for _ in range(steps):
        states.append(g.state()[0])
        observations.append(obs["pursuer"][0].copy())
        obs = g.step(rng.uniform(-1, 1, (1, 2)), rng.uniform(-1, 1, (1, 2))).obs
    return np.array(states), np.array(observations)


def timed(call, ticks: int, frame_skip: int) -> list[float]:
    """Seconds of each ``call(t)`` for ``t`` in ``range(ticks)`` at which the player decides."""
    out = []
    for t in range(ticks):
        start = time.perf_counter()
        call(t)
        elapsed = time.perf_counter() - start
        if t % frame_skip == 0:
            out.append(elapsed)
    return out


def measure(kind: str, config: str, decisions: int, rounds: int, zoo: Path) -> dict[str, object]:
    from pecli.game.si import SILayout
    from pecli.models.algorithms import deterministic_actor
    from pecli.policies import resolve_policy
    from pecli.runtime import Controller
    from pecli.scenario import load_scenario

    scenario = load_scenario(config)
    checkpoint, model = build(kind, config, zoo)
    learned = resolve_policy(str(checkpoint), "pursuer", scenario, seed=0)
    controller = Controller.load(model, seed=0)
    skip = controller.model.frame_skip
    ticks = decisions * skip
    states, observations = game(config, ticks)
    k = SILayout(scenario, "pursuer").k
    samples: dict[str, list[float]] = {"runtime": [], "onnx graph": [], "torch": [], "torch net": []}

    def runtime(t: int) -> None:
        controller.step(states[t, :k], states[t, k:])

    def torch_policy(t: int) -> None:
        learned.act(observations[t][None])

    for _ in range(rounds):
        controller.reset()
        samples["runtime"] += timed(runtime, ticks, skip)
        stack, window = controller.stack[None], controller.window()[None]
        graph = controller.model
        draws = (
            (np.full((1, graph.draws), 0.5, np.float32), np.zeros((1, graph.draws, 2), np.float32))
            if graph.draws
            else (None, None)
        )
        samples["onnx graph"] += timed(lambda t: graph.run(stack, window, *draws), decisions, 1)
        learned.reset(1, seed=0)
        samples["torch"] += timed(torch_policy, ticks, skip)
        stacks, windows = learned.memory(1)
        batch = {"obs": th.as_tensor(stacks)} | ({"history": th.as_tensor(windows)} if windows is not None else {})

        act = deterministic_actor(learned.actor)

        def net(_: int) -> None:
            with th.no_grad():
                act(learned.actor.features_extractor(batch))

        samples["torch net"] += timed(net, decisions, 1)
    return {
        "kind": kind,
        "samples": samples,
        "onnx_bytes": model.stat().st_size,
        "checkpoint_bytes": checkpoint.stat().st_size,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="robots", help="scenario (default: robots)")
    parser.add_argument("--kinds", nargs="+", default=["none", "bimdn"], help="belief kinds")
    parser.add_argument("--decisions", type=int, default=1000, help="timed decisions per path and round")
    parser.add_argument("--rounds", type=int, default=5, help="rounds, the paths alternating")
    args = parser.parse_args()
    th.set_num_threads(1)
    import onnxruntime

    print(
        f"{args.config}, batch 1, one thread each (torch {th.__version__}, onnxruntime {onnxruntime.__version__}), "
        f"{args.decisions} decisions x {args.rounds} rounds per path"
    )
    print("| belief | path | p50 ms | p99 ms | p50 vs torch | .onnx | checkpoint |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            result = measure(kind, args.config, args.decisions, args.rounds, Path(tmp))
            samples = result["samples"]
            p50 = {path: 1e3 * float(np.percentile(values, 50)) for path, values in samples.items()}
            p99 = {path: 1e3 * float(np.percentile(values, 99)) for path, values in samples.items()}
            sizes = f"{result['onnx_bytes'] / 1024:.0f} KiB | {result['checkpoint_bytes'] / 1024:.0f} KiB"
            for i, path in enumerate(samples):
                print(
                    f"| {kind} | {path} | {p50[path]:.3f} | {p99[path]:.3f} | {p50['torch'] / p50[path]:.1f}x | "
                    f"{sizes if i == 0 else ' | '} |"
                )


if __name__ == "__main__":
    main()
