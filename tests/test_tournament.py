"""Tournaments: discovery, pairings, determinism, paired starts, caching/resume, reports, CLI errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.errors import PecliError
from pecli.policies.mix import player_label
from pecli.process import descendants, live_parents
from pecli.scenario import Scenario
from pecli.tournament import (
    Player,
    find_players,
    pairing_results,
    player_spec,
    run_tournament,
    schedule,
)

runner = CliRunner()


def baselines(scenario: Scenario):
    return find_players([], scenario, baselines=True).players


def test_baselines_are_found_by_role(quick: Scenario) -> None:
    players = baselines(quick)
    assert [p.name for p in players["pursuer"]] == ["pure-pursuit"]
    assert [p.name for p in players["evader"]] == ["random-walk", "greedy", "rash"]


def test_pairing_results_by_spec_cached(quick: Scenario, tmp_path: Path) -> None:
    first = pairing_results(quick, ["pure-pursuit"], ["greedy", "rash"], 4, [0], tmp_path / "t")
    assert set(first) == {("pure-pursuit", "greedy"), ("pure-pursuit", "rash")}
    assert all(r.episodes == 4 and r.pursuer == "pure-pursuit" for r in first.values())
    cached: list[bool] = []
    again = pairing_results(
        quick, ["pure-pursuit"], ["greedy"], 4, [0], tmp_path / "t", on_result=lambda r, c: cached.append(c)
    )
    assert cached == [True] and again[("pure-pursuit", "greedy")] == first[("pure-pursuit", "greedy")]
    assert player_spec("runs/a/pursuer/final.zip") == str(Path("runs/a/pursuer/final.zip").resolve())
    assert player_spec("hj:model=rel4d") == "hj:model=rel4d"


def test_full_grid_and_sampled_pairings() -> None:
    def player(name: str, role: str) -> Player:
        return Player(name=name, spec=name, role=role, identity=f"file:{name}")

    players = {
        "pursuer": [player(f"p{i}", "pursuer") for i in range(5)],
        "evader": [player(f"e{i}", "evader") for i in range(6)],
    }
    assert len(schedule(players)) == 30
    sampled = schedule(players, sample=2, seed=1)
    assert sampled == schedule(players, sample=2, seed=1)  # seeded
    for p in players["pursuer"]:
        assert sum(pair[0] == p for pair in sampled) >= 2  # each meets at least its own 2 draws
    assert len(sampled) < 30


def test_deterministic_and_cached(quick: Scenario, tmp_path: Path) -> None:
    players = baselines(quick)
    pairings = schedule(players)
    first = run_tournament(quick, players, pairings, episodes=30, seeds=[0, 1], out=tmp_path / "a")
    second = run_tournament(quick, players, pairings, episodes=30, seeds=[0, 1], out=tmp_path / "b")
    assert [r.captures for r in first.pairings] == [r.captures for r in second.pairings]
    assert first.pairings[0].episodes == 60
    played: list[bool] = []
    third = run_tournament(
        quick,
        players,
        pairings,
        episodes=30,
        seeds=[0, 1],
        out=tmp_path / "a",
        on_result=lambda result, cached: played.append(cached),
    )
    assert played == [True, True, True]  # resume skips every done pairing
    assert [r.captures for r in third.pairings] == [r.captures for r in first.pairings]


def test_a_grown_tournament_plays_only_new_pairings(quick: Scenario, tmp_path: Path) -> None:
    players = baselines(quick)
    small = {"pursuer": players["pursuer"], "evader": players["evader"][:1]}
    run_tournament(quick, small, schedule(small), episodes=20, seeds=[0], out=tmp_path)
    cached: list[bool] = []
    run_tournament(
        quick,
        players,
        schedule(players),
        episodes=20,
        seeds=[0],
        out=tmp_path,
        on_result=lambda result, was_cached: cached.append(was_cached),
    )
    assert sorted(cached) == [False, False, True]


def test_bad_paths_and_empty_zoos(quick: Scenario, tmp_path: Path) -> None:
    with pytest.raises(PecliError, match="no such file or folder"):
        find_players([str(tmp_path / "missing")], quick)
    (tmp_path / "empty").mkdir()
    with pytest.raises(PecliError, match="no checkpoints under"):
        find_players([str(tmp_path / "empty")], quick)
    with pytest.raises(PecliError, match="no evader to play"):
        find_players(["pure-pursuit"], quick)


def test_cli_reports_and_resume(tmp_path: Path) -> None:
    out = tmp_path / "t"
    args = ["tournament", "--baselines", "-c", "quick", "-n", "20", "--seeds", "2", "--out", str(out), "-w", "1"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "greedy" in result.stdout and "ratings" in result.stdout
    for name in ("results.json", "results.csv", "capture_rates.png"):
        assert (out / name).is_file(), name
    data = json.loads((out / "results.json").read_text())
    assert len(data["pairings"]) == 3 and data["seeds"] == [0, 1] and data["episodes_per_seed"] == 20
    assert {r["name"] for r in data["ratings"]} == {"pure-pursuit", "random-walk", "greedy", "rash"}
    assert all(row["best_in_row"] for row in data["pairings"])  # one pursuer: best in every row
    again = runner.invoke(app, args)
    assert again.exit_code == 1 and "--resume" in again.output
    resumed = runner.invoke(app, [*args, "--resume", "--json"])
    assert resumed.exit_code == 0 and json.loads(resumed.stdout)["pairings"] == data["pairings"]


def test_cli_errors_are_one_line(tmp_path: Path) -> None:
    for args, message in (
        (["tournament"], "nothing to play"),
        (["tournament", str(tmp_path / "nope")], "no such file or folder"),
        (["tournament", "--baselines", "-n", "0"], "--episodes must be at least 1"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 1 and message in result.output and "Traceback" not in result.output


def test_only_players_with_games_are_rated(quick: Scenario, tmp_path: Path) -> None:
    from pecli.tournament import rate

    players = baselines(quick)
    subset = [(players["pursuer"][0], players["evader"][0])]
    results = run_tournament(quick, players, subset, episodes=20, seeds=[0], out=tmp_path)
    assert {r.name for r in results.ratings} == {"pure-pursuit", "random-walk"}
    assert rate(players, []) == []


def test_a_damaged_cache_entry_is_played_again(quick: Scenario, tmp_path: Path) -> None:
    players = baselines(quick)
    pairings = schedule(players)[:1]
    run_tournament(quick, players, pairings, episodes=10, seeds=[0], out=tmp_path)
    for entry in (tmp_path / "pairings").iterdir():
        entry.write_text("{truncated")
    cached: list[bool] = []
    run_tournament(
        quick,
        players,
        pairings,
        episodes=10,
        seeds=[0],
        out=tmp_path,
        on_result=lambda result, was_cached: cached.append(was_cached),
    )
    assert cached == [False]


def test_colliding_names_get_the_part_of_their_path_that_tells_them_apart() -> None:
    from pecli.tournament import _unique_names

    a = Player(name="ours/pursuer/final", spec="/z1/ours/pursuer/final.zip", role="pursuer", identity="1")
    b = Player(name="ours/pursuer/final", spec="/z2/ours/pursuer/final.zip", role="pursuer", identity="2")
    c = Player(name="other/pursuer/final", spec="/z2/other/pursuer/final.zip", role="pursuer", identity="3")
    names = [p.name for p in _unique_names([a, b, c])]
    assert names == ["z1/ours/pursuer/final", "z2/ours/pursuer/final", "other/pursuer/final"]


def test_sampling_without_checkpoints_is_refused(quick: Scenario) -> None:
    with pytest.raises(PecliError, match="--sample draws opponents for checkpoints only"):
        schedule(baselines(quick), sample=4)


# -- process hygiene: a killed tournament leaves no worker behind; one writer per --out --------------------
def _wait_for(condition, seconds: float, what: str) -> None:
    import time

    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
@pytest.mark.parametrize("signal_name", ["SIGKILL", "SIGTERM"])
def test_a_killed_tournament_leaves_no_worker_behind(tmp_path: Path, signal_name: str) -> None:
    """Two workers: one finishes pairings, one is stuck in a pairing that never ends. Once a pairing is cached
    the driver is killed; its workers and the resource tracker must be gone within seconds."""
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "t"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    command = [
        sys.executable,
        "-m",
        "pecli",
        "tournament",
        "--baselines",
        "stalling:StallingEvader",
        "-c",
        "quick",
        "-n",
        "4",
        "--seeds",
        "1",
        "--workers",
        "2",
        "--out",
        str(out),
    ]
    driver = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    children: set[int] = set()
    try:
        _wait_for(lambda: driver.poll() is not None or any((out / "pairings").glob("*.json")), 180, "a cached pairing")
        assert driver.poll() is None, driver.communicate()
        children = descendants(driver.pid)
        assert len(children) >= 2  # the workers (and multiprocessing's resource tracker)
        driver.send_signal(getattr(signal, signal_name))
        driver.wait(timeout=60)
        _wait_for(lambda: not children & set(live_parents()), 20, f"the driver's children {children} to end")
        if signal_name == "SIGTERM":  # ends as Ctrl-C does
            stderr = driver.stderr.read()  # the workers, which shared the pipe, are gone: no wait
            assert driver.returncode == 130 and "interrupted" in stderr and "Traceback" not in stderr, stderr
    finally:
        for pid in children | {driver.pid}:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        driver.communicate()


def test_one_tournament_writes_an_output_folder_at_a_time(tmp_path: Path, quick: Scenario) -> None:
    from conftest import hold

    out = tmp_path / "t"
    out.mkdir()
    holder = hold(out)
    try:
        assert holder.poll() is None  # it holds the lock
        result = runner.invoke(
            app,
            [
                "tournament",
                "--baselines",
                "-c",
                "quick",
                "-n",
                "2",
                "--seeds",
                "1",
                "--workers",
                "1",
                "--out",
                str(out),
            ],
        )
        assert result.exit_code == 1, result.output
        assert f"is being written by process {holder.pid}" in result.output and "tournament output" in result.output
        with pytest.raises(PecliError, match="being written"):
            run_tournament(quick, baselines(quick), schedule(baselines(quick)), 2, [0], out)
        assert not (out / "results.json").exists()
    finally:
        holder.kill()
        holder.wait()
    # the OS dropped the dead holder's lock: the folder can be written again
    result = runner.invoke(
        app,
        ["tournament", "--baselines", "-c", "quick", "-n", "2", "--seeds", "1", "--workers", "1", "--out", str(out)],
    )
    assert result.exit_code == 0, result.output


def test_an_impossible_batch_is_refused_before_it_is_allocated(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        [
            "tournament",
            "--baselines",
            "-c",
            "quick",
            "-n",
            "10000000000",
            "--seeds",
            "1",
            "-w",
            "1",
            "--out",
            str(tmp_path / "t"),
        ],
    )
    assert result.exit_code == 1 and "more than one batch can play" in result.output
    played = runner.invoke(app, ["play", "-p", "pure-pursuit", "-e", "greedy", "-c", "quick", "-n", "10000000000"])
    assert (
        played.exit_code == 1 and "more than one batch can play" in played.output and "Traceback" not in played.output
    )


def test_the_heatmap_of_a_small_grid_with_long_names_fits_them(tmp_path: Path) -> None:
    """One pursuer and one evader named by their checkpoint paths: the figure grows to fit the labels instead of
    Matplotlib warning that it could not (which a run with warnings as errors turned into a failure)."""
    import warnings
    from types import SimpleNamespace

    from pecli.reports import heatmap

    pursuer, evader = "none-s0/pursuer/round-002", "none-s0/evader/round-002"
    results = SimpleNamespace(
        grid=lambda: {(pursuer, evader): SimpleNamespace(capture_rate=0.5)},
        players={"pursuer": [SimpleNamespace(name=pursuer)], "evader": [SimpleNamespace(name=evader)]},
        scenario=SimpleNamespace(name="quick"),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        path = heatmap(results, tmp_path / "capture_rates.png")  # type: ignore[arg-type]
    assert path.stat().st_size > 1000


def zoo_results(scenario: Scenario, pursuers: int, evaders: int, run: str = "league-seed-"):
    """Results of a tournament of a league's zoo: ``pursuers`` × ``evaders`` players with run/folder/round names."""
    from pecli.stats import Rating
    from pecli.tournament import PairingResult, TournamentResults

    def players(role: str, count: int) -> list[Player]:
        return [
            Player(f"{run}{i % 3}/exploiter-{role}/round-{i:03d}", f"/zoo/{role}{i}.zip", role, f"{role}{i}")
            for i in range(count)
        ]

    found = {"pursuer": players("pursuer", pursuers), "evader": players("evader", evaders)}
    pairings = [
        PairingResult(p.name, e.name, 100, (7 * i + 3 * j) % 101, 0.5, 0.25)
        for j, e in enumerate(found["evader"])
        for i, p in enumerate(found["pursuer"])
    ]
    ratings = [Rating(p.name, 1000.0 - i, 12.0, 100) for i, p in enumerate(found["pursuer"] + found["evader"])]
    return TournamentResults(scenario, found, pairings, ratings, 50, [0, 1])


