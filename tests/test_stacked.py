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
from pecli.rl.train import TrainJob, checkpoint_meta, make_learner, with_overrides
from pecli.roles import opponent_of
from pecli.scenario import Scenario

TINY = {
    "buffer_size": 500,
    "batch_size": 16,
    "learning_starts": 50,
    "net_arch": [32, 32],
    "n_envs": 6,
    "belief_settings.hidden": 16,
    "belief_settings.fc": 8,
}


def members(quick: Scenario, belief: str, count: int, role: str = "evader", **settings) -> list[LearnedPolicy]:
    """``count`` fresh learned players (distinct weights: seeds 0 .. count-1) of one network shape."""
    scenario = with_overrides(quick, {**TINY, "belief": belief, **settings})
    out = []
    for seed in range(count):
        job = TrainJob(role=role, scenario=scenario, opponent="random-walk", zoo=Path("unused"), name="t", seed=seed)
        _, model, _ = make_learner(job, resolve_policy("random-walk", opponent_of(role), scenario), seed=seed)
        out.append(LearnedPolicy(model.policy.actor, role, scenario, checkpoint_meta(job, model, 0), seed=seed))
    return out


def play_both(quick: Scenario, players: list, steps: int = 120, games: int = 16) -> float:
    """The largest difference between the actions of a stacked pool of ``players`` and of the same pool one by
    one, on the same observations (the one-by-one pool's actions are played; games restart as they end)."""
    role = players[0].role
    names = [f"m{i}" for i in range(len(players))]
    pools = [
        MixedPolicy(role, copy.deepcopy(players), names, stack=stack)  # each its own copies: they keep memories
        for stack in (True, False)
    ]
    game = Game(quick, n=games, seed=3, auto_reset=True)
    obs = game.reset(seed=3)
    for pool in pools:
        pool.reset(games, seed=5)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(steps):
        stacked, alone = (pool.act(obs[role]) for pool in pools)
        worst = max(worst, float(np.abs(stacked - alone).max()))
        other = rng.uniform(-1, 1, (games, 2))
        result = game.step(*((alone, other) if role == "pursuer" else (other, alone)))
        obs = result.obs
        if result.done.any():
            for pool in pools:
                pool.reset(games, mask=result.done)
    return worst


def counting(monkeypatch) -> list[tuple[int, int, int]]:
    """Each stacked decision from now on: (its stack's id, members deciding, their games); each checked against
    the stack's limits."""
    used: list[tuple[int, int, int]] = []
    decide = StackedActors.decide

    def counted(self: StackedActors, rows, stacks, histories):
        used.append((id(self), len(rows), sum(len(stack) for stack in stacks)))
        assert len(rows) >= self.worth and used[-1][2] <= self.games_per_member * len(rows)
        return decide(self, rows, stacks, histories)

    monkeypatch.setattr(StackedActors, "decide", counted)
    return used


@pytest.mark.parametrize(
    ("belief", "role"),
    [("none", "evader"), ("bimdn", "evader"), ("bimdn", "pursuer"), ("ukf", "evader"), ("image", "pursuer")],
)
def test_a_stacked_pool_plays_as_its_members_one_by_one(quick: Scenario, belief: str, role: str, monkeypatch) -> None:
    """The evader sees in the world frame; the car pursuer's belief points turn into its heading (and its image
    belief's wedge-shaped coverage)."""
    count = 3 * WORTH_STACKING[belief]  # with 16 games, enough of them decide together in most steps
    players = members(quick, belief, count, role)
    pool = MixedPolicy(role, players, [str(i) for i in range(count)])
    assert len(pool._stacked) == count and len({id(stack) for stack, _ in pool._stacked.values()}) == 1
    used = counting(monkeypatch)
    assert play_both(quick, players) < 1e-5
    assert len(used) > 20  # most decisions were taken together


def test_only_members_of_one_shape_stack_and_the_others_decide_alone(quick: Scenario, monkeypatch) -> None:
    players = [
        *members(quick, "none", 6),
        *members(quick, "bimdn", 6),
        resolve_policy("greedy", "evader", quick),
        *members(quick, "bimdn-mixed", 2),
        *members(quick, "none", 6, net_arch=[16, 16]),
    ]
    pool = MixedPolicy("evader", players, [str(i) for i in range(len(players))])
    stacks = {index: id(stack) for index, (stack, _) in pool._stacked.items()}
    assert sorted(stacks) == [
        *range(12),
        *range(15, 21),
    ]  # not the scripted one, nor the mixed belief's sampling actors
    assert [len({stacks[i] for i in group}) for group in (range(6), range(6, 12), range(15, 21))] == [1, 1, 1]
    assert len(set(stacks.values())) == 3  # none 32-wide, bimdn, none 16-wide
    assert StackedActors.key(players[12]) is None and StackedActors.key(players[13]) is None
    used = counting(monkeypatch)
    assert play_both(quick, players, steps=80, games=24) < 1e-5
    assert len({stack for stack, _, _ in used}) >= 2  # stacks of two shapes decided together at times
    assert MixedPolicy("evader", players, [str(i) for i in range(len(players))], stack=False)._stacked == {}


def test_many_games_per_member_decide_on_their_own(quick: Scenario, monkeypatch) -> None:
    players = members(quick, "none", 5)
    used = counting(monkeypatch)
    assert play_both(quick, players, steps=20, games=64) < 1e-5  # about 13 games each: one by one is cheaper
    assert used == []
