"""The experiment driver: train the grid, rank the checkpoints, play the final tournament, report.

Everything lives in ``out``::

    out/
        experiment.yaml      the experiment as run (``status`` and ``report`` read it)
        scenario.yaml        its scenario as first run (the game and training settings), checked on every run
        experiment.json      the driver's record: each run's status, the stages, one entry per session
        zoo/<run>/           the runs (self-play or one-role runs), each resumable on its own
        tasks/<run>.json     where and since when a run's task runs (written by the task)
        ranking/             the ranking tournament (its pairing cache, results.json)
        kept.json            the checkpoints the ranking kept, per run and role
        tournament/          the final tournament (pairing cache, results.json/csv, per-player heatmap)
        report.md, report.json, table.png     the report (:mod:`pecli.experiment.report`)

Running it again on the same ``out`` continues it: finished runs are skipped (a self-play run's task only
writes the averages a stop left behind), unfinished ones continue from their durable state, cached pairings
are not played again.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from pecli.errors import PecliError
from pecli.experiment.folder import (
    KEPT_FILE,
    SCENARIO_FILE,
    SPEC_FILE,
    STATE_FILE,
    RunStatus,
    driver_alive,
    read_state,
    read_task_marker,
)
from pecli.experiment.runs import averages_behind, run_progress, setting_changes
from pecli.experiment.spec import LoadedExperiment, RunSpec
from pecli.io import atomic_write_json, atomic_write_text
from pecli.roles import ROLES
from pecli.scenario import read_yaml

if TYPE_CHECKING:
    from pecli.experiment.ray_executor import RayCluster
    from pecli.tournament import PairingResult, TournamentResults

POLL_SECONDS = 1.0
GRACE_SECONDS = 30.0  # after Ctrl-C, how long running runs get to commit their state
RAY_LOGS = "/tmp/ray/session_latest/logs"  # where embedded Ray writes its logs (workers' tracebacks)


@dataclass
class Session:
    """What one ``pecli experiment run`` did (appended to ``experiment.json``)."""

    started: float = field(default_factory=time.time)
    runs_started: int = 0
    runs_resumed: int = 0
    runs_skipped: int = 0  # finished (or paused at --until-cpu-hours) before this session
    pairings_played: int = 0
    pairings_cached: int = 0
    ended: str = "running"  # running, done, paused (at until_cpu_hours), interrupted, failed
    until_cpu_hours: float | None = None  # --until-cpu-hours of this session


class ExperimentRunner:
    """Runs one experiment into ``out`` on a :class:`~pecli.experiment.ray_executor.RayCluster`.

    ``on_update(rows, stage)`` is called about once a second while runs train and after every pairing,
    for a live view; ``stage`` says what is going on (``"training"``, ``"ranking 12/80"``, ...).

    ``until_cpu_hours`` trains each self-play run only until it has used that much CPU (at most its own
    budget) and, while any run is short of its own budget, stops before the ranking: every run at an equal
    budget first, the rest on a later call with a larger value or none. One-role runs train to their end.
    """

    def __init__(
        self,
        experiment: LoadedExperiment,
        out: Path,
        on_update: Callable[[list[RunStatus], str], None] = lambda rows, stage: None,
        until_cpu_hours: float | None = None,
    ) -> None:
        if until_cpu_hours is not None and not until_cpu_hours > 0:
            raise PecliError(f"--until-cpu-hours must be a positive number of hours, not {until_cpu_hours}")
        self.experiment = experiment
        self.out = out
        self.until_cpu_hours = until_cpu_hours
        self.zoo = out / "zoo"
        self.on_update = on_update
        self.session = Session(until_cpu_hours=until_cpu_hours)
        self.rows = [RunStatus(run, run_progress(run, self.zoo)) for run in experiment.runs()]
        self.stage = "starting"
        self.prepared = False

    # -- the record in out/ ------------------------------------------------------------------------
    def prepare(self) -> None:
        """Record the experiment in ``out``, or check that ``out`` holds this same experiment and that no
        other driver runs it (:meth:`run` does it first if it was not done)."""
        spec = self.experiment.spec
        state = read_state(self.out)
        if state:
            if state.get("fingerprint") != spec.fingerprint():
                raise PecliError(
                    f"{self.out} holds experiment '{state.get('name')}' with other settings: "
                    "give another --out (or the same experiment file to continue it)"
                )
            if driver_alive(state):
                raise PecliError(
                    f"{self.out} is being run by process {state['driver']['pid']}: wait for it, or stop it"
                )
        scenario = self.experiment.scenario.model_dump(mode="json", exclude={"name", "description"})
        recorded = self.out / SCENARIO_FILE
        if state and recorded.is_file():
            changed = setting_changes(read_yaml(recorded), scenario)
            if changed:
                more = f" and {len(changed) - 1} more" if len(changed) > 1 else ""
                raise PecliError(
                    f"the scenario '{spec.scenario}' has changed since {self.out} started "
                    f"({changed[0]}{more}; as first run: {recorded}): restore it (or the pecli "
                    "that ran it), or give another --out"
                )
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "tasks").mkdir(exist_ok=True)
        atomic_write_text(self.out / SPEC_FILE, yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False))
        if not recorded.is_file():  # an experiment started before pecli recorded it: from now on
            atomic_write_text(recorded, yaml.safe_dump(scenario, sort_keys=False))
        self.sessions = state.get("sessions", [])
        self.stages: dict[str, Any] = state.get("stages", {})
        self.prepared = True
        self._save()

    def _save(self, ended: str | None = None) -> None:
        spec = self.experiment.spec
        atomic_write_json(
            self.out / STATE_FILE,
            {
                "name": spec.name,
                "fingerprint": spec.fingerprint(),
                "source": self.experiment.source,
                "driver": {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started": self.session.started,
                    "ended": ended,
                },
                "runs": {
                    row.run.name: {"status": row.status, "error": row.error, "host": row.host} for row in self.rows
                },
                "stages": self.stages,
                "sessions": [*self.sessions, vars(self.session)],
            },
        )

    def _update(self, stage: str | None = None) -> None:
        if stage is not None:
            self.stage = stage
        self.on_update(self.rows, self.stage)

    # -- the stages ----------------------------------------------------------------------------------
    def run(self, cluster: RayCluster) -> Path | None:
        """Run every stage not done yet; returns the report's Markdown file, or None where ``until_cpu_hours``
        paused runs short of their budget (the ranking waits for every run)."""
        if not self.prepared:
            self.prepare()
        try:
            self._train(cluster)
            if self.stages["train"] == "paused":
                self.session.ended = "paused"
                self._save(ended="paused")
                return None
            self._tournament(cluster, self._rank(cluster))
            path = self._report()
        except KeyboardInterrupt:
            self.session.ended = "interrupted"
            self._save(ended="interrupted")
            raise
        except BaseException:
            self.session.ended = "failed"
            self._save(ended="failed")
            raise
        self.session.ended = "done"
        self._save(ended="done")
        return path

    def _task(self, run: RunSpec) -> RunSpec:
        """The run as its task trains it: with its CPU budget cut to ``until_cpu_hours``, if that is less."""
        if self.until_cpu_hours is None or not run.selfplay:
            return run
        return run.model_copy(update={"cpu_hours": min(run.cpu_hours or self.until_cpu_hours, self.until_cpu_hours)})

    def _trained(self, row: RunStatus) -> str:
        """``done``, or ``paused`` for a run that reached ``until_cpu_hours`` short of its own budget."""
        return "paused" if self.until_cpu_hours is not None and not row.progress.done else "done"

    def _train_stage(self) -> str:
        return "paused" if any(row.status == "paused" for row in self.rows) else "done"

    def _train(self, cluster: RayCluster) -> None:
        pending: dict[Any, RunStatus] = {}
        # in the order runs start (LoadedExperiment.runs: schedule, seed, kind): a partly run grid has every kind
        # of the first seeds of the first schedule rather than all seeds of a few kinds
        for row in self.rows:
            task = self._task(row.run)
            finished = row.progress.done or (task is not row.run and run_progress(task, self.zoo).done)
            if finished and not averages_behind(row.run, self.zoo):
                row.status = self._trained(row)
                self.session.runs_skipped += 1
                continue
            row.status, row.error, row.submitted = "queued", "", time.time()
            pending[cluster.submit_run(task, self.zoo, self.out / "tasks" / f"{row.run.name}.json")] = row
        self.stages["train"] = "running" if pending else self._train_stage()
        self._save()
        try:
            while pending:
                for ref in cluster.wait(list(pending), timeout=POLL_SECONDS):
                    row = pending.pop(ref)
                    row.progress = run_progress(row.run, self.zoo)
                    try:
                        outcome = cluster.result(ref)
                    except PecliError as exc:
                        row.status, row.error = "failed", str(exc)
                    except (
                        Exception
                    ) as exc:  # a bug, or a worker lost more often than Ray retries: keep the others going
                        row.status = "failed"
                        row.error = f"{type(exc).__name__}: {exc} (its traceback is in Ray's logs, {RAY_LOGS})"
                    else:
                        row.status = self._trained(row)
                        if outcome["did"] == "started":
                            self.session.runs_started += 1
                        elif outcome["did"] == "resumed":
                            self.session.runs_resumed += 1
                        else:  # finished before: its task only wrote the averages a stop left behind
                            self.session.runs_skipped += 1
                    self._save()
                started = False
                for row in pending.values():
                    row.progress = run_progress(row.run, self.zoo)
                    marker = read_task_marker(self.out, row.run)
                    if row.status == "queued" and marker.get("started", 0) >= row.submitted - 1:
                        row.status, row.host, started = "running", marker.get("host", ""), True
                if started:
                    self._save()
                self._update("training")
        except KeyboardInterrupt:
            running = [ref for ref, row in pending.items() if row.status == "running"]
            self._update(f"stopping: {len(running)} runs commit their state")
            cluster.stop(list(pending), grace=GRACE_SECONDS)
            for row in pending.values():
                row.status = "stopped"
                row.progress = run_progress(row.run, self.zoo)
            raise
        failed = [row for row in self.rows if row.status == "failed"]
        if failed:
            self.stages["train"] = "failed"
            more = f" (and {len(failed) - 1} more)" if len(failed) > 1 else ""
            raise PecliError(
                f"run {failed[0].run.name} failed: {failed[0].error}{more}; "
                "the others are saved: run the experiment again to retry"
            )
        self.stages["train"] = self._train_stage()
        self._save()

    def _play(
        self, cluster: RayCluster, name: str, players: dict, pairings: list, episodes: int, seeds: int
    ) -> TournamentResults:
        """One tournament into ``out/<name>`` with Ray playing the pairings not cached."""
        from pecli.tournament import run_tournament

        done = 0

        def counted(result: PairingResult, cached: bool) -> None:
            nonlocal done
            done += 1
            if cached:
                self.session.pairings_cached += 1
            else:
                self.session.pairings_played += 1
            self._update(f"{name} {done}/{len(pairings)}")

        self.stages[name] = {"pairings": len(pairings), "status": "running"}
        self._save()
        results = run_tournament(
            self.experiment.scenario,
            players,
            pairings,
            episodes,
            list(range(seeds)),
            self.out / name,
            on_result=counted,
            executor=cluster.play_pairings,
        )
        self.stages[name]["status"] = "done"
        self._save()
        return results

    def _rank(self, cluster: RayCluster) -> dict[str, dict[str, list[str]]]:
        """The paper's ranking: each checkpoint against ``sample`` random checkpoints of the other side; keeps
        the best ``keep`` per run and role by mean capture rate. Returns ``{run: {role: [paths]}}``."""
        from pecli.tournament import find_players, schedule

        settings = self.experiment.spec.ranking
        if settings.players == "handed-over":
            kept = handed_over([row.run for row in self.rows], self.zoo)
            atomic_write_json(self.out / KEPT_FILE, kept)
            return kept
        runs = self.experiment.grid_order([row.run for row in self.rows])
        found = find_players([str(self.zoo / run.name) for run in runs], self.experiment.scenario)
        pairings = schedule(found.players, sample=settings.sample, seed=0)
        self._update("ranking")
        results = self._play(cluster, "ranking", found.players, pairings, settings.episodes, settings.seeds)
        kept = keep_best(results, [row.run for row in self.rows], settings.keep)
        atomic_write_json(self.out / KEPT_FILE, kept)
        return kept

    def _tournament(self, cluster: RayCluster, kept: dict[str, dict[str, list[str]]]) -> TournamentResults:
        from pecli.reports import write_reports
        from pecli.tournament import find_players, schedule

        settings = self.experiment.spec.tournament
        paths = [path for roles in kept.values() for role in ROLES for path in roles.get(role, [])]
        extra = [self._solved(spec) for spec in settings.players]
        found = find_players([*paths, *extra], self.experiment.scenario, baselines=settings.baselines)
        pairings = schedule(found.players)
        self._update("tournament")
        results = self._play(cluster, "tournament", found.players, pairings, settings.episodes, settings.seeds)
        write_reports(results, self.out / "tournament")
        return results

    def _solved(self, spec: str) -> str:
        """A player string, with an HJ player that would read this machine's solution cache (``hj``,
        ``hj:model=rel6d``) given a solution file in ``out/hj/`` instead, solved there first if needed (a
        minute and a half for the default model), so that every node of a cluster reads the same file."""
        from pecli.hj.cache import solve_cached
        from pecli.hj.grid import DEFAULT_MODEL
        from pecli.hj.problem import Problem
        from pecli.policies.hj import parse_options

        family, _, options = spec.partition(":")
        if family != "hj":
            return spec
        settings = parse_options(options)
        if "solution" in settings:
            return spec
        model = settings.pop("model", DEFAULT_MODEL)
        scenario = self.experiment.scenario
        self._update(f"solving the HJ game ({model})")
        _, path, _ = solve_cached(
            Problem.for_scenario(scenario, model),
            scenario.name,  # type: ignore[arg-type]
            out=self.out / "hj" / f"hj-{model}.npz",
        )
        if not settings:
            return str(path.resolve())  # a solution file plays as itself, named after it
        return "hj:" + ",".join([str(path.resolve()), *(f"{key}={value}" for key, value in settings.items())])

    def _report(self) -> Path:
        from pecli.experiment.report import write_report

        self._update("report")
        paths = write_report(self.out)
        self.stages["report"] = "done"
        return paths[0]


def handed_over(runs: list[RunSpec], zoo: Path) -> dict[str, dict[str, list[str]]]:
    """Each self-play run's handed-over players, ``<zoo>/<run>/<role>/average.zip``: ``{run: {role: [path]}}``;
    :class:`PecliError` for a run that has none (it trained no round)."""
    from pecli.zoo import AVERAGE_FILE

    kept: dict[str, dict[str, list[str]]] = {}
    for run in runs:
        paths = {role: zoo / run.name / role / AVERAGE_FILE for role in run.roles}
        missing = [str(path) for path in paths.values() if not path.is_file()]
        if missing:
            raise PecliError(f"{run.name} hands over no player: {missing[0]} is missing (did it train a round?)")
        kept[run.name] = {role: [str(path)] for role, path in paths.items()}
    return kept


def keep_best(results: TournamentResults, runs: list[RunSpec], keep: int) -> dict[str, dict[str, list[str]]]:
    """The best ``keep`` checkpoints of each run and role by mean capture rate in ``results`` (a pursuer's
    highest, an evader's lowest): ``{run: {role: [checkpoint paths]}}``, best first."""
    by_name = {p.name: p for role in ROLES for p in results.players[role]}
    scores: dict[str, list[tuple[int, int]]] = {}
    for r in results.pairings:
        for name in (r.pursuer, r.evader):
            scores.setdefault(name, []).append((r.captures, r.episodes))
    kept: dict[str, dict[str, list[str]]] = {run.name: {} for run in runs}
    for run in runs:
        for role in run.roles:
            mine = [
                p
                for p in results.players[role]  # the run's main agents (a league's exploiters only train them)
                if Path(p.spec).parent.parent.name == run.name and Path(p.spec).parent.name == role and p.name in scores
            ]
            rate = {p.name: sum(c for c, _ in scores[p.name]) / sum(n for _, n in scores[p.name]) for p in mine}
            best = sorted(mine, key=lambda p: (-rate[p.name] if role == "pursuer" else rate[p.name], p.name))
            kept[run.name][role] = [by_name[p.name].spec for p in best[:keep]]
    return kept
