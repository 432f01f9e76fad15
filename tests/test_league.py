"""The league: main learners against a pool that keeps the scripted players, and exploiters that join it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pecli.errors import ConfigError
from pecli.match import play_match
from pecli.policies import resolve_policy
from pecli.rl import schedules as schedules_module
from pecli.rl import selfplay as selfplay_module
from pecli.rl.pool import OpponentPool
from pecli.rl.selfplay import SelfPlay, SelfPlayInterrupted, SelfPlayJob
from pecli.rl.train import with_overrides
from pecli.roles import opponent_of
from pecli.scenario import Scenario
from pecli.zoo import read_metadata

ADVERSARIES = ("circler", "blindside", "wall-runner", "hider", "corner-sitter")  # pecli's evaders, in every league
TINY = {
    "buffer_size": 2000,
    "batch_size": 32,
    "learning_starts": 100,
    "net_arch": [16, 16],
    "n_envs": 4,
    "checkpoint_every": 5,
    "selfplay.rounds": 2,
    "selfplay.steps_per_round": 240,
    "selfplay.opponents": "league",
    "selfplay.exploiter_join": 0.05,
}


def job(quick: Scenario, zoo: Path) -> SelfPlayJob:
    return SelfPlayJob(with_overrides(quick, TINY), zoo, "lg", seed=0, progress=False)


def state(run: Path) -> dict:
    return json.loads((run / "selfplay.json").read_text())


def test_the_scripted_players_keep_their_share() -> None:
    pool = OpponentPool("evader")
    for name in ("greedy", "circler"):
        pool.add(name, name, generation=0)
    for r in (1, 2):
        pool.add(f"evader-r{r:03d}", f"evader/round-00{r}.zip", generation=r)
        for _ in range(50):
            pool.observe(f"evader-r{r:03d}", True)  # the learned evaders beat the learner: pfsp wants only them
    for _ in range(50):
        pool.observe("greedy", False)
        pool.observe("circler", False)
    pfsp, league = pool.weights("pfsp"), pool.weights("league", floor=0.2)
    assert pfsp[:2].sum() < 0.05 and league[:2].sum() == pytest.approx(0.2 + 0.8 * pfsp[:2].sum())
    assert league.sum() == pytest.approx(1.0)


def test_a_pfsp_floor_goes_to_the_scripted_players_that_still_win() -> None:
    pool = OpponentPool("evader")
    for name in ("greedy", "blindside"):
        pool.add(name, name, generation=0)
    pool.add("evader-r001", "evader/round-001.zip", generation=1)
    for won in [True] * 30 + [False] * 70:  # blindside beats the learner 3 games in 10, greedy never
        pool.observe("blindside", won)
        pool.observe("greedy", False)
    uniform, pfsp = pool.weights("league", floor=0.5), pool.weights("league", floor=0.5, split="pfsp")
    assert uniform[:2].sum() == pytest.approx(pfsp[:2].sum())  # the scripted players' share is the floor's either way
    assert pfsp[1] > uniform[1] > uniform[0] > pfsp[0]  # but the pfsp split gives blindside more of it, greedy less
    assert pfsp.sum() == pytest.approx(1.0)
    with pytest.raises(ValueError, match="unknown league floor split"):
        pool.weights("league", floor=0.5, split="elo")


def test_the_joined_exploiters_keep_their_share() -> None:
    pool = OpponentPool("evader")
    pool.add("greedy", "greedy", generation=0)
    for r in (1, 2):
        pool.add(f"evader-r{r:03d}", f"evader/round-00{r}.zip", generation=r)
        pool.add(f"exploiter-evader-r{r:03d}", f"exploiter-evader/round-00{r}.zip", generation=r)
    for _ in range(50):
        pool.observe("evader-r002", True)  # the newest main evader beats the learner; the rest never do
        for name in ("greedy", "evader-r001", "exploiter-evader-r001", "exploiter-evader-r002"):
            pool.observe(name, False)
    pool.observe("exploiter-evader-r002", True)
    assert [e.kind for e in pool.entries] == ["main", "main", "exploiter", "main", "exploiter"]
    pfsp = pool.weights("pfsp")
    league = pool.weights("league", floor=0.2, exploiter_share=0.3)
    exploiters = [2, 4]
    assert pfsp[exploiters].sum() < 0.05
    assert league[exploiters].sum() == pytest.approx(0.3 + 0.5 * pfsp[exploiters].sum())
    assert league[0] == pytest.approx(0.2 + 0.5 * pfsp[0])  # the scripted floor as before
    assert league[4] > league[2]  # split by pfsp: most to the exploiter that still wins a game
    assert league.sum() == pytest.approx(1.0)
    assert np.allclose(pool.weights("league", floor=0.2, exploiter_share=0.0), pool.weights("league", floor=0.2))
    only_exploiters = OpponentPool("evader")
    only_exploiters.add("exploiter-evader-r001", "exploiter-evader/round-001.zip", generation=1)
    assert only_exploiters.weights("league", exploiter_share=0.3) == pytest.approx([1.0])


def test_a_league_needs_the_alternating_schedule(quick: Scenario) -> None:
    with pytest.raises(ConfigError, match="needs the alternating schedule"):
        with_overrides(quick, {"selfplay.opponents": "league", "selfplay.schedule": "simultaneous"})


def test_the_floor_and_the_exploiters_share_cannot_keep_more_than_every_game(quick: Scenario) -> None:
    with pytest.raises(ConfigError, match="together keep more than all the games"):
        with_overrides(quick, {"selfplay.league_floor": 0.6, "selfplay.league_exploiter_share": 0.5})


def test_a_main_pursuer_spends_the_exploiters_share_on_them(quick: Scenario, tmp_path: Path) -> None:
    """Round 1's evader exploiter joins (a timeout of one turn); round 2's main pursuer then draws the joined
    exploiters with at least ``league_exploiter_share`` of its weights."""
    league = with_overrides(
        quick,
        {
            **TINY,
            "selfplay.league_exploiter_share": 0.4,
            "selfplay.exploiter_join": 1.0,
            "selfplay.league_exploiter_timeout": 1,
            "selfplay.league_exploiter_roles": ["evader"],
        },
    )
    SelfPlay(SelfPlayJob(league, tmp_path, "lg", seed=0, progress=False), report=lambda line: None).run()
    run = tmp_path / "lg"
    assert [t["joined"] for t in state(run)["turns"] if t["learner"] == "exploiter" and t["round"] == 1] == [True]
    weights = {o["name"]: o["weight"] for o in read_metadata(run / "pursuer" / "round-002.zip").opponents}
    assert "exploiter-evader-r001" in weights
    assert 0.4 <= weights["exploiter-evader-r001"] < 1.0
    assert sum(weights.values()) == pytest.approx(1.0, abs=1e-3)


def test_a_league_trains_main_agents_and_exploiters(quick: Scenario, tmp_path: Path) -> None:
    lines: list[str] = []
    SelfPlay(job(quick, tmp_path), report=lines.append).run()
    run = tmp_path / "lg"
    turns, pools = state(run)["turns"], state(run)["pools"]
    assert [(t["round"], t["role"], t["learner"]) for t in turns] == [
        (r, role, kind) for r in (1, 2) for kind in ("main", "exploiter") for role in ("pursuer", "evader")
    ]
    assert set(ADVERSARIES) <= {e["name"] for e in pools["evader"]["entries"]}
    assert "interceptor" in {e["name"] for e in pools["pursuer"]["entries"]}
    for t in (t for t in turns if t["learner"] == "exploiter"):
        meta = read_metadata(run / t["checkpoint"])
        assert t["checkpoint"].startswith(f"exploiter-{t['role']}/")
        assert [o["name"] for o in meta.opponents] == [
            f"{'evader' if t['role'] == 'pursuer' else 'pursuer'}-r{t['round']:03d}"
        ]
        in_pool = any(e["spec"] == t["checkpoint"] for e in pools[t["role"]]["entries"])
        assert in_pool == t["joined"]  # only an exploiter that beat the main agent joins
        won = 1 - meta.opponents[0]["opponent_wins"] / max(meta.opponents[0]["episodes"], 1)
        assert t["joined"] == (meta.opponents[0]["episodes"] > 0 and won >= 0.05)
    joined = [t for t in turns if t["learner"] == "exploiter" and t["joined"] and t["round"] == 1]
    assert joined, "no exploiter joined in round 1 (the test expects one with this seed)"
    for t in joined:  # it started afresh: no parent, and only one round of steps
        again = read_metadata(run / f"exploiter-{t['role']}" / "round-002.zip")
        assert again.parent == "" and again.steps == 240
    assert "exploiter" in lines[0]
    tensorboard = {str(path.relative_to(run / "tb")) for path in (run / "tb").glob("**/events.out.tfevents.*")}
    assert {path.split("/events")[0] for path in tensorboard} == {
        "pursuer_0",
        "evader_0",
        *(f"exploiter-{role}/r00{r}_0" for role in ("pursuer", "evader") for r in (1, 2)),
    }


@pytest.mark.parametrize(
    "every, after, roles, exploited",
    [
        (2, 0, ["pursuer", "evader"], (2,)),
        (0, 0, ["pursuer", "evader"], ()),
        (1, 1e-6, ["pursuer", "evader"], (2,)),
        (1, 100, ["pursuer", "evader"], ()),
        (1, 0, ["evader"], (1, 2)),
    ],
)
def test_the_exploiters_train_every_kth_round_once_the_run_spent_its_cpu_or_never(
    quick: Scenario, tmp_path: Path, every: int, after: float, roles: list[str], exploited: tuple[int, ...]
) -> None:
    """``after`` CPU-hours: 1e-6 (3.6 ms) is spent by round 1's turns, so round 2 has exploiters; 100 never is.
    ``roles``: the sides that have an exploiter. An exploiter plays the real game: no curriculum."""
    league = with_overrides(
        quick,
        {
            **TINY,
            "selfplay.league_exploiter_every": every,
            "selfplay.league_exploiter_after": after,
            "selfplay.league_exploiter_roles": roles,
        },
    )
    loop = SelfPlay(SelfPlayJob(league, tmp_path, "lg", seed=0, progress=False), report=lambda line: None)
    loop.run()
    run = tmp_path / "lg"
    turns, pools = state(run)["turns"], state(run)["pools"]
    assert [(t["round"], t["role"], t["learner"]) for t in turns] == [
        (r, role, kind)
        for r in (1, 2)
        for kind in ("main", "exploiter")[: 1 + (r in exploited)]
        for role in ("pursuer", "evader")
        if kind == "main" or role in roles
    ]
    assert (run / "exploiter-pursuer").is_dir() == (bool(exploited) and "pursuer" in roles)
    assert set(ADVERSARIES) <= {e["name"] for e in pools["evader"]["entries"]}  # still a league
    assert all(learner.curriculum is not None for learner in loop.learners.values())  # quick.yaml has one
    assert all(learner.curriculum is None for learner in loop.exploiters.values())


def test_an_exploiter_that_does_not_win_joins_at_its_timeout(quick: Scenario, tmp_path: Path) -> None:
    """``exploiter_join: 1``: an exploiter joins by winning every game of its turn, or at the end of its second
    turn since it started afresh (a timeout of 2), and starts afresh after either."""
    league = with_overrides(
        quick, {**TINY, "selfplay.rounds": 3, "selfplay.exploiter_join": 1.0, "selfplay.league_exploiter_timeout": 2}
    )
    lines: list[str] = []
    SelfPlay(SelfPlayJob(league, tmp_path, "lg", seed=0, progress=False), report=lines.append).run()
    run = tmp_path / "lg"
    turns, pools = state(run)["turns"], state(run)["pools"]
    timeouts = 0
    for role in ("pursuer", "evader"):
        since = 0  # the exploiter's turns since it started afresh
        for t in (t for t in turns if t["learner"] == "exploiter" and t["role"] == role):
            since += 1
            meta = read_metadata(run / t["checkpoint"])
            assert (meta.parent == "") == (since == 1)
            opponent = meta.opponents[0]
            won = opponent["episodes"] > 0 and opponent["opponent_wins"] == 0
            assert t["joined"] == (won or since == 2)
            assert any(e["spec"] == t["checkpoint"] for e in pools[role]["entries"]) == t["joined"]
            timeouts += t["joined"] and not won
            since = 0 if t["joined"] else since
    assert timeouts >= 2  # with this seed: the evader exploiter never wins a game
    assert any("joins the pool (its timeout)" in line for line in lines)


def test_join_games_decide_whether_an_exploiter_joins(quick: Scenario, tmp_path: Path) -> None:
    """``exploiter_join_games: N``: after its turn the exploiter's final network plays N games against the main
    agent it trained against; they decide the join and are recorded, and replaying them from the checkpoints gives
    the same rate (seeded by the turn)."""
    league = with_overrides(quick, {**TINY, "selfplay.exploiter_join_games": 12, "selfplay.exploiter_join": 0.3})
    lines: list[str] = []
    SelfPlay(SelfPlayJob(league, tmp_path, "lg", seed=0, progress=False), report=lines.append).run()
    run = tmp_path / "lg"
    turns, pools = state(run)["turns"], state(run)["pools"]
    exploiters = [t for t in turns if t["learner"] == "exploiter"]
    assert len(exploiters) == 4 and all(t["join_rate"] is not None for t in exploiters)
    assert all(t["join_rate"] is None and t["joined_by"] == "" for t in turns if t["learner"] == "main")
    for t in exploiters:
        assert t["joined"] == (t["join_rate"] >= 0.3) and t["joined_by"] == ("win" if t["joined"] else "")
        assert any(e["spec"] == t["checkpoint"] for e in pools[t["role"]]["entries"]) == t["joined"]
        role = t["role"]
        me = resolve_policy(str(run / t["checkpoint"]), role, league)
        target = read_metadata(run / t["checkpoint"]).opponents[0]["spec"]  # the main agent it trained against
        them = resolve_policy(str(run / target), opponent_of(role), league)
        players = (me, them) if role == "pursuer" else (them, me)
        result, _ = play_match(
            league, *players, episodes=12, seed=selfplay_module.turn_seed(0, t["round"], role, "exploiter") + 1
        )
        won = result.capture_rate if role == "pursuer" else 1 - result.capture_rate
        assert won == pytest.approx(t["join_rate"], abs=1e-4)

    def by_record(t: dict) -> bool:  # what the turn's own games would have decided
        rate = t["captures"] / t["episodes"] if t["episodes"] else float("nan")
        return (rate if t["role"] == "pursuer" else 1 - rate) >= 0.3

    assert any(t["joined"] != by_record(t) for t in exploiters)  # with this seed: the join games overrule the record
    assert sum(" in its join games" in line for line in lines) == 2


def test_a_stop_after_an_exploiter_joined_starts_it_afresh(quick: Scenario, tmp_path: Path, monkeypatch) -> None:
    built: dict[str, int] = {}
    original = schedules_module.Learner

    class Stopping(original):
        def __init__(self, job, role, *args, kind=selfplay_module.MAIN, **kwargs) -> None:
            if kind == selfplay_module.EXPLOITER:
                built[role] = built.get(role, 0) + 1
                if built[role] == 2:  # a side's second exploiter: the fresh one after the first joined the pool
                    raise KeyboardInterrupt
            super().__init__(job, role, *args, kind=kind, **kwargs)

    monkeypatch.setattr(schedules_module, "Learner", Stopping)
    with pytest.raises(SelfPlayInterrupted):
        SelfPlay(job(quick, tmp_path)).run()
    monkeypatch.undo()
    run = tmp_path / "lg"
    joined = [t for t in state(run)["turns"] if t["joined"]]
    assert len(joined) == 1  # committed, but its learner was not yet replaced
    resumed = job(quick, tmp_path)
    resumed.resume = True
    SelfPlay(resumed).run()
    role = joined[0]["role"]
    again = read_metadata(run / f"exploiter-{role}" / "round-002.zip")
    assert again.parent == "" and again.steps == 240
    assert len(state(run)["turns"]) == 8
    assert np.all([t["steps"] > 0 for t in state(run)["turns"]])


def test_nash_weights_are_the_mixture_around_the_league_floor() -> None:
    pool = OpponentPool("evader")
    for name in ("greedy", "hider"):
        pool.add(name, name, generation=0)
    pool.add("evader-r001", "evader/round-001.zip", generation=1)
    nash = pool.weights("nash", floor=0.2, nash={"evader-r001": 1.0})
    assert nash == pytest.approx([0.1, 0.1, 0.8])  # the floor to the scripted players, the rest to the mixture
    assert pool.weights("nash", floor=0.0, nash={"hider": 0.25, "evader-r001": 0.75}) == pytest.approx([0, 0.25, 0.75])
    assert pool.weights("nash", floor=0.0, nash={}) == pytest.approx([1 / 3] * 3)  # no mixture yet: uniform


def test_nash_opponents_play_the_meta_game_and_draw_its_mixture(quick: Scenario, tmp_path: Path) -> None:
    nash = with_overrides(
        quick,
        {
            **TINY,
            "selfplay.opponents": "nash",
            "selfplay.nash_games": 8,
            "selfplay.league_exploiter_every": 0,
            "selfplay.league_floor": 0.0,
        },
    )
    SelfPlay(SelfPlayJob(nash, tmp_path, "ps", seed=0, progress=False), report=lambda line: None).run()
    run = tmp_path / "ps"
    record = state(run)
    pursuers = [e["name"] for e in record["pools"]["pursuer"]["entries"]]
    evaders = [e["name"] for e in record["pools"]["evader"]["entries"]]
    assert "evader-r001" in evaders and "pursuer-r002" in pursuers
    played = set(record["payoffs"])
    assert {f"{p}|{e}" for p in pursuers[:-1] for e in evaders[:-1]} <= played  # every pairing before the last round's
    assert all(games == 8 and 0 <= captures <= 8 for captures, games in record["payoffs"].values())
    # round 2's pursuer drew its evaders by the Nash mixture of the meta-game as it stood then
    from pecli.metagame import solve

    before = [e for e in evaders if e != "evader-r002"]
    names = [p for p in pursuers if p != "pursuer-r002"]
    matrix = np.array([[record["payoffs"][f"{p}|{e}"][0] / 8 for e in before] for p in names])
    mixture = solve(names, before, matrix).support("evader")
    weights = {o["name"]: o["weight"] for o in read_metadata(run / "pursuer" / "round-002.zip").opponents}
    assert weights == pytest.approx({e: mixture.get(e, 0.0) for e in before}, abs=1e-3)
