"""Both roles of pecli's game trained with BenchMARL, competitively: one group and one policy per role.

``train`` runs MASAC (or MADDPG) on a single PettingZoo env until a CPU budget is spent and returns each role's
deterministic actor as a plain torch module (observation ``(B, 11)`` -> action ``(B, 2)`` in [-1, 1]).

The algorithm and experiment start from BenchMARL's own defaults (``get_from_yaml()``: its
``benchmarl/conf/algorithm/*.yaml`` and ``conf/experiment/base_experiment.yaml``); ``experiment_config`` changes
only what one non-vectorised env on a shared CPU needs, and each change is recorded with its reason.

Every ``SAVE_EVERY`` CPU-seconds the experiment's state (``Experiment.state_dict``: the losses, the replay buffers,
the collector) is saved with the run's progress to ``<experiment folder>/checkpoints/resume.pt``; a run stopped
midway continues from there through BenchMARL's own ``restore_file``, its budget counting what was spent before.
"""

from __future__ import annotations

import copy
import math
import os
import platform
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any

import torch
from benchmarl.algorithms import MaddpgConfig, MasacConfig
from benchmarl.algorithms.common import AlgorithmConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.experiment.callback import Callback
from benchmarl.models.mlp import Mlp, MlpConfig
from tensordict import TensorDictBase
from torch import nn
from torchrl.envs.utils import ExplorationType, set_exploration_type

from pecli import process
from pecli.io import atomic_write_json
from pecli.peers.benchmarl import PecliTask

from . import PeerRun

ALGORITHMS: dict[str, type[AlgorithmConfig]] = {"masac": MasacConfig, "maddpg": MaddpgConfig}
RECORD = "benchmarl.json"
TOLERANCE = 1e-5  # the pure actor against BenchMARL's policy, max abs difference of the actions
MEMORY_FRAMES = 1_000_000
NEVER = 10**12  # frames: the CPU budget ends the run, not BenchMARL's frame or iteration count
RESUME = "resume.pt"  # in the experiment folder's checkpoints/: where a stopped run continues from
SAVE_EVERY = 300.0  # CPU seconds between checkpoints

# What one non-vectorised env on a shared CPU changes in base_experiment.yaml, and why.
CHANGES: dict[str, tuple[Any, str]] = {
    "sampling_device": ("cpu", "no accelerator"),
    "train_device": ("cpu", "no accelerator"),
    "buffer_device": ("cpu", "no accelerator"),
    "share_policy_params": (False, "competitive: each role its own policy (one agent per group)"),
    "off_policy_n_envs_per_worker": (1, "a single non-vectorised PettingZoo env (default 10 sequential copies)"),
    "off_policy_collected_frames_per_batch": (
        1200,
        "3 full-length episodes per iteration for a budget checked each iteration (default 6000)",
    ),
    "off_policy_n_optimizer_steps": (
        200,
        "the default ratio of 1000 steps per 6000 frames (also fine_tuned/vmas) at 1200 frames",
    ),
    "off_policy_train_batch_size": (128, "unchanged default, as fine_tuned/vmas"),
    "off_policy_memory_size": (MEMORY_FRAMES, "unchanged default, as fine_tuned/vmas"),
    "exploration_anneal_frames": (
        1_000_000,
        "MADDPG's noise annealing: fine_tuned/vmas's value, the default's max_n_frames / 3 of 3M",
    ),
    "max_n_frames": (NEVER, "the CPU budget stops training"),
    "max_n_iters": (None, "the CPU budget stops training"),
    "evaluation": (False, "no evaluation episodes: the driver plays the actors afterwards"),
    "render": (False, "nothing to render"),
    "loggers": (["csv"], "BenchMARL's own csv log under out; no wandb"),
    "create_json": (False, "marl-eval json is written by evaluation, which is off"),
    "checkpoint_interval": (0, "BenchMARL's own checkpoints off: the run saves one every SAVE_EVERY CPU-seconds"),
}


class BudgetSpent(KeyboardInterrupt):
    """Stops a run: ``Experiment.run`` closes the experiment on a KeyboardInterrupt (its graceful stop), then
    raises it again."""


