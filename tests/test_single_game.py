"""SingleGame (plain floats, one game) must play exactly like Game(n=1, auto_reset=False).

Both are driven with the same actions and compared step by step: observations (float32, up to
rounding), rewards, flags, step counts, distances, sensor verdicts and SI states. The only
tolerated differences are rounding: math.cos/sin/tan against NumPy's, and float32 scaling order
in the own-frame observation block.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from pecli.game.game import Game, StepResult
from pecli.game.single import SingleGame, SingleStep
from pecli.roles import ROLES
from pecli.scenario import CarAgent, Scenario, builtin_config_dir, load_scenario

CONFIGS = sorted(path.stem for path in builtin_config_dir().glob("*.yaml"))
FRAMES = ("own", "world")
OBS_ATOL = 1e-5
STATE_ATOL = 1e-9
REWARD_RTOL = 1e-9

Record = dict[str, np.ndarray | float | bool | int]


def _scenario(name: str, frame: str = "own") -> Scenario:
    return load_scenario(name).model_copy(update={"observation_frame": frame})


def _pair(scenario: Scenario, seed: int) -> tuple[Game, SingleGame]:
    return Game(scenario, n=1, seed=seed, auto_reset=False), SingleGame(scenario, seed=seed)


def _actions(rng: np.random.Generator, steps: int) -> np.ndarray:
    """``(steps, 2, 2)`` actions (pursuer, evader) held for random runs of steps: uniform in [-1, 1],
    limit-hugging +-1, far outside [-1, 1] (clipped by the games), and jittery slightly outside."""
    out = np.empty((steps + 32, 2, 2))
    i = 0
    while i < steps:
        run = int(rng.integers(1, 32))
        kind = int(rng.integers(4))
        if kind == 0:
            out[i : i + run] = rng.uniform(-1.0, 1.0, (2, 2))
        elif kind == 1:
            out[i : i + run] = rng.choice([-1.0, 1.0], (2, 2))
        elif kind == 2:
            out[i : i + run] = rng.uniform(-3.0, 3.0, (2, 2))
        else:
            out[i : i + run] = rng.uniform(-1.2, 1.2, (run, 2, 2))
        i += run
    return out[:steps]


# ---------------------------------------------------------------------- records and comparison
def _observed(obs: dict, state: np.ndarray, normalised: np.ndarray) -> Record:
    return {
        "obs_pursuer": obs["pursuer"],
        "obs_evader": obs["evader"],
        "state": state,
        "normalised_state": normalised,
    }


def _ref_reset(game: Game, obs: dict) -> Record:
    return _observed({role: obs[role][0] for role in ROLES}, game.state()[0], game.normalised_state()[0])


def _single_reset(game: SingleGame, obs: dict) -> Record:
    return _observed(obs, game.state(), game.normalised_state())


def _ref_step(game: Game, result: StepResult) -> Record:
    record = _ref_reset(game, result.obs)
    record.update(
        reward_pursuer=result.rewards["pursuer"][0],
        reward_evader=result.rewards["evader"][0],
        captured=bool(result.captured[0]),
        timed_out=bool(result.timed_out[0]),
        done=bool(result.done[0]),
        steps=int(result.steps[0]),
        distance=result.distance[0],
        seen_pursuer=bool(result.seen["pursuer"][0]),
        seen_evader=bool(result.seen["evader"][0]),
        t=int(game.t[0]),
        finished=bool(game.finished[0]),
    )
    return record


def _single_step(game: SingleGame, result: SingleStep) -> Record:
    for role in ROLES:
        obs = result.obs[role]
        assert obs.shape == (game.obs_dim[role],) and obs.dtype == np.float32
        assert type(result.rewards[role]) is float and type(result.seen[role]) is bool
    assert type(result.captured) is bool and type(result.done) is bool and type(result.steps) is int
    record = _single_reset(game, result.obs)
    record.update(
        reward_pursuer=result.rewards["pursuer"],
        reward_evader=result.rewards["evader"],
        captured=result.captured,
        timed_out=result.timed_out,
        done=result.done,
        steps=result.steps,
        distance=result.distance,
        seen_pursuer=result.seen["pursuer"],
        seen_evader=result.seen["evader"],
        t=game.t,
        finished=game.finished,
    )
    return record


def _compare(ref: list[Record], single: list[Record], label: str) -> None:
    """Compare two traces record by record, each quantity over the whole trace at once."""
    assert len(ref) == len(single)
    assert [record.keys() for record in ref] == [record.keys() for record in single]
    for key in dict.fromkeys(key for record in ref for key in record):
        rows = [i for i, record in enumerate(ref) if key in record]
        expected = np.array([ref[i][key] for i in rows])
        actual = np.array([single[i][key] for i in rows])
        msg = f"{label}: {key}"
        if key.startswith("obs") or key == "normalised_state":
            np.testing.assert_allclose(actual, expected, rtol=0, atol=OBS_ATOL, err_msg=msg)
        elif key.startswith("reward"):
            np.testing.assert_allclose(actual, expected, rtol=REWARD_RTOL, atol=0, err_msg=msg)
        elif key in ("state", "distance"):
            np.testing.assert_allclose(actual, expected, rtol=0, atol=STATE_ATOL, err_msg=msg)
        else:
            np.testing.assert_array_equal(actual, expected, err_msg=msg)
    for i, record in enumerate(single):  # zero-sum
        if "reward_pursuer" in record:
            assert record["reward_evader"] == -record["reward_pursuer"], (label, i)


Hook = Callable[[int, Game, SingleGame], None]


def _rollout(
    ref: Game,
    single: SingleGame,
    actions: np.ndarray,
    *,
    label: str,
    reset_when_done: bool = True,
    hook: Hook | None = None,
) -> list[Record]:
    """Step both games with the same actions, reset both when done; compare the traces; return Game's."""
    ref_trace = [_ref_reset(ref, ref.observe())]
    single_trace = [_single_reset(single, single.observe())]
    for i, (pursuer_action, evader_action) in enumerate(actions):
        if hook is not None:
            hook(i, ref, single)
        ref_result = ref.step(pursuer_action[None], evader_action[None])
        single_result = single.step(pursuer_action, evader_action)
        ref_trace.append(_ref_step(ref, ref_result))
        single_trace.append(_single_step(single, single_result))
        if reset_when_done and (ref_result.done[0] or single_result.done):
            ref_trace.append(_ref_reset(ref, ref.reset()))
            single_trace.append(_single_reset(single, single.reset()))
    _compare(ref_trace, single_trace, label)
    return ref_trace


