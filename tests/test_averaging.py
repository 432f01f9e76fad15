"""Weight averaging of checkpoints (``pecli zoo average``): the mean, and what counts as one network."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch as th

from pecli.rl.averaging import SAME_NETWORK, _network, mean_state
from pecli.zoo import CheckpointMeta, ZooError


def test_the_mean_state_averages_weights_and_keeps_the_newest_counters() -> None:
    old = {"w": th.tensor([1.0, 2.0]), "n": th.tensor(3)}
    new = {"w": th.tensor([3.0, 6.0]), "n": th.tensor(7)}
    mean = mean_state([old, new])
    assert th.equal(mean["w"], th.tensor([2.0, 4.0])) and mean["w"].dtype == th.float32
    assert int(mean["n"]) == 7  # an integer buffer (a batch-norm counter) is not averaged
    with pytest.raises(ZooError, match="different parameters"):
        mean_state([old, {"w": new["w"]}])
    with pytest.raises(ZooError, match="w differ in shape"):
        mean_state([old, {"w": th.zeros(3, 3), "n": new["n"]}])


def test_one_network_ignores_the_training_settings_a_belief_carries() -> None:
    scenario = {"name": "tuned", "training": {"selfplay": {"league_floor": 0.3}}}
    meta = CheckpointMeta(
        role="pursuer",
        steps=1,
        episodes=1,
        algo="td3",
        belief="bimdn",
        scenario="tuned",
        scenario_hash="h",
        opponent="selfplay",
        frame_skip=2,
        frame_stack=4,
        history_length=200,
        history_stride=10,
        belief_kwargs={"hidden": 128, "scenario": scenario},
    )
    later = replace(meta, belief_kwargs={"hidden": 128, "scenario": {**scenario, "training": {"selfplay": {}}}})
    assert all(_network(meta, name) == _network(later, name) for name in SAME_NETWORK)  # a setting pecli added
    wider = replace(meta, belief_kwargs={"hidden": 64, "scenario": scenario})
    assert _network(meta, "belief_kwargs") != _network(wider, "belief_kwargs")