def cpu_now() -> float:
    """CPU seconds of this process, its finished children and its live descendants."""
    times = os.times()
    live = 0.0
    for pid in process.descendants(os.getpid()):
        try:
            live += process.cpu_seconds(pid)
        except OSError:  # it ended meanwhile (and its time went to the finished children)
            pass
    return times.user + times.system + times.children_user + times.children_system + live


class Progress(Callback):
    """Counts each iteration's frames and episodes, logs a line, saves the experiment every ``SAVE_EVERY``
    CPU-seconds and stops the run when the budget is spent."""

    def __init__(self, budget: float, log: Callable[[str], None], save: Callable[[], None]) -> None:
        super().__init__()
        self.budget, self.log, self.save = budget, log, save
        self.start = cpu_now()
        self.spent_before = 0.0  # CPU seconds of the sittings before this one (a continued run)
        self.last_checkpoint = 0.0
        self.curve: list[dict[str, Any]] = []
        self.episodes = 0
        self.batch: dict[str, Any] = {}

    def __getstate__(self) -> dict[str, Any]:
        """BenchMARL pickles its callbacks into the experiment folder: without the experiment and the functions."""
        return {**self.__dict__, "experiment": None, "log": None, "save": None}

    def used(self) -> float:
        return self.spent_before + cpu_now() - self.start

    def on_state_dict(self, state_dict: dict[str, Any]) -> None:
        state_dict["pecli_progress"] = {"cpu_seconds": self.used(), "curve": self.curve, "episodes": self.episodes}

    def on_load_state_dict(self, state_dict: dict[str, Any]) -> None:
        saved = state_dict["pecli_progress"]
        self.spent_before = self.last_checkpoint = float(saved["cpu_seconds"])
        self.curve[:] = saved["curve"]  # in place: the record holds this list
        self.episodes = int(saved["episodes"])

    def checkpoint(self) -> None:
        """The experiment's state and this run's progress, written atomically to ``checkpoints/resume.pt``."""
        folder = Path(self.experiment.folder_name) / "checkpoints"
        folder.mkdir(exist_ok=True)
        tmp = folder / f"{RESUME}.tmp"
        torch.save(self.experiment.state_dict(), tmp)
        os.replace(tmp, folder / RESUME)
        self.last_checkpoint = self.used()

    def on_batch_collected(self, batch: TensorDictBase) -> None:
        groups = list(self.experiment.group_map)
        done = batch.get(("next", groups[0], "done")).any(-2).squeeze(-1)  # one agent a group; they end together
        self.batch = {"batch_episodes": int(done.sum())}
        for group in groups:
            rewards = batch.get(("next", group, "episode_reward"))[done]
            self.batch[f"{group}_episode_reward"] = rewards.mean().item() if done.any() else math.nan
        captured = batch.get(("next", groups[0], "info", "captured"))[done]
        self.batch["captured"] = captured.float().mean().item() if done.any() else math.nan

    def on_train_end(self, training_td: TensorDictBase, group: str) -> None:
        if group != list(self.experiment.train_group_map)[-1]:
            return
        self.episodes += self.batch["batch_episodes"]
        point = {
            "iteration": len(self.curve) + 1,
            "frames": self.experiment.total_frames,
            "episodes": self.episodes,
            **self.batch,
            "cpu_seconds": round(self.used(), 2),
        }
        self.curve.append(point)
        self.log(line(point, self.budget))
        self.save()
        if point["cpu_seconds"] >= self.budget:
            raise BudgetSpent
        if point["cpu_seconds"] - self.last_checkpoint >= SAVE_EVERY:
            self.checkpoint()


def line(point: dict[str, Any], budget: float) -> str:
    """One progress line."""
    return (
        f"iteration {point['iteration']}: {point['frames']} frames, {point['episodes']} episodes; "
        f"the batch's {point['batch_episodes']}: episode reward pursuer {point['pursuer_episode_reward']:.1f}, "
        f"evader {point['evader_episode_reward']:.1f}, captured {point['captured']:.2f}; "
        f"CPU {point['cpu_seconds']:.0f}/{budget:.0f} s"
    )


