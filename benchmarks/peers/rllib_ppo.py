"""Both roles of the game trained at once by RLlib's multi-agent PPO, to a CPU budget.

    run = train("paper", cpu_seconds=600, seed=0, out=Path("runs/peers/rllib"))
    run.actors["pursuer"](torch.zeros(1, 11))       # a deterministic action in [-1, 1], shape (1, 2)

The env is ``parallel_env(scenario)`` in RLlib's ``ParallelPettingZooEnv``, as docs/benchmarks/peers.md shows;
PPO runs on the new API stack with one RLModule per agent (``pursuer`` and ``evader``, simultaneous self-play).
Sampling and learning run in this process (no env-runner or learner actors), torch on one thread. The budget is
the CPU time of this process and of every process below it (Ray's GCS, raylet and workers), read after each
``algo.train()`` iteration. Every ``SAVE_EVERY`` CPU-seconds the algorithm is saved (``algo.save_to_path``) into
``out/checkpoint`` with the CPU spent and the curve so far; a run stopped midway continues from there
(``algo.restore_from_path``), its budget counting what the earlier sittings spent.

The settings are RLlib's own tuned continuous-control PPO (``rllib/examples/algorithms/ppo/mujoco_ppo.py``) with
one change for the game's reward scale: the learner multiplies rewards by 1/1000 before GAE, as pecli's own
training does, so that ``vf_clip_param = 10`` (which clips the squared value error) and the global-norm gradient
clip mean what they mean on unit-scale rewards. The returns logged are the env's, unscaled.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import time
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from pecli.game.pettingzoo_env import parallel_env
from pecli.process import descendants

from . import PeerRun

AGENTS = ("pursuer", "evader")
ACTION_DIM = 2

# RLlib's tuned PPO for MuJoCo (Humanoid-v4 by default), the newest continuous-control tuned example:
# https://github.com/ray-project/ray/blob/master/rllib/examples/algorithms/ppo/mujoco_ppo.py
TRAINING: dict[str, Any] = {
    "train_batch_size_per_learner": 2048,
    "minibatch_size": 512,
    "num_epochs": 10,
    "lr": 0.0003,
    "vf_loss_coeff": 1.0,
    "entropy_coeff": [[0, 0.01], [2_000_000, 0.0]],
    "gamma": 0.99,
    "lambda_": 0.95,
    "kl_coeff": 0.5,
    "clip_param": 0.2,
    "vf_clip_param": 10.0,
    "grad_clip": 50.0,
    "grad_clip_by": "global_norm",
}
MODEL: dict[str, Any] = {
    "vf_share_layers": False,
    "fcnet_hiddens": [256, 256],
    "fcnet_kernel_initializer": "orthogonal_",  # torch.nn.init.orthogonal_
    "fcnet_activation": "tanh",
    "head_fcnet_hiddens": [256],
    "head_fcnet_activation": None,
    "free_log_std": True,
}
REWARD_SCALE = 0.001  # rewards / 1000 for learning, as configs/paper.yaml's training.reward_scale
RAY_INIT: dict[str, Any] = {"num_cpus": 1, "include_dashboard": False}
CHECK_TOLERANCE = 1e-5
CHECKPOINT = "checkpoint"  # algo.save_to_path's folder, with RESUME: where a stopped run continues from
RESUME = "resume.json"  # the CPU spent and the curve when the checkpoint was saved
SAVE_EVERY = 300.0  # CPU seconds between checkpoints


class DeterministicActor(nn.Module):
    """Observations ``(B, 11)`` -> the mean of PPO's diagonal Gaussian, clamped to [-1, 1]: ``(B, 2)``."""

    def __init__(self, encoder: nn.Module, head: nn.Module, action_dim: int = ACTION_DIM) -> None:
        super().__init__()
        self.encoder = encoder
        self.head = head
        self.action_dim = action_dim

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.encoder(obs))[..., : self.action_dim].clamp(-1.0, 1.0)