def _count(trace: list[Record], key: str) -> int:
    return sum(bool(record.get(key, False)) for record in trace)


# ---------------------------------------------------------------------- random rollouts
@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("name", CONFIGS)
def test_random_rollout_matches_game(name: str, frame: str) -> None:
    scenario = _scenario(name, frame)
    ref, single = _pair(scenario, seed=17)
    assert single.obs_dim == ref.obs_dim and single.state_dim == ref.state_dim
    assert single.fov == ref.fov and single.speed_scale == ref.speed_scale
    rng = np.random.default_rng(CONFIGS.index(name) * 10 + FRAMES.index(frame))
    steps = max(600, 2 * scenario.horizon + 100)  # several episodes, at least two of them timeouts or captures
    trace = _rollout(ref, single, _actions(rng, steps), label=f"{name}/{frame}")
    assert _count(trace, "done") >= 2


@pytest.mark.parametrize("frame", FRAMES)
def test_variant_scenario_matches_game(frame: str) -> None:
    """What no built-in config exercises: acceleration capped above v_switch, other reward
    coefficients, another dt, horizon and capture radius."""
    base = _scenario("car_vs_car", frame)
    scenario = base.model_copy(
        update={
            "dt": 0.05,
            "horizon": 90,
            "capture_radius": 0.4,
            "reward": base.reward.model_copy(update={"capture": 250.0, "time": 0.3, "distance": 0.7}),
            "pursuer": base.pursuer.model_copy(update={"v_switch": 0.8}),
            "evader": base.evader.model_copy(update={"v_switch": 1.2}),
        }
    )
    ref, single = _pair(scenario, seed=5)
    trace = _rollout(ref, single, _actions(np.random.default_rng(99), 500), label=f"variant/{frame}")
    assert _count(trace, "done") >= 4


