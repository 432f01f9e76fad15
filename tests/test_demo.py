"""``pecli demo``: the main job end to end (train, measure beside the baseline, export, draw) on a tiny budget."""

from __future__ import annotations

from pecli.demo import BASELINE, EVADERS, demo_scenario, run_demo


def test_demo_scenario_is_the_quick_game_with_tuned_training():
    from pecli.scenario import load_scenario

    scenario, quick, tuned = demo_scenario(), load_scenario("quick"), load_scenario("tuned")
    assert scenario.arena == quick.arena and scenario.horizon == quick.horizon
    assert scenario.training.n_step == tuned.training.n_step
    assert scenario.training.learning_rate == tuned.training.learning_rate


def test_demo_trains_measures_exports_and_draws(tmp_path):
    lines: list[str] = []
    result = run_demo(tmp_path / "demo", cpu_minutes=0.05, episodes=8, progress=False, report=lines.append)
    assert [row.evader for row in result.rows] == list(EVADERS)
    assert all(0.0 <= row.trained <= 1.0 and 0.0 <= row.baseline <= 1.0 for row in result.rows)
    assert result.checkpoint.is_file() and result.export.is_file() and result.export.suffix == ".onnx"
    greedy = next(row.trained for row in result.rows if row.evader == "greedy")
    assert result.export_capture == greedy  # the export plays the checkpoint's games as the checkpoint did
    assert [p.suffix for p in result.pictures] == [".gif", ".png"]
    assert all(p.stat().st_size > 1000 for p in result.pictures)
    assert 0.0 < result.cpu_seconds < 60.0
    assert any(BASELINE in line for line in lines) and lines[-1].startswith("4/4")
