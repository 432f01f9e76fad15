"""A study's report: its best trials, parameter importances and optimisation history (Optuna's matplotlib
visualisations), and the best trial's settings as a training profile (a scenario YAML)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import optuna
import yaml

from pecli.io import atomic_write_text
from pecli.rl.train import with_overrides
from pecli.rl.tune import stored_settings
from pecli.scenario import scenario_from_dict

TrialState = optuna.trial.TrialState


def best_trials(study: optuna.Study, count: int = 10) -> list[optuna.trial.FrozenTrial]:
    """The ``count`` complete trials with the highest scores, best first."""
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    return sorted(complete, key=lambda t: t.value, reverse=True)[:count]


def importances(study: optuna.Study) -> dict[str, float]:
    """Each parameter's share of the score's variation (PED-ANOVA, no extra dependency); empty with too few trials."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return optuna.importance.get_param_importances(
                study, evaluator=optuna.importance.PedAnovaImportanceEvaluator()
            )
    except (ValueError, RuntimeError, ZeroDivisionError):
        return {}


def summary(study: optuna.Study, count: int = 10) -> str:
    """The report as Markdown: the study's settings, trial counts, best trials and importances."""
    s = stored_settings(study)
    trials = study.get_trials(deepcopy=False)
    counts = {state: sum(t.state == state for t in trials) for state in TrialState}
    lines = [
        f"# Study `{study.study_name}`",
        "",
        f"`pecli tune {s.what}` on `{s.scenario['name']}`"
        + (f" against `{s.opponent}`" if s.opponent else "")
        + (
            f": {s.repeats} runs of {s.cpu_minutes:g} CPU-minutes per trial (the score is their mean), "
            if s.repeats > 1
            else f": {s.cpu_minutes:g} CPU-minutes per trial, "
        )
        + f"{s.evaluations} evaluations of {s.eval_episodes} episodes"
        f" against {', '.join(s.eval_opponents)}; pruner {s.pruner}.",
        "",
        f"Trials: {counts[TrialState.COMPLETE]} complete, {counts[TrialState.PRUNED]} pruned, "
        f"{counts[TrialState.FAIL]} failed, {counts[TrialState.RUNNING]} running.",
        "",
    ]
    best = best_trials(study, count)
    if best:
        names = list(dict.fromkeys(name for t in best for name in t.params))
        seeds = s.repeats > 1  # each seed's score beside the mean
        lines += [
            "## Best trials",
            "",
            "| trial | score | " + ("per seed | " if seeds else "") + "CPU-min | " + " | ".join(names) + " |",
            "| ---: | ---: | " + ("--- | " if seeds else "") + "---: | " + " | ".join("---" for _ in names) + " |",
        ]
        for t in best:
            cells = [_cell(t.params.get(name, "")) for name in names]
            each = " ".join(f"{v:.2f}" for v in t.user_attrs.get("scores", [])) + " | " if seeds else ""
            lines.append(
                f"| {t.number} | {t.value:.3f} | {each}{t.user_attrs.get('cpu_seconds', 0) / 60:.1f} | "
                + " | ".join(cells)
                + " |"
            )
        lines.append("")
    shares = importances(study)
    if shares:
        lines += ["## Parameter importances (PED-ANOVA)", "", "| parameter | importance |", "| --- | ---: |"]
        lines += [f"| {name} | {value:.3f} |" for name, value in shares.items()]
        lines.append("")
    return "\n".join(lines)


def _cell(value: Any) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def write_report(study: optuna.Study, folder: Path) -> list[Path]:
    """``report.md``, the search space (``space.yaml``) and the PNGs (``history.png``, ``importances.png``,
    ``intermediate.png``) into ``folder``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as plots

    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / "report.md", folder / "space.yaml"]
    atomic_write_text(written[0], summary(study) + "\n")
    atomic_write_text(written[1], stored_settings(study).space_text)  # the search space as the user wrote it
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    figures = {
        "history.png": lambda: plots.plot_optimization_history(study),
        "intermediate.png": lambda: plots.plot_intermediate_values(study),
    }
    if len(complete) >= 2 and importances(study):
        figures["importances.png"] = lambda: plots.plot_param_importances(
            study, evaluator=optuna.importance.PedAnovaImportanceEvaluator()
        )
    for name, draw in figures.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the matplotlib visualisations are flagged experimental
            axes = draw()
        figure = axes.figure if hasattr(axes, "figure") else axes[0].figure
        figure.set_size_inches(8, 5)
        figure.tight_layout()
        figure.savefig(folder / name, dpi=100)
        plt.close(figure)
        written.append(folder / name)
    return written


def profile(study: optuna.Study, name: str, trial: int | None = None) -> str:
    """The study's config with a trial's settings (the best one's by default) as scenario YAML."""
    s = stored_settings(study)
    chosen = study.best_trial if trial is None else study.trials[trial]
    scenario = scenario_from_dict(s.scenario, source="the study's config")
    scenario = with_overrides(scenario, chosen.user_attrs["overrides"], source=f"trial {chosen.number}")
    data = scenario.model_dump(mode="json")
    data["name"] = name
    data["description"] = (
        f"{scenario.description} -- training tuned by `pecli tune {s.what}` "
        f"(study {study.study_name}, trial {chosen.number}, score {chosen.value:.3f})"
    )
    return yaml.safe_dump(data, sort_keys=False)