def test_start_states_and_seeds_match_game() -> None:
    """A new seed restarts the episode counter; a plain reset continues it (as in Game)."""
    for name in CONFIGS:
        ref, single = _pair(_scenario(name), seed=123)
        np.testing.assert_array_equal(single.state(), ref.state()[0])  # the constructor's episode 0
        for seed in (None, None, 7, None, 123, None, 2**63 + 5):
            ref_obs, single_obs = ref.reset(seed=seed), single.reset(seed=seed)
            assert single.seed == ref.seed and single.episode == ref.episode[0]
            np.testing.assert_allclose(single.state(), ref.state()[0], rtol=0, atol=STATE_ATOL, err_msg=name)
            for role in ROLES:
                np.testing.assert_allclose(single_obs[role], ref_obs[role][0], rtol=0, atol=OBS_ATOL, err_msg=name)
            assert single.t == 0 and not single.finished


# ---------------------------------------------------------------------- chosen states
def _player_state(agent, x: float, y: float, speed: float = 0.0, heading: float = 0.0, steer: float = 0.0) -> list:
    """An SI state of one player: a car's ``(x, y, delta, v, psi)`` or a point mass's ``(x, y, vx, vy)``."""
    if isinstance(agent, CarAgent):
        return [x, y, steer, speed, heading]
    return [x, y, speed * math.cos(heading), speed * math.sin(heading)]


def _both(pursuer: list, evader: list) -> np.ndarray:
    return np.array(pursuer + evader, dtype=np.float64)


def _set_both(ref: Game, single: SingleGame, state: np.ndarray, t: int = 0) -> None:
    ref_obs = ref.set_state(state[None], t=t)
    single_obs = single.set_state(state, t=t)
    for role in ROLES:
        np.testing.assert_allclose(single_obs[role], ref_obs[role][0], rtol=0, atol=OBS_ATOL)


def _wall_states(scenario: Scenario) -> list[np.ndarray]:
    """Both players just inside walls and corners, at full speed towards them (forwards and in reverse)."""
    hx, hy = scenario.arena.half
    p, e = scenario.pursuer, scenario.evader
    vp, ve = p.v_max, e.v_max
    return [
        _both(_player_state(p, hx - 0.05, 0.3, vp, 0.0), _player_state(e, -hx + 0.05, -0.3, ve, math.pi)),
        _both(_player_state(p, 0.3, hy - 0.02, vp, math.pi / 2), _player_state(e, 1.0, -hy + 0.1, ve, -math.pi / 2)),
        _both(_player_state(p, hx - 0.1, hy - 0.1, vp, math.pi / 4, steer=0.2),
              _player_state(e, -hx + 0.1, -hy + 0.1, ve * math.sqrt(2), -3 * math.pi / 4)),
        # reversing into a wall (a car with v < 0), and a point mass exactly on the wall
        _both(_player_state(p, -hx + 0.05, 0.0, -1.0, 0.0), _player_state(e, hx, hy, ve, math.pi / 4)),
    ]  # fmt: skip


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("name", CONFIGS)
def test_near_walls_matches_game(name: str, frame: str) -> None:
    scenario = _scenario(name, frame)
    ref, single = _pair(scenario, seed=1)
    rng = np.random.default_rng(4)
    for k, state in enumerate(_wall_states(scenario)):
        _set_both(ref, single, state)
        towards = np.sign(np.concatenate([state[:2], state[ref.dynamics["pursuer"].state_dim :][:2]]))
        # first push into the walls at full throttle, then random actions
        pushes = np.tile(np.array([[towards[0], 1.0], [towards[2], towards[3]]]), (6, 1, 1))
        actions = np.concatenate([pushes, _actions(rng, 30)])
        _rollout(ref, single, actions, label=f"{name}/{frame}/wall {k}", reset_when_done=False)
        hx, hy = scenario.arena.half
        assert np.all(np.abs(single.state()[[0, 1]]) <= [hx, hy])


