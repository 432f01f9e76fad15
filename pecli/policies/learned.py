"""A trained checkpoint as a :class:`Policy`: SB3's actor with the memory it was trained with.

The memory, the decision clock and a mixed belief's random numbers are :class:`WindowedPolicy`'s;
this module runs the actor (belief network included) at each decision.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch as th

from pecli.errors import PecliError, PolicyError
from pecli.policies.windowed import Draws, WindowedPolicy
from pecli.roles import Role
from pecli.scenario import Scenario
from pecli.text import article
from pecli.zoo import CheckpointMeta, ZooError, read_metadata


class LearnedPolicy(WindowedPolicy):
    """Plays with the actor of an SB3 model.

    Args:
        actor: the model's actor network (reads ``obs`` and, with a belief, ``history``).
        role: the role it plays.
        scenario: the game; observations have its layout.
        meta: the checkpoint's metadata (frame skip/stack and history window come from it).
        seed: seed of a mixed belief's draws (:meth:`reset` with a seed restarts them).
    """

    def __init__(
        self, actor: th.nn.Module, role: Role, scenario: Scenario, meta: CheckpointMeta, seed: int | None = None
    ) -> None:
        self._belief = getattr(actor.features_extractor, "belief", None)
        mixed = self._belief is not None and self._belief.kind == "bimdn-mixed"
        super().__init__(
            role,
            scenario,
            frame_skip=meta.frame_skip,
            frame_stack=meta.frame_stack,
            history_length=meta.history_length if meta.belief != "none" else None,
            history_stride=meta.history_stride,
            draws=self._belief.samples if mixed else 0,
            seed=seed,
        )
        self.actor = actor
        self.meta = meta
        from pecli.models.algorithms import deterministic_actor

        actor.train(False)  # batch (re)normalisation layers (CrossQ) play with their running statistics
        self._act = deterministic_actor(actor)

    @classmethod
    def load(cls, path: str | Path, role: Role, scenario: Scenario, seed: int | None = None) -> LearnedPolicy:
        """Load a zoo checkpoint; refuses one of another role or trained on another scenario."""
        path = Path(path)
        try:
            meta = read_metadata(path)
        except ZooError as exc:
            raise PolicyError(str(exc)) from None
        if meta.role != role:
            raise PolicyError(f"{path} is {article(meta.role)} checkpoint; it cannot play {role}")
        if meta.scenario_hash != scenario.fingerprint():
            raise PolicyError(
                f"{path} was trained on {_scenario_mismatch(path, meta, scenario)}: pass the config it was trained with"
            )
        from pecli.models.checkpoint import (
            load_policy,  # SB3 and the networks load only when a checkpoint is asked for
        )

        try:
            policy = load_policy(path, meta, scenario)
        except ZooError as exc:
            raise PolicyError(str(exc)) from None
        return cls(policy.actor, role, scenario, meta, seed=seed)

    def current_belief(self, games: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The belief given the window of the last :meth:`act`, for drawing, for the first ``games`` games:
        ``(weights (g, K), means (g, K, 2), stds (g, K, 2))`` in normalised world coordinates;
        ``None`` for a policy without a belief."""
        memory = self.memory(games)
        if self._belief is None or memory is None or memory[1] is None:
            return None
        with th.no_grad():
            mixture = self._belief.mixture(th.as_tensor(memory[1]))
        return mixture.weights.numpy(), mixture.means.numpy(), mixture.stds.numpy()

    def _decide(
        self, stack: np.ndarray, history: np.ndarray | None, draws: Draws | None, due: np.ndarray
    ) -> np.ndarray:
        """SB3's deterministic ``Actor.forward`` without its preprocessing, which insists on the training-time
        keys (a belief's actor trained on stored ``belief`` features but plays from the ``history`` window):
        ``deterministic_actor(actor)(actor.features_extractor(batch))``, on the actor's device."""
        batch = {"obs": stack}
        if history is not None:
            batch["history"] = history
        if draws is not None:
            batch["uniform"], batch["normal"] = draws
        device = self.actor.device
        with th.no_grad():
            features = self.actor.features_extractor(
                {key: th.as_tensor(value, device=device) for key, value in batch.items()}
            )
            return self._act(features).cpu().numpy()

    def __repr__(self) -> str:
        return f"LearnedPolicy(role={self.role!r}, algo={self.meta.algo!r}, steps={self.meta.steps})"


def _scenario_mismatch(path: Path, meta: CheckpointMeta, scenario: Scenario) -> str:
    """How the game ``path`` learned differs from ``scenario``: the differing keys when its run's config is
    beside it, else the two names and fingerprints."""
    from pecli.zoo import run_of

    run = run_of(path)
    if run is not None:
        try:
            trained = run.scenario()
        except PecliError:
            trained = None
        if trained is not None and trained.fingerprint() == meta.scenario_hash:
            changes = [f"{key} {theirs!r} there, {ours!r} here" for key, ours, theirs in scenario.differences(trained)]
            more = f" and {len(changes) - 3} more" if len(changes) > 3 else ""
            return f"'{meta.scenario}', which differs from '{scenario.name}' in " + "; ".join(changes[:3]) + more
    return (
        f"scenario '{meta.scenario}' (fingerprint {meta.scenario_hash}), another game than '{scenario.name}' "
        f"({scenario.fingerprint()})"
    )
