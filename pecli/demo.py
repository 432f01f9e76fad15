"""The main job end to end on a small scenario: train a pursuer, measure it beside pure pursuit, export, draw.

What ``pecli demo`` (and ``make demo``) runs, in a few CPU-minutes: a pursuer trained with the tuned training
settings in the small ``quick`` arena against the greedy evader for a CPU budget; the trained pursuer and the
paper's pure-pursuit baseline each play the paper's scripted evaders (random walk, greedy, rash, section V-B)
from the same start states; the pursuer exported to ONNX plays greedy again through the robot runtime's graph;
one episode is drawn as a GIF and several as a PNG.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from pecli.errors import PecliError
from pecli.scenario import Scenario, load_scenario, scenario_from_dict

EVADERS = ("random-walk", "greedy", "rash")
BASELINE = "pure-pursuit"
RUN_NAME = "demo"


def demo_scenario() -> Scenario:
    """The ``quick`` game (8 m × 8 m, T = 150) trained with ``tuned``'s settings, curriculum and all."""
    game, tuned = load_scenario("quick").model_dump(mode="json"), load_scenario("tuned").model_dump(mode="json")
    training = tuned["training"] | {"steps": 200_000, "checkpoint_every": 100}
    return scenario_from_dict(game | {"name": "demo", "training": training}, source="the demo")


@dataclass(frozen=True)
class Row:
    """One evader met by the trained pursuer and by the baseline: capture rates over the same games."""

    evader: str
    trained: float
    baseline: float


@dataclass
class DemoResult:
    """What the demo measured and wrote."""

    checkpoint: Path
    export: Path | None  # None where onnx or onnxruntime is not installed
    rows: list[Row] = field(default_factory=list)
    export_capture: float | None = None  # the export against greedy, on the same games as the checkpoint
    pictures: list[Path] = field(default_factory=list)
    cpu_seconds: float = 0.0  # training's CPU time


def run_demo(
    out: Path,
    cpu_minutes: float = 1.5,
    episodes: int = 500,
    seed: int = 0,
    progress: bool = True,
    report: Callable[[str], None] = lambda line: None,
) -> DemoResult:
    """Train, measure, export and draw into ``out`` (a zoo folder and the pictures); replaces an earlier demo."""
    import shutil

    from pecli.export.exporter import NEEDS_ONNX, export_available, export_checkpoint
    from pecli.match import play_match
    from pecli.policies import resolve_policy
    from pecli.render import animate_episode, draw_episodes
    from pecli.rl.budget import check_cpu_minutes
    from pecli.rl.train import TrainJob, train
    from pecli.zoo import read_metadata

    check_cpu_minutes(cpu_minutes)
    if episodes < 1:
        raise PecliError("--episodes must be at least 1")
    scenario = demo_scenario()
    zoo = out / "zoo"
    if (zoo / RUN_NAME).exists():
        shutil.rmtree(zoo / RUN_NAME)
    job = TrainJob(
        role="pursuer",
        scenario=scenario,
        opponent="greedy",
        zoo=zoo,
        name=RUN_NAME,
        seed=seed,
        progress=progress,
        cpu_budget=cpu_minutes * 60.0,
    )
    report(f"1/4 training a pursuer against greedy for {cpu_minutes:g} CPU-minutes (quick arena, tuned settings)")
    checkpoint = train(job, report=report)
    spent = read_metadata(checkpoint).cpu_seconds or 0.0

    report(f"2/4 the trained pursuer and {BASELINE} against the scripted evaders, {episodes} games each")
    rows = []
    recordings = {}
    for evader in EVADERS:
        rates = []
        for pursuer in (str(checkpoint), BASELINE):
            result, recording = play_match(
                scenario,
                resolve_policy(pursuer, "pursuer", scenario),
                resolve_policy(evader, "evader", scenario),
                episodes=episodes,
                seed=seed,
                record=min(8, episodes) if (pursuer != BASELINE and evader == "greedy") else 0,
            )
            rates.append(result.capture_rate)
            if recording is not None:
                recordings[evader] = recording
        rows.append(Row(evader, rates[0], rates[1]))

    exported, export_capture = None, None
    if not export_available():
        report(f"3/4 skipped: {NEEDS_ONNX}")
    else:
        report("3/4 exporting to ONNX (parity-checked) and playing the export against greedy")
        exported = export_checkpoint(checkpoint).model
        result, _ = play_match(
            scenario,
            resolve_policy(str(exported), "pursuer", scenario),
            resolve_policy("greedy", "evader", scenario),
            episodes=episodes,
            seed=seed,
        )
        export_capture = result.capture_rate

    report("4/4 drawing")
    out.mkdir(parents=True, exist_ok=True)
    title = f"the trained pursuer vs greedy on quick (seed {seed})"
    pictures = [
        animate_episode(recordings["greedy"], out / "demo.gif", title=title),
        draw_episodes(recordings["greedy"], out / "demo.png", episodes=min(8, episodes), title=title),
    ]
    return DemoResult(
        checkpoint=checkpoint,
        export=exported,
        rows=rows,
        export_capture=export_capture,
        pictures=pictures,
        cpu_seconds=spent,
    )