@pytest.mark.parametrize("size", [19, 40])
def test_the_tables_of_a_zoo_of_any_size_fit_120_columns(quick: Scenario, size: int) -> None:
    """A small grid keeps the paper's layout with names; a large one numbers its players and splits as it must."""
    import io

    from rich.console import Console

    from pecli.reports import ratings_table, results_tables

    results = zoo_results(quick, size, size)
    out = io.StringIO()
    console = Console(file=out, width=120, force_terminal=False)
    tables = results_tables(results, width=120)
    for table in [*tables, ratings_table(results, limit=40)]:
        console.print(table)
    shown = out.getvalue()
    assert max(len(line) for line in shown.splitlines()) <= 120
    assert "P1 " in shown and f"E{size}" in shown and f"P{size}" in shown  # numbered
    assert f"league-seed-{(size - 1) % 3}/exploiter-pursuer/round-{size - 1:03d}" in shown  # the legend names all
    assert len(tables) == (2 if size == 19 else 3)  # the legend, then the grid in as many parts as it needs
    last = f"{(7 * (size - 1) + 3 * (size - 1)) % 101 / 100:.2f}"
    assert any(line.split()[:1] == [f"E{size}"] and line.rstrip().endswith(last) for line in shown.splitlines())


def test_a_small_grid_keeps_the_paper_layout_with_names(quick: Scenario) -> None:
    from pecli.reports import results_tables

    (table,) = results_tables(zoo_results(quick, 2, 2, run="s"), width=120)
    assert [column.header for column in table.columns][1:] == [f"s{i}/exploiter-pursuer/round-00{i}" for i in range(2)]


def test_a_seed_without_sample_is_refused_not_ignored(tmp_path: Path) -> None:
    out = str(tmp_path / "t")
    result = runner.invoke(app, ["tournament", "--baselines", "-c", "quick", "-s", "7", "--out", out])
    assert result.exit_code == 1 and "--seed seeds the --sample draw only" in result.output, result.output
    negative = runner.invoke(app, ["tournament", "--baselines", "-c", "quick", "-s", "-1", "--sample", "2"])
    assert negative.exit_code == 2  # below the option's minimum


def test_a_long_policy_string_is_named_by_its_size_and_a_digest(quick: Scenario) -> None:
    spec = "mix:pure-pursuit@1." + "0" * 60 + "1,interceptor@2"  # a weight written long: past 80 characters
    assert len(spec) > 80 and player_label("mix:pure-pursuit,interceptor") == "mix:pure-pursuit,interceptor"
    name = player_label(spec)
    assert name.startswith("mix of 2 (") and len(name) < 30 and name != player_label(spec.replace("@2", "@3"))
    found = find_players([spec, "greedy"], quick)
    assert [p.name for p in found.players["pursuer"]] == [f"{name}/pursuer"]
