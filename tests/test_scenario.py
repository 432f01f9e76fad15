"""Scenario files: the built-ins load, and mistakes are refused with one line naming key and file."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from pecli.errors import ConfigError
from pecli.scenario import builtin_config_dir, load_scenario, parse_angle

from conftest import BUILTINS


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
        node = node[key]
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
