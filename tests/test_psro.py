"""``pecli psro``: the populations' meta-game, its Nash mixtures as players, best responses joining, resumable."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli.cli import app
from pecli.exploit import read_pair
from pecli.policies import resolve_policy
from pecli.policies.nash import read_nash
from pecli.psro import PsroJob, psro, read_psro
from pecli.scenario import load_scenario

runner = CliRunner()


def test_psro_grows_both_populations_and_measures_each_mixtures_nash_conv(tmp_path: Path, tiny: Path) -> None:
    out = tmp_path / "psro"
    args = ["psro", "pure-pursuit", "hider", "-c", str(tiny), "--iterations", "1", "--cpu-minutes", "0.015"]
    args += ["-n", "10", "--held-out", "20", "--out", str(out), "--json"]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    assert len(json.loads(first.stdout)) == 1
    second = runner.invoke(app, [*args[:6], "2", *args[7:]])  # two iterations: the first one is not trained again
    assert second.exit_code == 0, second.output
    iterations = json.loads(second.stdout)
    assert len(iterations) == 2 and iterations[0] == json.loads(first.stdout)[0]
    assert iterations[0]["pursuer_mixture"] == {"pursuer-0": 1.0}  # one member each: the mixture is the player
    assert set(iterations[1]["pursuer_mixture"]) <= {"pursuer-0", "pursuer-1"}
    for it in iterations:
        assert it["nash_conv"] == pytest.approx(it["best_pursuer"] - it["best_evader"])
        assert it["interval"][0] <= it["nash_conv"] <= it["interval"][1]
    first_pursuer = out / iterations[0]["joined"]["pursuer"]
    assert first_pursuer.is_file() and "iter-01/against-evader/fresh-s0" in iterations[0]["joined"]["pursuer"]
    assert "iter-02/against-evader/warm-s0" in iterations[1]["joined"]["pursuer"]  # warm from the newest member
    record = read_nash(out / "iter-02" / "nash.json")  # the members of iteration 2's game, relative to its folder
    assert {m.name for m in record.pursuer} <= {"pursuer-0", "pursuer-1"}
    scenario = load_scenario(str(tiny))
    player = resolve_policy(f"nash:{out / 'iter-02'}", "evader", scenario)
    assert player.role == "evader"
    pair = read_pair(out / "iter-02")
    assert pair is not None and pair.nash_conv == pytest.approx(iterations[1]["nash_conv"])
    assert (out / "nash-conv.png").stat().st_size > 1000 and read_psro(out) == read_psro(out)
    other = PsroJob(
        ("pure-pursuit",), ("rash",), scenario, out, iterations=2, cpu_minutes=0.015, episodes=10, held_out=20
    )
    with pytest.raises(Exception, match="other players or settings"):
        psro(other)
    settings = {"iterations": 2, "cpu_minutes": 0.015, "episodes": 10, "held_out": 20}
    with pytest.raises(Exception, match="other players or settings"):  # another meta-solver is another PSRO
        psro(PsroJob(("pure-pursuit",), ("hider",), scenario, out, pursuer_solver="last", **settings))  # type: ignore[arg-type]


def test_each_sides_mixture_follows_its_meta_solver(tmp_path: Path, tiny: Path) -> None:
    from pecli.cli.psro import MetaSolver
    from pecli.metagame import MAXENT_SLACK, META_SOLVERS
    from pecli.psro import _fresh_record, meta_game, write_mixture

    assert tuple(choice.value for choice in MetaSolver) == META_SOLVERS  # the command offers every meta-solver

    scenario = load_scenario(str(tiny))
    job = PsroJob(
        ("pure-pursuit",), ("hider",), scenario, tmp_path, episodes=4, pursuer_solver="last", evader_solver="uniform"
    )
    populations = {"pursuer": ["pure-pursuit", "interceptor"], "evader": ["hider", "rash", "greedy"]}
    game = meta_game(job, populations, lambda line: None)  # type: ignore[arg-type]
    write_mixture(job, game, populations, tmp_path / "iter-01")  # type: ignore[arg-type]
    record = read_nash(tmp_path / "iter-01" / "nash.json")
    assert [(m.spec, m.weight) for m in record.pursuer] == [("interceptor", 1.0)]  # the newest pursuer alone
    assert sorted(m.spec for m in record.evader) == ["greedy", "hider", "rash"]
    assert [m.weight for m in record.evader] == pytest.approx([1 / 3] * 3)
    assert record.solvers == {"pursuer": "last", "evader": "uniform"}  # the file says which mixtures it holds
    assert record.slack is None and _fresh_record(job).slack is None
    spread = replace(job, pursuer_solver="maxent")
    game = meta_game(spread, populations, lambda line: None)  # type: ignore[arg-type]  # the pairings cached above
    write_mixture(spread, game, populations, tmp_path / "iter-02")  # type: ignore[arg-type]
    record = read_nash(tmp_path / "iter-02" / "nash.json")
    assert record.solvers["pursuer"] == "maxent" and record.slack == MAXENT_SLACK
    assert _fresh_record(spread).slack == MAXENT_SLACK  # a resumed run with another slack would be refused
    assert _fresh_record(replace(spread, slack=0.1)).slack == 0.1
    with pytest.raises(Exception, match="no meta-solver 'best'"):
        psro(PsroJob(("pure-pursuit",), ("hider",), scenario, tmp_path / "p", evader_solver="best"))


@pytest.mark.parametrize(
    "args, message",
    [
        (["pure-pursuit", "hider", "--iterations", "0"], "--iterations"),
        (["pure-pursuit", "hider", "--cpu-minutes", "inf"], "--cpu-minutes"),
        (["hider", "pure-pursuit"], "hider"),  # two players: the pursuer, then the evader
        (["pure-pursuit", "hider", "--slack", "0.1"], "add --pursuer-mixture maxent"),
        (["pure-pursuit", "hider", "--evader-mixture", "maxent", "--slack", "2"], "--slack must be in (0, 1]"),
        (["hider", "rash", "greedy"], "no pursuer among the players"),
        (["pure-pursuit", "hider", "--reuse", "."], "holds no played pairings"),
        (["pure-pursuit", "missing.zip"], "missing.zip"),
    ],
)
def test_mistakes_end_in_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    result = runner.invoke(app, ["psro", *args, "-c", "quick", "--out", str(tmp_path / "p")])
    assert result.exit_code != 0 and message in result.output and "Traceback" not in result.output


def test_psro_starts_from_populations_and_takes_a_tournaments_pairings(tmp_path: Path, tiny: Path) -> None:
    from pecli.psro import PsroRecord, _check, _fresh_record, meta_game, newest_checkpoint, take_pairings

    tournament = tmp_path / "tournament"
    played = runner.invoke(
        app,
        ["tournament", "pure-pursuit", "interceptor", "hider", "rash", "-c", str(tiny), "-n", "4", "--seeds", "1"]
        + ["--workers", "1", "--out", str(tournament)],
    )
    assert played.exit_code == 0, played.output
    scenario = load_scenario(str(tiny))
    populations = {"pursuer": ["pure-pursuit", "interceptor"], "evader": ["hider", "rash", "greedy"]}
    job = PsroJob(populations["pursuer"], populations["evader"], scenario, tmp_path / "psro", episodes=4)
    job = replace(job, reuse=tournament)
    _check(job)
    lines: list[str] = []
    assert take_pairings(job, tournament, populations, lines.append) == 4  # greedy's two were never played
    assert lines == [f"meta-game: 4 of the 6 pairings not yet played taken from {tournament}"]
    assert take_pairings(job, tournament, populations, lines.append) == 0 and "0 of the 2" in lines[-1]
    assert "--seeds 1" in lines[-1]  # why none matched
    game = meta_game(job, populations, lines.append)  # type: ignore[arg-type]
    assert sum("meta-game: " in line and " vs " in line for line in lines) == 2  # greedy's pairings only
    assert game.matrix.shape == (2, 3)
    record = _fresh_record(job)
    assert record.pursuers == ["pure-pursuit", "interceptor"] and record.evaders == ["hider", "rash", "greedy"]
    old = record.model_dump(mode="json", exclude={"pursuers", "evaders"}) | {"pursuer": "pure-pursuit", "evader": "x"}
    assert PsroRecord.model_validate(old).pursuers == ["pure-pursuit"]  # a record from one pair still reads
    assert newest_checkpoint(["a/round-001.zip", "b/best.zip", "greedy"]) == Path("b/best.zip")
    assert newest_checkpoint(["greedy"]) is None
    with pytest.raises(Exception, match="named twice"):
        _check(replace(job, evaders=["hider", "hider"]))
    job.out.joinpath("psro.json").write_text(json.dumps(record.model_dump(mode="json")))
    with pytest.raises(Exception, match=r"other players or settings \(its evaders\)"):
        psro(replace(job, evaders=["hider", "rash"], iterations=1))


def test_pairings_are_taken_only_from_small_json_files(tmp_path: Path) -> None:
    from pecli.tournament import MAX_PAIRING_BYTES, reuse_pairings

    source = tmp_path / "source" / "pairings"
    source.mkdir(parents=True)
    (source / "aa.json").write_text('{"episodes": 4}')
    (source / "bb.json").write_text(" " * (MAX_PAIRING_BYTES + 1))  # too large
    (source / "cc.json").write_text("not json")
    (source / "dd.json").symlink_to(source / "aa.json")
    (source / "ee").mkdir()
    (source / "ee.json").mkdir()  # not a file
    out = tmp_path / "out"
    assert reuse_pairings(source, out, ["aa", "bb", "cc", "dd", "ee", "ff"]) == (1, 6)
    assert json.loads((out / "pairings" / "aa.json").read_text()) == {"episodes": 4}
    assert sorted(p.name for p in (out / "pairings").iterdir()) == ["aa.json"]