@pytest.mark.parametrize("name", CONFIGS)
def test_capture_distance_edges_match_game(name: str) -> None:
    """Players standing still exactly at, just inside and just outside the capture distance 2c."""
    scenario = _scenario(name)
    cd = scenario.capture_distance
    p, e = scenario.pursuer, scenario.evader
    still = np.zeros((1, 2, 2))
    for gap, expect_capture in ((cd, True), (cd - 1e-9, True), (cd + 1e-9, False), (cd + 1e-3, False)):
        ref, single = _pair(scenario, seed=2)
        _set_both(ref, single, _both(_player_state(p, 1.0, 0.5), _player_state(e, 1.0 + gap, 0.5)), t=3)
        trace = _rollout(ref, single, still, label=f"{name}/gap {gap!r}", reset_when_done=False)
        assert trace[-1]["captured"] is expect_capture
        assert trace[-1]["steps"] == 4
    # a capture on the horizon's last step is a capture, not a timeout
    ref, single = _pair(scenario, seed=2)
    _set_both(ref, single, _both(_player_state(p, 1.0, 0.5), _player_state(e, 1.0 + cd, 0.5)), t=scenario.horizon - 1)
    trace = _rollout(ref, single, still, label=f"{name}/last step", reset_when_done=False)
    assert trace[-1]["captured"] and not trace[-1]["timed_out"] and trace[-1]["steps"] == scenario.horizon
    # closing in head-on at speed, full throttle: the capture happens on some step of the approach
    ref, single = _pair(scenario, seed=2)
    _set_both(ref, single, _both(_player_state(p, -2.0, 0.2, 1.0, 0.0), _player_state(e, 0.0, 0.2, 1.0, math.pi)))
    pursuer_action = [0.0, 1.0] if isinstance(p, CarAgent) else [1.0, 0.0]
    evader_action = [0.0, 1.0] if isinstance(e, CarAgent) else [-1.0, 0.0]
    actions = np.tile([pursuer_action, evader_action], (40, 1, 1))
    trace = _rollout(ref, single, actions, label=f"{name}/approach", reset_when_done=False)
    assert _count(trace, "captured") == 1


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("name", CONFIGS)
def test_sensor_edges_match_game(name: str, frame: str) -> None:
    """Targets just inside / outside the sensing range and the edges of the FOV wedge."""
    scenario = _scenario(name, frame)
    p, e = scenario.pursuer, scenario.evader
    sensing_range = p.sensor.range
    ref, single = _pair(scenario, seed=3)
    for fov_evader in (None, 1.3):  # None: the config's; 1.3 rad also narrows a car evader's wedge
        if fov_evader is not None:
            ref.fov["evader"] = single.fov["evader"] = fov_evader
        half = 0.5 * ref.fov["pursuer"]
        for psi in (0.0, 0.7, -2.9, math.pi / 2):
            for bearing, distance in (
                (half - 1e-6, 2.0), (half + 1e-6, 2.0), (-half + 1e-6, 2.0), (-half - 1e-6, 2.0),
                (0.0, sensing_range), (0.0, sensing_range * (1 + 1e-9)), (0.0, sensing_range - 1e-9), (math.pi, 1.0),
            ):  # fmt: skip
                angle = psi + bearing
                x, y = -0.5 * distance * math.cos(angle), -0.5 * distance * math.sin(angle)
                state = _both(
                    _player_state(p, x, y, 0.0, psi),
                    _player_state(e, x + distance * math.cos(angle), y + distance * math.sin(angle), 0.0, angle + 2.5),
                )
                _set_both(ref, single, state)
                trace = _rollout(ref, single, np.zeros((2, 2, 2)), label=f"{name}/{frame}/{psi}/{bearing}")
                assert trace[-1]["done"] is False
    # edges where both sides do exact arithmetic (psi = 0, both still, pursuer near the left wall)
    ref.fov["pursuer"] = single.fov["pursuer"] = math.pi / 2
    x0 = 1.5 - scenario.arena.half[0]
    is_car = isinstance(p, CarAgent)
    for dx, dy, expected in (
        (sensing_range, 0.0, True),
        (sensing_range * (1 + 1e-9), 0.0, False),
        (1.0, 1.0 - 1e-6, True),
        (1.0, 1.0 + 1e-6, not is_car),  # outside a car's 90 degree wedge; a point mass sees a disk
        (-1.0, 0.0, not is_car),
    ):
        _set_both(ref, single, _both(_player_state(p, x0, 0.0), _player_state(e, x0 + dx, dy)))
        label = f"{name}/{frame}/exact {dx}, {dy}"
        trace = _rollout(ref, single, np.zeros((1, 2, 2)), label=label, reset_when_done=False)
        assert trace[1]["seen_pursuer"] is expected and not trace[1]["done"], (dx, dy)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("name", CONFIGS)