def process_cpu(pid: int) -> float:
    """CPU seconds of one process from ``/proc``: its own and its finished (reaped) children's."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    ticks = sum(int(value) for value in fields[11:15])  # utime, stime, cutime, cstime
    return ticks / os.sysconf("SC_CLK_TCK")


def tree_cpu() -> tuple[float, float]:
    """CPU seconds of this process and of the live processes below it (with what their children used)."""
    others = 0.0
    for pid in descendants(os.getpid()):
        try:
            others += process_cpu(pid)
        except (OSError, IndexError):  # ended while being read
            continue
    return process_cpu(os.getpid()), others


def scale_rewards_connector() -> type:
    """A learner connector piece that multiplies each module's rewards by ``REWARD_SCALE`` (before GAE)."""
    from ray.rllib.connectors.connector_v2 import ConnectorV2
    from ray.rllib.core.columns import Columns

    class ScaleRewards(ConnectorV2):
        def __call__(self, *, rl_module: Any, batch: dict, episodes: list, **kwargs: Any) -> dict:
            for module_batch in batch.values():
                if Columns.REWARDS in module_batch:
                    module_batch[Columns.REWARDS] = module_batch[Columns.REWARDS] * REWARD_SCALE
            return batch

    return ScaleRewards


def scaled_reward_learner() -> type:
    """RLlib's torch PPO learner with :func:`scale_rewards_connector` inserted just before GAE."""
    from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
    from ray.rllib.connectors.learner import GeneralAdvantageEstimation

    scale_rewards = scale_rewards_connector()

    class ScaledRewardPPOLearner(PPOTorchLearner):
        def build(self) -> None:
            super().build()
            self._learner_connector.insert_before(GeneralAdvantageEstimation, scale_rewards())

    return ScaledRewardPPOLearner


def make_config(scenario: str, seed: int) -> Any:
    """The PPOConfig: the docs' multi-agent setup, one process, RLlib's tuned training and model settings."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env

    register_env("pecli", lambda config: ParallelPettingZooEnv(parallel_env(config["scenario"])))
    model = {**MODEL, "fcnet_kernel_initializer": getattr(torch.nn.init, MODEL["fcnet_kernel_initializer"])}
    return (
        PPOConfig()
        .environment("pecli", env_config={"scenario": scenario})
        .multi_agent(policies=set(AGENTS), policy_mapping_fn=lambda agent_id, episode, **kwargs: agent_id)
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(**TRAINING, learner_class=scaled_reward_learner())
        .rl_module(model_config=DefaultModelConfig(**model))
        .debugging(seed=seed)
    )


def settings(scenario: str, seed: int) -> dict[str, Any]:
    """The settings of a run, JSON-able."""
    return {
        "scenario": scenario,
        "seed": seed,
        "algorithm": "PPO, new API stack, one RLModule per agent, policy_mapping_fn = agent id",
        "env": "ParallelPettingZooEnv(parallel_env(scenario))",
        "training": TRAINING,
        "model": MODEL,
        "reward_scale": REWARD_SCALE,
        "num_env_runners": 0,
        "num_learners": 0,
        "torch_threads": 1,
        "ray_init": RAY_INIT,
        "source": "https://github.com/ray-project/ray/blob/master/rllib/examples/algorithms/ppo/mujoco_ppo.py",
    }


def per_agent(values: Any) -> dict[str, float | None]:
    """``{agent: float}`` from one of RLlib's per-module metrics (absent before any value is logged)."""
    values = values if isinstance(values, dict) else {}
    return {agent: float(values[agent]) if agent in values else None for agent in AGENTS}


def curve_point(result: dict[str, Any], cpu: float) -> dict[str, Any]:
    """The figures of one ``algo.train()`` result worth keeping."""
    runners, learners = result.get("env_runners", {}), result.get("learners", {})
    return {
        "iteration": int(result["training_iteration"]),
        "env_steps": int(runners.get("num_env_steps_sampled_lifetime", 0)),
        "episodes": int(runners.get("num_episodes_lifetime", 0)),
        "episode_len_mean": float(runners["episode_len_mean"]) if "episode_len_mean" in runners else None,
        "return_mean": per_agent(runners.get("module_episode_returns_mean")),
        "vf_explained_var": per_agent({k: v.get("vf_explained_var") for k, v in learners.items() if k in AGENTS}),
        "entropy": per_agent({k: v.get("entropy") for k, v in learners.items() if k in AGENTS}),
        "cpu_s": round(cpu, 2),
    }


