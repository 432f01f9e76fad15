"""An exported ONNX model as a :class:`Policy`: it plays, renders and joins tournaments like its checkpoint.

The game hands policies normalised observations; the exported graph takes SI rows. This policy
keeps the same memory as :class:`~pecli.policies.learned.LearnedPolicy` (:class:`WindowedPolicy`),
turns the frame stack and window into SI rows (:meth:`pecli.game.si.SILayout.to_si`) at each
decision, and plays the graph's ``action`` output. Its ``command`` attribute holds the SI command
of each game's last decision.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pecli.errors import ExportError, PolicyError
from pecli.game.si import SILayout
from pecli.policies.windowed import Draws, WindowedPolicy
from pecli.roles import Role
from pecli.runtime import ExportedModel
from pecli.scenario import Scenario, scenario_from_dict


def exported_scenario(sidecar: dict[str, Any], source: str = "sidecar") -> Scenario:
    """The scenario an exported model was exported for, from its sidecar."""
    config = sidecar.get("scenario", {}).get("config") if isinstance(sidecar.get("scenario"), dict) else None
    if not isinstance(config, dict):
        raise ExportError(f"{source}: the sidecar holds no scenario")
    return scenario_from_dict(config, source=source)


class ExportedPolicy(WindowedPolicy):
    """Plays an :class:`~pecli.runtime.ExportedModel` in the batched game.

    Args:
        model: the exported model.
        scenario: the game; must be the one the model was exported for.
        seed: seed of a mixed belief's draws (:meth:`reset` with a seed restarts them).
    """

    def __init__(
        self, model: ExportedModel, scenario: Scenario, seed: int | None = None, source: str = "the exported model"
    ) -> None:
        super().__init__(
            model.role,  # type: ignore[arg-type]
            scenario,
            frame_skip=model.frame_skip,
            frame_stack=model.frame_stack,
            history_length=model.history_length if model.has_history else None,
            history_stride=model.history_stride,
            draws=model.draws,
            seed=seed,
        )
        self.model = model
        self.source = source
        self.layout = SILayout(scenario, self.role)
        self.half = np.array(scenario.arena.half)
        self.command = np.zeros((0, 2))

    @classmethod
    def load(cls, path: str | Path, role: Role, scenario: Scenario, seed: int | None = None) -> ExportedPolicy:
        """Load an exported model; refuses one of another role or exported for another scenario."""
        try:
            model = ExportedModel.load(path)
        except ExportError as exc:
            raise PolicyError(str(exc)) from None
        if model.role != role:
            raise PolicyError(f"{path} is an exported {model.role}; it cannot play {role}")
        if model.scenario_fingerprint != scenario.fingerprint():
            raise PolicyError(
                f"{path} was exported for scenario '{model.scenario_name}' ({model.scenario_fingerprint}), "
                f"not for '{scenario.name}' ({scenario.fingerprint()}): pass the config it was trained with"
            )
        return cls(model, scenario, seed=seed, source=str(path))

    def reset(self, n: int, mask: np.ndarray | None = None, seed: int | None = None) -> None:
        if mask is None or n != self.n:
            self.command = np.zeros((n, 2))
        super().reset(n, mask, seed)

    def _inputs(self, stack: np.ndarray, history: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """Normalised stacks ``(d, k * dim)`` and windows ``(d, T * dim)`` as SI rows
        ``(d, k, dim)``, ``(d, T, dim)``."""
        dim = self.layout.dim
        rows = self.layout.to_si(stack.reshape(-1, dim)).reshape(stack.shape[0], -1, dim)
        if history is None:
            return rows, None
        return rows, self.layout.to_si(history.reshape(-1, dim)).reshape(history.shape[0], -1, dim)

    def _decide(
        self, stack: np.ndarray, history: np.ndarray | None, draws: Draws | None, due: np.ndarray
    ) -> np.ndarray:
        obs, window = self._inputs(stack, history)
        uniform, normal = draws if draws is not None else (None, None)
        outputs = self.model.run(obs, window, uniform, normal)
        action = outputs["action"]
        if action.shape != (obs.shape[0], 2):
            raise PolicyError(
                f"{self.source}: its graph answered actions of shape {action.shape}, not ({obs.shape[0]}, 2)"
            )
        self.command[due] = outputs["command"]
        return action

    def current_belief(self, games: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The belief given the window of the last :meth:`act` for the first ``games`` games:
        ``(weights (g, K), means (g, K, 2), stds (g, K, 2))``, normalised world coordinates (as
        :meth:`LearnedPolicy.current_belief`); ``None`` without a belief. Draws no random numbers."""
        memory = self.memory(games)
        if memory is None or memory[1] is None:
            return None
        obs, window = self._inputs(*memory)
        rows = obs.shape[0]
        zeros = (np.zeros((rows, self.draws), np.float32), np.zeros((rows, self.draws, 2), np.float32))
        outputs = self.model.run(obs, window, *zeros)
        return outputs["belief_weights"], outputs["belief_means"] / self.half, outputs["belief_stds"] / self.half

    def __repr__(self) -> str:
        return f"ExportedPolicy(role={self.role!r}, belief={self.model.belief!r})"