def test_states_beyond_limits_match_game(name: str, frame: str) -> None:
    """set_state does not check limits: speeds far beyond them (the own-frame block is clipped to
    [-1, 1], the world-frame one is not) and steering beyond its limits are pulled back alike."""
    scenario = _scenario(name, frame)
    p, e = scenario.pursuer, scenario.evader
    ref, single = _pair(scenario, seed=9)
    for speed, steer in ((3.0, 0.9), (-4.0, -0.9)):
        state = _both(
            _player_state(p, -1.0, 0.0, speed * p.v_max, 0.0, steer=steer),
            _player_state(e, 1.0, 0.3, speed * e.v_max, math.pi - 0.2, steer=-steer),
        )
        _set_both(ref, single, state)
        _rollout(ref, single, _actions(np.random.default_rng(1), 5), label=f"{name}/{frame}/speed {speed}")
    if frame == "own":  # the clip matters here: Game's observation holds +-1 where the block is clipped
        _set_both(ref, single, state)
        assert np.any(np.abs(ref.observe()["pursuer"][0, ref.dynamics["pursuer"].state_dim :]) == 1.0)


# ---------------------------------------------------------------------- curriculum knobs
@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("name", CONFIGS)
def test_curriculum_knobs_match_game(name: str, frame: str) -> None:
    """fov and speed_scale are read at every step; turn them during a rollout on both games."""
    scenario = _scenario(name, frame)
    ref, single = _pair(scenario, seed=8)
    schedule = {
        40: {("fov", "pursuer"): math.pi / 3, ("speed_scale", "evader"): 0.5},
        90: {("speed_scale", "evader"): 1.5, ("speed_scale", "pursuer"): 0.3},
        140: {("fov", "pursuer"): 2 * math.pi, ("speed_scale", "evader"): 0.2},
        200: {("fov", "pursuer"): 0.4, ("fov", "evader"): 1.0, ("speed_scale", "pursuer"): 1.0},
        260: {("speed_scale", "pursuer"): 2.0, ("speed_scale", "evader"): 2.0},
    }

    def turn_knobs(i: int, ref: Game, single: SingleGame) -> None:
        for (knob, role), value in schedule.get(i, {}).items():
            getattr(ref, knob)[role] = value
            getattr(single, knob)[role] = value

    _rollout(ref, single, _actions(np.random.default_rng(3), 360), label=f"{name}/{frame}/knobs", hook=turn_knobs)
    assert single.fov == ref.fov and single.speed_scale == ref.speed_scale


# ---------------------------------------------------------------------- after the end
@pytest.mark.parametrize("name", CONFIGS)
def test_finished_game_freezes_like_game(name: str) -> None:
    scenario = _scenario(name)
    p, e = scenario.pursuer, scenario.evader
    rng = np.random.default_rng(6)
    ref, single = _pair(scenario, seed=4)
    ends = (
        ("capture", _both(_player_state(p, 0.0, 0.0, 0.5), _player_state(e, 0.3, 0.0, 0.5)), 0),
        ("timeout", _both(_player_state(p, -3.0, 0.0, 0.5), _player_state(e, 3.0, 0.0, 0.5)), scenario.horizon - 1),
    )  # fmt: skip
    for kind, state, t in ends:
        _set_both(ref, single, state, t=t)
        trace = _rollout(ref, single, _actions(rng, 8), label=f"{name}/{kind}", reset_when_done=False)
        first, frozen = trace[1], trace[2:]
        assert first["captured" if kind == "capture" else "timed_out"] and first["done"]
        for record in frozen:
            assert not (record["captured"] or record["timed_out"] or record["done"])
            assert record["reward_pursuer"] == 0.0 and record["steps"] == first["steps"] and record["finished"]
            np.testing.assert_array_equal(record["state"], first["state"])
        # a reset ends the freeze and continues the episode counter
        _compare([_ref_reset(ref, ref.reset())], [_single_reset(single, single.reset())], f"{name}/{kind}/reset")
        assert not single.finished and single.episode == ref.episode[0]


def test_bad_inputs_are_rejected() -> None:
    single = SingleGame(_scenario("paper"), seed=0)
    with pytest.raises(ValueError):
        single.step([0.0, 0.0, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError):
        single.step(np.zeros((2, 2)), [0.0, 0.0])
    with pytest.raises(ValueError):
        single.set_state(np.zeros(single.state_dim + 1))
    single.step(np.zeros((2,), dtype=np.float32), (0, 1))  # any length-2 numbers are fine