def progress(point: dict[str, Any], budget: float) -> str:
    """One log line per iteration."""
    returns = "  ".join(
        f"{agent} {value:9.1f}" if value is not None else f"{agent}         -"
        for agent, value in point["return_mean"].items()
    )
    return (
        f"rllib it {point['iteration']:4d}  steps {point['env_steps']:8d}  episodes {point['episodes']:6d}  "
        f"return {returns}  cpu {point['cpu_s']:7.1f}/{budget:.0f} s"
    )


def pure_actor(module: Any) -> DeterministicActor:
    """A copy of an RLlib PPO module's policy path (actor encoder, then pi head) as plain torch, in eval mode."""
    encoder = module.encoder
    body = encoder.actor_encoder if hasattr(encoder, "actor_encoder") else encoder.encoder
    actor = DeterministicActor(copy.deepcopy(body.net), copy.deepcopy(module.pi.net))
    return actor.to("cpu").eval().requires_grad_(False)


def real_observations(scenario: str, seed: int, n: int = 512) -> dict[str, np.ndarray]:
    """``n`` observations of each agent from games played with random actions."""
    env, rng = parallel_env(scenario), np.random.default_rng(seed)
    found: dict[str, list[np.ndarray]] = {agent: [] for agent in AGENTS}
    obs, _ = env.reset(seed=seed)
    while len(found["pursuer"]) < n:
        for agent in AGENTS:
            found[agent].append(obs[agent])
        obs, _, _, _, _ = env.step({agent: rng.uniform(-1, 1, ACTION_DIM).astype(np.float32) for agent in AGENTS})
        if not env.agents:
            obs, _ = env.reset()
    return {agent: np.stack(found[agent]).astype(np.float32) for agent in AGENTS}


def rllib_actions(module: Any, obs: torch.Tensor) -> torch.Tensor:
    """RLlib's own deterministic action: ``forward_inference``, the distribution's mode, clipped to the box."""
    from ray.rllib.core.columns import Columns

    with torch.no_grad():
        inputs = module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
        dist = module.get_inference_action_dist_cls().from_logits(inputs).to_deterministic()
        return dist.sample().clamp(-1.0, 1.0)


def check_actor(actor: nn.Module, module: Any, obs: np.ndarray, agent: str) -> float:
    """The largest gap between the pure actor and RLlib's inference; raises if it is over ``CHECK_TOLERANCE``."""
    batch = torch.as_tensor(obs)
    with torch.no_grad():
        gap = float((actor(batch) - rllib_actions(module, batch)).abs().max())
    if not gap <= CHECK_TOLERANCE:
        raise AssertionError(f"the {agent} actor differs from RLlib's inference by {gap:.3g}")
    return gap


def versions() -> dict[str, str]:
    return {package: version(package) for package in ("ray", "torch", "gymnasium", "pettingzoo", "numpy")}


def write_record(out: Path, record: dict[str, Any]) -> None:
    """``rllib.json`` in ``out``, written atomically."""
    out.mkdir(parents=True, exist_ok=True)
    target = out / "rllib.json"
    tmp = target.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    os.replace(tmp, target)


def save(algo: Any, out: Path, curve: list[dict[str, Any]], spent: float) -> None:
    """The algorithm and the run so far into ``out/checkpoint``, replacing the last one only once complete."""
    target, tmp, old = out / CHECKPOINT, out / f"{CHECKPOINT}.tmp", out / f"{CHECKPOINT}.old"
    shutil.rmtree(tmp, ignore_errors=True)
    algo.save_to_path(str(tmp.resolve()))
    (tmp / RESUME).write_text(json.dumps({"cpu_s": spent, "curve": curve}) + "\n")
    shutil.rmtree(old, ignore_errors=True)
    if target.exists():
        os.replace(target, old)
    os.replace(tmp, target)
    shutil.rmtree(old, ignore_errors=True)