def experiment_config(out: Path) -> ExperimentConfig:
    """BenchMARL's default experiment with :data:`CHANGES` applied, logging under ``out``; restoring a stopped
    run's checkpoint there, if it has one."""
    config = ExperimentConfig.get_from_yaml()
    for key, (value, _) in CHANGES.items():
        setattr(config, key, value)
    config.save_folder = str(out)
    config.restore_file = next((str(path) for path in out.glob(f"*/checkpoints/{RESUME}")), None)
    return config


def jsonable(value: Any) -> Any:
    """A value as strict JSON: classes and other objects by name, NaN as null."""
    if isinstance(value, dict):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(item) for item in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, bool | int | str):
        return value
    return getattr(value, "__name__", str(value))


def settings(algorithm: str, config: ExperimentConfig, algorithm_config: AlgorithmConfig, model: MlpConfig) -> dict:
    """The exact settings of a run, and where they came from."""
    base = "https://github.com/facebookresearch/BenchMARL/blob/main/benchmarl/conf"
    return {
        "algorithm": algorithm,
        "algorithm_config": jsonable(asdict(algorithm_config)),
        "algorithm_config_source": f"{base}/algorithm/{algorithm}.yaml (unchanged)",
        "model_config": jsonable(asdict(model)),
        "model_config_source": f"{base}/model/layers/mlp.yaml (unchanged; the critic's too)",
        "experiment_config": jsonable(
            {key: value for key, value in vars(config).items() if key not in ("save_folder", "restore_file")}
        ),
        "experiment_config_source": f"{base}/experiment/base_experiment.yaml, with experiment_changes",
        "experiment_changes": {key: {"value": jsonable(value), "why": why} for key, (value, why) in CHANGES.items()},
        "fine_tuned_reference": "https://github.com/facebookresearch/BenchMARL/blob/main/fine_tuned/vmas/conf/config.yaml",
        "torch_threads": 1,
        "n_envs": 1,
    }


def versions() -> dict[str, str]:
    """The versions of Python and of the libraries a run depends on."""
    names = ("benchmarl", "torchrl", "tensordict", "torch", "pettingzoo", "gymnasium", "numpy")
    return {"python": platform.python_version(), **{name: version(name) for name in names}}


def find_mlp(policy: nn.Module) -> Mlp:
    """The one BenchMARL ``Mlp`` inside a group's policy."""
    found = [module for module in policy.modules() if isinstance(module, Mlp)]
    if len(found) != 1:
        raise RuntimeError(f"expected one Mlp in the policy, found {len(found)}")
    return found[0]


def plain_layers(model: Mlp) -> nn.Sequential:
    """The MLP of a one-agent group as plain ``nn`` layers holding a copy of its trained weights."""
    multi = model.mlp
    if multi.n_agents != 1 or multi.centralized:
        raise RuntimeError("expected a decentralised MLP for a group of one agent")
    weights = multi.params[0]
    layers: list[nn.Module] = []
    for name, layer in multi._empty_net.named_children():  # the net without weights; params holds them
        if isinstance(layer, nn.Linear):
            plain = nn.Linear(layer.in_features, layer.out_features)
            plain.load_state_dict({key: weights[name, key].detach().clone() for key in ("weight", "bias")})
            layers.append(plain)
        elif next(layer.parameters(), None) is None and not list(layer.buffers()):
            layers.append(copy.deepcopy(layer))  # an activation
        else:
            raise RuntimeError(f"unexpected layer in the MLP: {layer}")
    return nn.Sequential(*layers)


class Squash(nn.Module):
    """The first ``n`` outputs (the location), through tanh, scaled to the action bounds ``[low, high]``."""

    def __init__(self, n: int, low: torch.Tensor, high: torch.Tensor) -> None:
        super().__init__()
        self.n = n
        self.register_buffer("offset", ((high + low) / 2).float())
        self.register_buffer("scale", ((high - low) / 2).float())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.tanh(x[..., : self.n]) * self.scale + self.offset


