"""Learned pool members of one network shape decide together (pecli.policies.stacked), as they would alone."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from pecli.game import Game
from pecli.policies import resolve_policy
from pecli.policies.learned import LearnedPolicy
from pecli.policies.mixed import MixedPolicy
from pecli.policies.stacked import WORTH_STACKING, StackedActors
from pecli.roles import opponent_of
from pecli.rl.train import TrainJob, checkpoint_meta, make_learner, with_overrides
from pecli.scenario import Scenario

TINY = {"buffer_size": 500, "batch_size": 16, "learning_starts": 50, "net_arch": [32, 32], "n_envs": 6,
        "belief_settings.hidden": 16, "belief_settings.fc": 8}


def members(quick: Scenario, belief: str, count: int, role: str = "evader", **settings) -> list[LearnedPolicy]:
    """``count`` fresh learned players (distinct weights: seeds 0 .. count-1) of one network shape."""
    scenario = with_overrides(quick, {**TINY, "belief": belief, **settings})
    out = []
    for seed in range(count):
        job = TrainJob(role=role, scenario=scenario, opponent="random-walk", zoo=Path("unused"), name="t", seed=seed)
        _, model, _ = make_learner(job, resolve_policy("random-walk", opponent_of(role), scenario), seed=seed)
        out.append(LearnedPolicy(model.policy.actor, role, scenario, checkpoint_meta(job, model, 0), seed=seed))
    return out


def play_both(quick: Scenario, players: list, steps: int = 120, games: int = 6) -> float:
    """The largest difference between the actions of a stacked pool of ``players`` and of the same pool one by
    one, on the same observations (the one-by-one pool's actions are played; games restart as they end)."""
    names = [f"m{i}" for i in range(len(players))]
    pools = [MixedPolicy("evader", copy.deepcopy(players), names, stack=stack)  # each its own copies: they keep memories
             for stack in (True, False)]
    game = Game(quick, n=games, seed=3, auto_reset=True)
    obs = game.reset(seed=3)
    for pool in pools:
        pool.reset(games, seed=5)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(steps):
        stacked, alone = (pool.act(obs["evader"]) for pool in pools)
        worst = max(worst, float(np.abs(stacked - alone).max()))
        result = game.step(rng.uniform(-1, 1, (games, 2)), alone)
        obs = result.obs
        if result.done.any():
            for pool in pools:
                pool.reset(games, mask=result.done)
    return worst


@pytest.mark.parametrize("belief", ["none", "bimdn"])
def test_a_stacked_pool_plays_as_its_members_one_by_one(quick: Scenario, belief: str, monkeypatch) -> None:
    count = 3 * WORTH_STACKING[belief]  # with 16 games, enough of them decide together in most steps
    players = members(quick, belief, count)
    pool = MixedPolicy("evader", players, [str(i) for i in range(count)])
    assert len(pool._stacked) == count and len({id(stack) for stack, _ in pool._stacked.values()}) == 1
    together: list[int] = []
    decide = StackedActors.decide
    monkeypatch.setattr(StackedActors, "decide", lambda self, rows, *a: together.append(len(rows)) or decide(self, rows, *a))
    assert play_both(quick, players, games=16) < 1e-5
    assert len(together) > 20 and min(together) >= WORTH_STACKING[belief]  # most decisions were taken together


def test_only_members_of_one_shape_stack_and_the_others_decide_alone(quick: Scenario) -> None:
    players = [*members(quick, "none", 3), *members(quick, "bimdn", 2), resolve_policy("greedy", "evader", quick),
               *members(quick, "bimdn-mixed", 2), *members(quick, "none", 2, net_arch=[16, 16])]
    pool = MixedPolicy("evader", players, [str(i) for i in range(10)])
    stacks = {index: id(stack) for index, (stack, _) in pool._stacked.items()}
    assert sorted(stacks) == [0, 1, 2, 3, 4, 8, 9]  # not the scripted one, nor the mixed belief's sampling actors
    assert len({stacks[i] for i in (0, 1, 2)}) == 1 and stacks[3] == stacks[4] and stacks[8] == stacks[9]
    assert len(set(stacks.values())) == 3  # none 32-wide, bimdn, none 16-wide
    assert StackedActors.key(players[5]) is None and StackedActors.key(players[6]) is None
    assert play_both(quick, players, steps=60) < 1e-5
    assert MixedPolicy("evader", players, [str(i) for i in range(10)], stack=False)._stacked == {}
