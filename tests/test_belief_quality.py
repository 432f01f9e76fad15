"""Offline belief quality: windows from played games, a belief fitted on them, its location error."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th

from pecli.belief.model import BeliefModel
from pecli.rl.belief_quality import (
    belief_means,
    collect_windows,
    fit_belief,
    last_sighting,
    location_error,
    mean_nll,
)
from pecli.scenario import Scenario


def _model(kind: str, quick: Scenario, windows, role: str = "pursuer") -> BeliefModel:
    t = quick.training
    samples = -(-t.history_length // t.history_stride)
    window = (samples, windows.history.shape[1] // samples)
    return BeliefModel(kind, window, quick.model_dump(mode="json"), role, hidden=16, fc=8)  # type: ignore[arg-type]


@pytest.mark.parametrize("role", ["pursuer", "evader"])
def test_a_sighting_now_is_where_the_opponent_is(quick: Scenario, role: str) -> None:
    opponents = ["greedy"] if role == "pursuer" else ["pure-pursuit"]
    observer = "pure-pursuit" if role == "pursuer" else "greedy"
    windows = collect_windows(quick, observer, opponents, games=8, seed=3, role=role)  # type: ignore[arg-type]
    assert windows.history.shape[0] == windows.target.shape[0] == windows.unseen.shape[0] > 0
    assert (~windows.unseen).any() and np.abs(windows.target).max() <= 1.0
    last, sighted = last_sighting(_model("ukf", quick, windows, role).decoder, windows.history)
    seen_now = ~windows.unseen
    assert sighted[seen_now].all()  # what is seen now is in the window
    assert location_error(quick, last[seen_now], windows.target[seen_now]).max() < 1e-3  # and is the truth
    assert location_error(quick, np.zeros((1, 2)), np.ones((1, 2)))[0] == pytest.approx(np.hypot(*quick.arena.half))


def test_fitting_keeps_the_best_validation_state(quick: Scenario) -> None:
    th.manual_seed(0)
    data = collect_windows(quick, "pure-pursuit", ["random-walk", "greedy"], games=8, seed=0)
    validation = collect_windows(quick, "pure-pursuit", ["random-walk", "greedy"], games=4, seed=50)
    model = _model("bimdn", quick, data)
    before = mean_nll(model, validation)
    settings = quick.training.belief_settings.model_copy(update={"batch_size": 32})
    fit = fit_belief(model, data, validation, settings, updates=60, check_every=20)
    assert fit.validation_nll == pytest.approx(mean_nll(model, validation), rel=1e-5)  # the state it kept
    assert fit.validation_nll <= before and fit.kept_update in (0, 20, 40, 60)
    assert belief_means(model, validation.history).shape == (len(validation), 2)
    with pytest.raises(ValueError, match="nothing to fit"):
        fit_belief(_model("ukf", quick, data), data, validation, settings, updates=1, check_every=1)