def pure_actor(experiment: Experiment, group: str) -> nn.Module:
    """The group's policy in deterministic mode as plain torch: MASAC's tanh of the loc, MADDPG's tanh of its
    output, each scaled to the action bounds."""
    spec = experiment.action_spec[group, "action"]
    low, high = spec.space.low[0], spec.space.high[0]
    actor = nn.Sequential(plain_layers(find_mlp(experiment.group_policies[group])), Squash(spec.shape[-1], low, high))
    return actor.eval().requires_grad_(False)


def check_actor(experiment: Experiment, group: str, actor: nn.Module) -> float:
    """The largest difference between ``actor`` and BenchMARL's deterministic policy on replayed observations;
    raises when over :data:`TOLERANCE`."""
    sample = experiment.replay_buffers[group].sample().select((group, "observation"))
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        expected = experiment.group_policies[group](sample.clone()).get((group, "action"))[:, 0]
        got = actor(sample.get((group, "observation"))[:, 0])
    difference = (got - expected).abs().max().item()
    if got.shape != expected.shape or not difference <= TOLERANCE:
        raise RuntimeError(f"the plain {group} actor differs from BenchMARL's policy by {difference}")
    return difference


@dataclass
class Record:
    """``benchmarl.json``: rewritten after each iteration and at the end."""

    path: Path
    fields: dict[str, Any] = field(default_factory=dict)

    def save(self) -> None:
        atomic_write_json(self.path, jsonable(self.fields))


def train(
    scenario: str,
    cpu_seconds: float,
    seed: int,
    out: Path,
    log: Callable[[str], None] = print,
    algorithm: str = "masac",
) -> PeerRun:
    """Train both roles of ``scenario`` with BenchMARL until this process's CPU time (children included, and the
    earlier sittings' of a continued run) reaches ``cpu_seconds``, checked after each iteration; write
    ``out/benchmarl.json``."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algorithm!r}: one of {sorted(ALGORITHMS)}")
    torch.set_num_threads(1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config, algorithm_config, model = (
        experiment_config(out),
        ALGORITHMS[algorithm].get_from_yaml(),
        MlpConfig.get_from_yaml(),
    )
    library = f"BenchMARL {version('benchmarl')} {algorithm.upper()}"
    record = Record(out / RECORD, {"library": library, "scenario": scenario, "seed": seed, "finished": False})
    record.fields |= {"cpu_budget": cpu_seconds, "settings": settings(algorithm, config, algorithm_config, model)}
    record.fields["versions"] = versions()
    progress = Progress(cpu_seconds, log, record.save)
    record.fields["curve"] = progress.curve
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="No episode terminated this iteration")
        experiment = Experiment(
            task=PecliTask(scenario, {"scenario": scenario}),
            algorithm_config=algorithm_config,
            model_config=model,
            critic_model_config=MlpConfig.get_from_yaml(),
            seed=seed,
            config=config,
            callbacks=[progress],
        )
        if config.restore_file is not None:
            log(f"continuing from {config.restore_file} ({progress.used():.0f} CPU s spent)")
        try:
            experiment.run()
        except BudgetSpent:
            pass
    actors = {group: pure_actor(experiment, group) for group in experiment.group_map}
    differences = {group: check_actor(experiment, group, actor) for group, actor in actors.items()}
    used = progress.used()
    record.fields |= {"finished": True, "frames": experiment.total_frames, "episodes": progress.episodes}
    record.fields |= {"iterations": len(progress.curve), "cpu_seconds": used, "actor_check_max_abs": differences}
    record.fields["experiment_folder"] = str(experiment.folder_name)
    record.save()
    (Path(experiment.folder_name) / "checkpoints" / RESUME).unlink(missing_ok=True)  # finished: the actors remain
    return PeerRun(
        actors=actors,
        steps=experiment.total_frames,
        episodes=progress.episodes,
        cpu_seconds=used,
        iterations=len(progress.curve),
        settings=record.fields["settings"],
        library=library,
    )