def saved(out: Path) -> Path | None:
    """The newest complete checkpoint of a stopped run (the previous one if a save stopped between its renames)."""
    for name in (CHECKPOINT, f"{CHECKPOINT}.old"):
        if (out / name / RESUME).is_file():
            return out / name
    return None


def train_loop(
    algo: Any,
    budget: float,
    start: float,
    log: Callable[[str], None],
    out: Path,
    spent: float = 0.0,
    curve: list[dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """``algo.train()`` until ``spent`` (earlier sittings) and the CPU of this process tree since ``start`` reach
    ``budget``, saving a checkpoint every ``SAVE_EVERY`` CPU-seconds."""
    curve = [] if curve is None else curve
    last_save = spent
    while True:
        result = algo.train()
        own, others = tree_cpu()
        point = curve_point(result, spent + own + others - start)
        point["ray_cpu_s"] = round(others, 2)
        curve.append(point)
        log(progress(point, budget))
        if point["cpu_s"] >= budget:
            return curve
        if point["cpu_s"] - last_save >= SAVE_EVERY:
            save(algo, out, curve, point["cpu_s"])
            last_save = point["cpu_s"]


def finish(algo: Any, scenario: str, seed: int, curve: list[dict[str, Any]], wall: float) -> PeerRun:
    """The pure actors (checked against RLlib's own inference) and the run's figures."""
    observations = real_observations(scenario, seed + 1)
    actors, gaps = {}, {}
    for agent in AGENTS:
        module = algo.get_module(agent)
        actors[agent] = pure_actor(module)
        gaps[agent] = check_actor(actors[agent], module, observations[agent], agent)
    last = curve[-1]
    run_settings = {**settings(scenario, seed), "actor_check_max_abs_diff": gaps, "wall_s": round(wall, 1)}
    return PeerRun(
        actors=actors,
        steps=last["env_steps"],
        episodes=last["episodes"],
        cpu_seconds=last["cpu_s"],
        iterations=last["iteration"],
        settings=run_settings,
        library=f"RLlib {version('ray')} PPO",
        curve=curve,
    )


def train(scenario: str, cpu_seconds: float, seed: int, out: Path, log: Callable[[str], None] = print) -> PeerRun:
    """Train both roles with RLlib's multi-agent PPO for ``cpu_seconds`` of CPU (continuing a stopped run from its
    checkpoint in ``out``); write ``out/rllib.json``."""
    import ray

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    torch.set_num_threads(1)
    out = Path(out)
    start, wall = sum(tree_cpu()), time.perf_counter()
    algo = None
    try:
        ray.init(**RAY_INIT)
        algo = make_config(scenario, seed).build_algo()
        spent, curve, checkpoint = 0.0, [], saved(out)
        if checkpoint is not None:
            algo.restore_from_path(str(checkpoint.resolve()))
            resume = json.loads((checkpoint / RESUME).read_text())
            spent, curve = float(resume["cpu_s"]), resume["curve"]
            log(f"continuing from {checkpoint} ({spent:.0f} CPU s spent, iteration {len(curve)})")
        curve = train_loop(algo, cpu_seconds, start, log, out, spent, curve)
        run = finish(algo, scenario, seed, curve, time.perf_counter() - wall)
    finally:
        if algo is not None:
            algo.stop()
        ray.shutdown()
    record = {
        "library": run.library,
        "versions": versions(),
        "settings": run.settings,
        "cpu_budget_s": cpu_seconds,
        "steps": run.steps,
        "episodes": run.episodes,
        "cpu_seconds": run.cpu_seconds,
        "iterations": run.iterations,
        "curve": run.curve,
    }
    write_record(out, record)
    return run


def discard_checkpoint(out: Path) -> None:
    """Remove a finished run's last checkpoint, once its actors are exported: the record and the exports are
    what it leaves (until then, the same command exports them from the checkpoint)."""
    shutil.rmtree(out / CHECKPOINT, ignore_errors=True)
