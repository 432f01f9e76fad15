"""A TD3/DDPG policy whose actor and critic read different parts of a ``Dict`` observation.

The actor sees only what the player sees (``obs`` and, with a belief, its features); the critic also sees
the privileged full ``state`` and the opponent's action ``opp_action``. That is MADDPG's
centralised critic with decentralised execution, on top of SB3's ``TD3Policy``: only
``make_critic`` changes, so save/load through SB3's zip format works as usual.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.td3.policies import ContinuousCritic, TD3Policy

from pecli.rl.extractors import ACTOR_KEYS, CRITIC_KEYS, KeysExtractor


class CentralCriticPolicy(TD3Policy):
    """``TD3Policy`` with a decentralised actor and a centralised critic.

    Args:
        actor_keys: observation entries the actor's default extractor reads.
        critic_keys: observation entries the critic reads (with the learner's action appended by SB3).
        Other arguments are those of ``TD3Policy``; ``features_extractor_class`` sets the actor's extractor.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        actor_keys: Sequence[str] = ACTOR_KEYS,
        critic_keys: Sequence[str] = CRITIC_KEYS,
        features_extractor_class: type[BaseFeaturesExtractor] = KeysExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        self.actor_keys = tuple(actor_keys)
        self.critic_keys = tuple(critic_keys)
        if features_extractor_class is KeysExtractor:
            features_extractor_kwargs = {"keys": self.actor_keys}
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
            **kwargs,
        )

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> ContinuousCritic:
        extractor = KeysExtractor(self.observation_space, keys=self.critic_keys)
        critic_kwargs = {**self.critic_kwargs, "features_extractor": extractor, "features_dim": extractor.features_dim}
        return ContinuousCritic(**critic_kwargs).to(self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(actor_keys=self.actor_keys, critic_keys=self.critic_keys)
        return data
