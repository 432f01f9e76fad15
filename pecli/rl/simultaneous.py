"""The paper's simultaneous schedule (MADDPG): two SB3 learners act in the same games and both learn every step.

The loop, read top to bottom: both learners sample their actions (SB3's own exploration, noise
included); the games step once with both; each critic's ``opp_action`` is set to what the other
learner did at this step and, for the next observation, to what the other learner's actor would do
there without noise (MADDPG's target actions); each learner stores its transition, counts its steps,
runs its callbacks and, every ``train_freq`` vector steps once past ``learning_starts``, its
``gradient_steps`` updates. SB3's ``_sample_action``, ``_store_transition`` and ``train`` do the work,
so every algorithm and callback that works with ``learn`` works here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.noise import VectorizedActionNoise

from pecli.roles import ROLES, Role, opponent_of

LOG_INTERVAL = 4  # episodes between TensorBoard dumps, as SB3's learn()


def learn_simultaneously(models: dict[Role, Any], steps: int, callbacks: dict[Role, list[BaseCallback]]) -> None:
    """Train both ``models`` (their ``env`` two faces of one :class:`~wrappers.simultaneous.SimultaneousGame`)
    for ``steps`` more transitions each, or until a callback stops.

    Raises whatever a callback or the models raise (``KeyboardInterrupt`` included), leaving both
    models usable: the caller commits them.
    """
    runs: dict[Role, BaseCallback] = {}
    targets: dict[Role, int] = {}
    for role in ROLES:
        model = models[role]
        targets[role], runs[role] = model._setup_learn(
            steps,
            CallbackList(callbacks[role]),  # plus its steps so far
            reset_num_timesteps=False,
            tb_log_name=role,
        )
        runs[role].on_training_start(locals(), globals())
    n = models["pursuer"].env.num_envs
    vector_steps = 0
    try:
        while any(models[role].num_timesteps < targets[role] for role in ROLES):
            for model in models.values():
                model.policy.set_training_mode(False)
            sampled = {
                role: models[role]._sample_action(models[role].learning_starts, models[role].action_noise, n)
                for role in ROLES
            }
            for role in ROLES:
                models[role].env.step_async(sampled[role][0])
            results = {role: models[role].env.step_wait() for role in ROLES}
            greedy = {role: models[role].predict(results[role][0], deterministic=True)[0] for role in ROLES}
            vector_steps += 1
            for role in ROLES:
                other = opponent_of(role)
                models[role]._last_obs["opp_action"] = sampled[other][1].astype(np.float32)
                results[role][0]["opp_action"] = np.asarray(greedy[other], dtype=np.float32)
                if not _step(models[role], runs[role], sampled[role][1], *results[role], vector_steps):
                    return
    finally:
        for role in ROLES:
            runs[role].on_training_end()


def _step(
    model: Any,
    callback: BaseCallback,
    buffer_action: np.ndarray,
    new_obs: dict[str, np.ndarray],
    rewards: np.ndarray,
    dones: np.ndarray,
    infos: list[dict[str, Any]],
    vector_steps: int,
) -> bool:
    """One learner's share of a vector step, as SB3's ``collect_rollouts`` and ``learn`` do it; ``False`` to stop."""
    model.num_timesteps += len(dones)
    callback.update_locals({"new_obs": new_obs, "rewards": rewards, "dones": dones, "infos": infos})
    if not callback.on_step():
        return False
    model._update_info_buffer(infos, dones)
    model._store_transition(model.replay_buffer, buffer_action, new_obs, rewards, dones, infos)
    model._update_current_progress_remaining(model.num_timesteps, model._total_timesteps)
    model._on_step()
    for index in np.flatnonzero(dones):
        model._episode_num += 1
        if isinstance(model.action_noise, VectorizedActionNoise):
            model.action_noise.reset(indices=[int(index)])
        if model._episode_num % LOG_INTERVAL == 0:
            model.dump_logs()
    if vector_steps % model.train_freq.frequency == 0 and model.num_timesteps > model.learning_starts:
        model.train(batch_size=model.batch_size, gradient_steps=model.gradient_steps)
    return True
