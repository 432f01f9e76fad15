"""A pecli scenario as a BenchMARL task (needs benchmarl, of the ``peers`` extra).

BenchMARL pickles the task into its experiment folder, so the class lives in an importable module.
"""

from __future__ import annotations

from collections.abc import Callable

from benchmarl.environments.pettingzoo.common import PettingZooClass
from torchrl.envs import EnvBase, PettingZooWrapper

from pecli.game.pettingzoo_env import parallel_env
from pecli.scenario import load_scenario


class PecliTask(PettingZooClass):
    """The scenario ``config["scenario"]``: two groups of one agent, continuous actions, a global state."""

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: str
    ) -> Callable[[], EnvBase]:
        scenario = self.config["scenario"]
        return lambda: PettingZooWrapper(env=parallel_env(scenario), return_state=True, seed=seed, device=device)

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_state(self) -> bool:
        return True

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return load_scenario(self.config["scenario"]).horizon

    @staticmethod
    def env_name() -> str:
        return "pecli"
