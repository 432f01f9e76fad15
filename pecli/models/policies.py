"""Policies whose actor and critic read different parts of a ``Dict`` observation.

The actor sees only what the player sees (``obs`` and, with a belief, its features); the critic also sees
the privileged full ``state`` and the opponent's action ``opp_action``. That is MADDPG's
centralised critic with decentralised execution. :class:`CentralCritic` adds it to any SB3 actor-critic
policy whose critics are built by ``make_critic``: only the critic's feature extractor changes, so the
algorithms train, save and load as usual.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from gymnasium import spaces
from sb3_contrib.crossq.policies import CrossQPolicy
from sb3_contrib.tqc.policies import TQCPolicy
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.sac.policies import SACPolicy
from stable_baselines3.td3.policies import TD3Policy

from pecli.models.extractors import ACTOR_KEYS, CRITIC_KEYS, KeysExtractor


class CentralCritic:
    """Mixin for an SB3 policy: a decentralised actor and a centralised critic.

    Args:
        actor_keys: observation entries the actor's default extractor reads.
        critic_keys: observation entries the critic reads (with the learner's action appended by SB3).
        Other arguments are those of the policy it is mixed into; ``features_extractor_class`` sets the
        actor's extractor.
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
        super().__init__(  # type: ignore[call-arg]
            observation_space,
            action_space,
            lr_schedule,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
            **kwargs,
        )

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> BaseModel:
        """The policy's own critic (and target critic) over the critic's keys, whatever extractor SB3 offers."""
        return super().make_critic(KeysExtractor(self.observation_space, keys=self.critic_keys))  # type: ignore[misc]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(actor_keys=self.actor_keys, critic_keys=self.critic_keys)
        return data


class CentralCriticPolicy(CentralCritic, TD3Policy):
    """TD3's and DDPG's policy (``TD3Policy``) with the centralised critic."""


class CentralCriticSACPolicy(CentralCritic, SACPolicy):
    """SAC's policy with the centralised critic; the actor is a squashed Gaussian."""


class CentralCriticTQCPolicy(CentralCritic, TQCPolicy):
    """TQC's policy (quantile critics) with the centralised critic."""


class CentralCriticCrossQPolicy(CentralCritic, CrossQPolicy):
    """CrossQ's policy (batch-renormalised actor and critics, no target networks) with the centralised critic."""
