"""Scenario files: the built-ins load, and mistakes are refused with one line naming key and file."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
import yaml
from conftest import BUILTINS

from pecli.errors import ConfigError
from pecli.scenario import builtin_config_dir, load_scenario, parse_angle, read_yaml


@pytest.mark.parametrize("name", BUILTINS)
def test_builtins_load_by_name_and_path(name: str) -> None:
    by_name = load_scenario(name)
    by_path = load_scenario(builtin_config_dir() / f"{name}.yaml")
    assert by_name == by_path and by_name.name == name


def test_paper_values(paper) -> None:
    assert (paper.arena.width, paper.arena.height, paper.dt, paper.horizon) == (16.0, 16.0, 0.1, 400)
    assert paper.capture_distance == 0.5
    assert paper.pursuer.kind == "car" and paper.evader.kind == "point_mass"
    assert paper.pursuer.sensor.fov == pytest.approx(2 * math.pi / 3)
    assert (paper.pursuer.v_min, paper.pursuer.v_max, paper.pursuer.a_max) == (-1.0, 2.5, 2.0)
    assert (paper.evader.v_max, paper.evader.a_max) == (1.5, 9.81)
    assert paper.observation_frame == "own"


def test_point_mass_and_robot_scenarios() -> None:
    pm = load_scenario("point_mass")
    assert (pm.arena.width, pm.horizon, pm.pursuer.sensor.range, pm.evader.v_max) == (10.0, 100, 3.75, 2.5)
    robots = load_scenario("robots")
    assert (robots.arena.width, robots.arena.height) == (10.0, 5.5)
    assert robots.pursuer.sensor.fov == pytest.approx(1.5 * math.pi) and robots.pursuer.sensor.range == 5.0
    assert robots.pursuer.lf == 0.15875 and robots.pursuer.lr == 0.17145


@pytest.mark.parametrize(
    ("text", "radians"),
    [("pi", math.pi), ("2pi/3", 2 * math.pi / 3), ("1.5*pi", 1.5 * math.pi), ("120deg", 2 * math.pi / 3), (1.0, 1.0)],
)
def test_angles(text, radians) -> None:
    assert parse_angle(text) == pytest.approx(radians)


def write(tmp_path: Path, data) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def paper_dict() -> dict:
    return yaml.safe_load((builtin_config_dir() / "paper.yaml").read_text())


def mutate(path: str, value) -> dict:
    data = paper_dict()
    keys = path.split(".")
    node = data
    for key in keys[:-1]:
        node = node.setdefault(key, {})
    node[keys[-1]] = value
    return data


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("pursuer.sensor.range", -1.0, r"pursuer\.sensor\.range: .*greater than 0"),
        ("pursuer.sensor.fov", 7.0, r"pursuer\.sensor\.fov: FOV must be in \(0, 2pi\]"),
        ("pursuer.sensor.fov", "sideways", r"pursuer\.sensor\.fov: cannot read 'sideways' as an angle"),
        ("pursuer.steer_min", 0.5, r"pursuer: steer_min \(0\.5\) must be below steer_max"),
        ("horizon", "long", r"horizon: .*integer"),
        ("arena.width", 0.4, r"must be larger than twice the capture distance"),
        ("evader.sensor.fov", 1.0, r"evader\.sensor: a point mass has no heading"),
        ("evader.kind", "boat", r"evader: .*(tag|kind)"),
        ("dt", 0, r"dt: .*greater than 0"),
    ],
)
def test_impossible_values_are_refused(tmp_path: Path, key: str, value, expected: str) -> None:
    path = write(tmp_path, mutate(key, value))
    with pytest.raises(ConfigError, match=expected) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(str(path)) and "\n" not in message


def test_unknown_key_is_named(tmp_path: Path) -> None:
    data = paper_dict()
    data["pursuer"]["wheelbase"] = 0.3
    with pytest.raises(ConfigError, match=r"bad\.yaml: pursuer\.wheelbase: unknown key"):
        load_scenario(write(tmp_path, data))


def test_missing_key_is_named(tmp_path: Path) -> None:
    data = paper_dict()
    del data["arena"]
    with pytest.raises(ConfigError, match=r"arena: missing required key"):
        load_scenario(write(tmp_path, data))


def test_broken_yaml_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"bad\.yaml: line \d+"):
        load_scenario(write(tmp_path, "arena: {width: 16\npursuer: ["))
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_scenario(write(tmp_path, "- just\n- a list\n"))
    with pytest.raises(ConfigError, match="config not found: nowhere.yaml"):
        load_scenario("nowhere.yaml")


def test_yaml_is_loaded_safely(tmp_path: Path) -> None:
    path = write(tmp_path, "!!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(ConfigError):
        load_scenario(path)


def test_fingerprint_tracks_the_game_not_the_name(paper) -> None:
    renamed = paper.model_copy(update={"name": "other", "description": "x"})
    assert renamed.fingerprint() == paper.fingerprint()
    slower = paper.model_copy(update={"evader": paper.evader.model_copy(update={"v_max": 1.0})})
    assert slower.fingerprint() != paper.fingerprint()


def test_with_sensor_range_widens_the_chosen_sensors(paper) -> None:
    seeing = paper.with_sensor_range(30.0, ("evader",))
    assert seeing.evader.sensor.range == 30.0 and seeing.evader.sensor.fov == paper.evader.sensor.fov
    assert seeing.pursuer == paper.pursuer and paper.evader.sensor.range != 30.0
    both = paper.with_sensor_range(30.0)
    assert both.pursuer.sensor.range == both.evader.sensor.range == 30.0
    assert both.fingerprint() != paper.fingerprint()
    with pytest.raises(ValueError, match="sensor range"):
        paper.with_sensor_range(0.0)


# -- strict configs: finite numbers, no duplicate keys, no bool/number mix-ups, plausible sizes ----------


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("pursuer.v_min", math.nan, r"pursuer\.v_min: must be a finite number \(got nan\)"),
        ("dt", math.inf, r"dt: must be a finite number \(got inf\)"),
        ("pursuer.v_max", math.inf, r"pursuer\.v_max: must be a finite number"),
        ("arena.width", math.inf, r"arena\.width: must be a finite number"),
        ("reward.capture", math.inf, r"reward\.capture: must be a finite number"),
        ("pursuer.sensor.fov", -math.inf, r"pursuer\.sensor\.fov: must be a finite number"),
        ("training.learning_rate", math.nan, r"training\.learning_rate: must be a finite number"),
        ("training.belief_settings.learning_rate", math.inf, r"belief_settings\.learning_rate: must be a finite"),
        ("horizon", True, r"horizon: a number is expected here, not the boolean true"),
        ("dt", False, r"dt: a number is expected here, not the boolean false"),
        ("training.net_arch", [128, True], r"training\.net_arch\.1: a number is expected here"),
        ("training.curriculum.enabled", 1, r"training\.curriculum\.enabled: true or false is expected here \(got 1\)"),
        ("training.steps", 10**40, r"training\.steps: .*less than or equal to"),
        ("horizon", 10**9, r"horizon: .*less than or equal to"),
        ("training.net_arch", [10**12], r"training\.net_arch\.0: .*less than or equal to"),
        ("training.net_arch", [64] * 100, r"training\.net_arch: .*at most 32"),
        ("training.steps", 2.5, r"training\.steps: .*valid integer \(got 2\.5\)"),
    ],
)
def test_non_finite_boolean_and_absurd_values_are_refused(tmp_path: Path, key: str, value, expected: str) -> None:
    path = write(tmp_path, mutate(key, value))
    with pytest.raises(ConfigError, match=expected) as info:
        load_scenario(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_yaml_spellings_of_numbers_are_read(tmp_path: Path) -> None:
    """YAML 1.1 reads ``1e-4`` and ``1e5`` as strings: they are numbers all the same, and ``1.0e+5`` is a count."""
    text = (builtin_config_dir() / "quick.yaml").read_text()
    text = text.replace("steps: 100000", "steps: 1e5\n  learning_rate: 1e-4\n  n_envs: 1.6e+1")
    scenario = load_scenario(write(tmp_path, text))
    assert (scenario.training.steps, scenario.training.learning_rate, scenario.training.n_envs) == (100_000, 1e-4, 16)
    assert isinstance(scenario.training.steps, int)


def test_duplicate_keys_are_refused_with_their_lines(tmp_path: Path) -> None:
    text = (builtin_config_dir() / "quick.yaml").read_text().replace("horizon: 150", "horizon: 150\nhorizon: 400")
    with pytest.raises(ConfigError, match=r"bad\.yaml: line 7: duplicate key 'horizon' \(first given on line 6\)"):
        load_scenario(write(tmp_path, text))
    nested = (builtin_config_dir() / "quick.yaml").read_text().replace("range: 6.0, fov", "range: 6.0, range: 7.0, fov")
    with pytest.raises(ConfigError, match=r"duplicate key 'range'"):
        load_scenario(write(tmp_path, nested))


def test_aliases_that_expand_past_any_config_and_files_that_never_end_are_refused(tmp_path: Path) -> None:
    """A page of nested aliases stands for billions of values, a link to /dev/zero or a FIFO for a file that never
    ends or never opens: each is refused in one line, before anything walks it."""
    lines = ["d0: &d0 {a: 1, b: 2}"]
    lines += [f"d{i}: &d{i} {{" + ", ".join(f"k{j}: *d{i - 1}" for j in range(8)) + "}" for i in range(1, 12)]
    with pytest.raises(ConfigError, match="more than 100,000 values once its aliases are expanded"):
        load_scenario(write(tmp_path, "\n".join(lines)))
    with pytest.raises(ConfigError, match="an alias that contains itself"):
        load_scenario(write(tmp_path, "a: &a [1, *a]\n"))
    endless = tmp_path / "endless.yaml"
    endless.symlink_to("/dev/zero")
    with pytest.raises(ConfigError, match="endless.yaml: not a regular file"):
        read_yaml(endless)
    blocking = tmp_path / "blocking.yaml"
    os.mkfifo(blocking)
    with pytest.raises(ConfigError, match="blocking.yaml: not a regular file"):
        read_yaml(blocking)
    big = tmp_path / "big.yaml"
    big.write_text("x: 1\n" + "#" * (1 << 20))
    with pytest.raises(ConfigError, match="more bytes than a configuration file can be"):
        read_yaml(big)


def test_merge_keys_may_override(tmp_path: Path) -> None:
    """YAML's ``<<: *anchor`` merge is not a duplicate: the mapping's own key overrides the merged one."""
    text = (builtin_config_dir() / "quick.yaml").read_text()
    text = text.replace(
        "evader:\n  kind: point_mass", "evader:\n  <<: &pm {kind: point_mass, v_max: 9.0}\n  kind: point_mass"
    )
    assert load_scenario(write(tmp_path, text)).evader.v_max == 1.5


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        (
            "training.n_envs",
            100_000_000,
            r"training\.n_envs: 100000000 games need ~[\d,]+ GiB; one process steps at most",
        ),
        (
            "training.net_arch",
            [60_000, 60_000, 60_000],
            r"training\.net_arch: \[60000, 60000, 60000\] need ~[\d,]+ GiB",
        ),
        ("training.buffer_size", 100_000_000, r"training\.buffer_size: 100000000 transitions need ~[\d,]+ GiB .*limit"),
    ],
)
def test_sizes_that_need_too_much_memory_are_refused_with_the_estimate(tmp_path: Path, key, value, expected) -> None:
    data = mutate(key, value)
    data["training"]["belief"] = "bimdn"
    with pytest.raises(ConfigError, match=expected):
        load_scenario(write(tmp_path, data))


@pytest.mark.parametrize("name", BUILTINS)
def test_builtins_fit_the_memory_limit(name: str) -> None:
    from pecli.scenario import MEMORY_LIMIT, memory_estimate

    scenario = load_scenario(name)
    for belief in ("none", "bimdn-mixed"):
        training = scenario.training.model_copy(update={"belief": belief})
        assert 0 < sum(memory_estimate(scenario.model_copy(update={"training": training})).values()) < MEMORY_LIMIT / 16


def test_set_overrides_are_validated_as_strictly_as_files(quick) -> None:
    from pecli.rl.train import parse_overrides, with_overrides

    for item, expected in (
        ("learning_rate=.inf", r"--set: training\.learning_rate: must be a finite number"),
        ("learning_rate=nan", "must be a finite number"),
        ("n_envs=true", "not the boolean true"),
        ("curriculum.enabled=1", "true or false is expected"),
        ("n_envs=100000000", "games need"),
    ):
        with pytest.raises(ConfigError, match=expected):
            with_overrides(quick, parse_overrides([item]))
    assert with_overrides(quick, parse_overrides(["learning_rate=1e-4", "steps=2e4"])).training.steps == 20_000


def test_a_file_saved_beside_the_builtins_never_becomes_one(tmp_path, monkeypatch) -> None:
    import shutil

    from pecli import scenario as module
    from pecli.errors import ConfigError

    configs = tmp_path / "configs"
    shutil.copytree(module.builtin_config_dir(), configs)
    (configs / "mine.yaml").write_text((configs / "quick.yaml").read_text().replace("name: quick", "name: mine"))
    (configs / "experiments" / "mine.yaml").write_text((configs / "experiments" / "smoke.yaml").read_text())
    monkeypatch.setattr(module, "builtin_config_dir", lambda: configs)
    assert "mine" not in module.builtin_names() and "quick" in module.builtin_names()
    assert "mine" not in module.builtin_experiments() and "smoke" in module.builtin_experiments()
    with pytest.raises(ConfigError, match="config not found: mine"):
        module.load_scenario("mine")
    assert module.load_scenario(configs / "mine.yaml").name == "mine"  # as a file it loads
