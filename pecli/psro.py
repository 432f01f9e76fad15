"""PSRO over whole players: the double oracle with trained best responses (Lanctot et al. 2017).

Two populations start from the players given: a league run's handed-over pursuer and evader, or whole zoos
(e.g. every round of several runs and the evaders a tournament met; ``reuse`` names a tournament whose played
pairings the first meta-game takes from its cache instead of playing them again). Each iteration plays the
meta-game of the populations (every pursuer against every evader, cached, so an iteration plays only its new
members' pairings), solves its Nash equilibrium (:mod:`pecli.metagame`) and writes each side's
mixture, by its meta-solver, as ``OUT/iter-NN/nash.json``, a player as ``nash:OUT/iter-NN``: the equilibrium's
(``nash``, PSRO's double oracle), every member alike (``uniform``, fictitious play) or the newest member alone
(``last``, iterated best response). Then one best response per role trains against the other side's mixture on
the real game (:mod:`pecli.exploit`: from scratch, or warm-started from the newest checkpoint of its own
population, the last one given or joined), and its held-out games against that mixture measure the mixtures'
NashConv, ``capture(BR pursuer, evader mixture) - capture(pursuer mixture, BR evader)`` (approximate, as the
responses are). The strongest response of each role joins its population, and the next iteration solves the
larger game.

NashConv per iteration is what PSRO drives down; the last iteration's mixture is the player to hand over (with
``last``, one network: the newest member). The output folder holds ``psro.json`` (the job and every finished
iteration), ``meta-game/`` (the pairings' cache), one ``iter-NN/`` per iteration (``nash.json``,
``against-pursuer/``, ``against-evader/``, ``pair.json``, as ``pecli exploit --pair`` writes them) and
``nash-conv.png``. A stopped command continues where it stopped.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pecli.errors import PecliError
from pecli.exploit import ExploitJob, ExploitResult, PairResult, exploit_all, pair_result
from pecli.io import atomic_path, atomic_write_json, read_output_record
from pecli.locks import locked
from pecli.metagame import MAXENT_SLACK, META_SOLVERS, MetaGame, MetaSolver, solve, with_meta_solvers
from pecli.policies import resolve_policy
from pecli.policies.nash import NASH_FILE, mixture_record
from pecli.rl.budget import MAX_CPU_MINUTES, check_cpu_minutes
from pecli.roles import ROLES, Role, opponent_of
from pecli.scenario import Scenario
from pecli.tournament import pairing_keys, pairing_results, pairings_cache, player_spec, reuse_pairings

RECORD_FILE = "psro.json"
CURVE_FILE = "nash-conv.png"
MAX_ITERATIONS = 100
MAX_POPULATION = 1000  # members a population may start with
META_GAME_DIR = "meta-game"  # the meta-game's cache of pairings
META_SEEDS = (0,)  # the seeds of each meta-game pairing's games (as `pecli tournament --seeds 1`)


@dataclass(frozen=True)
class PsroJob:
    """PSRO from the populations ``pursuers`` and ``evaders`` (policy strings or player files, in the order they
    joined: the last checkpoint is the newest) in ``scenario``, into ``out``.

    Each iteration trains ``len(seeds)`` responses per role of ``cpu_minutes`` each (``warm``: from the newest
    checkpoint of the learner's population, where it holds one) against the other side's mixture by its
    meta-solver (``pursuer_solver``, ``evader_solver``: one of :data:`pecli.metagame.META_SOLVERS`), measures them
    in ``held_out`` games against that mixture, and plays every new pairing of the meta-game ``episodes`` times.
    ``reuse``: a tournament's or another PSRO's folder whose cached pairings the meta-game takes (its games are
    keyed by everything that decides them, so only identical pairings are reused).
    """

    pursuers: Sequence[str]
    evaders: Sequence[str]
    scenario: Scenario
    out: Path
    iterations: int = 3
    cpu_minutes: float = 20.0
    seeds: Sequence[int] = (0,)
    warm: bool = True
    episodes: int = 200
    held_out: int = 500
    workers: int = 1
    pursuer_solver: MetaSolver = "nash"
    evader_solver: MetaSolver = "nash"
    reuse: Path | None = None
    slack: float = MAXENT_SLACK  # what a maxent meta-solver gives up against the meta-game's value


class _Record(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


class Iteration(_Record):
    """One finished iteration, as ``psro.json`` keeps it."""

    value: float = Field(ge=0.0, le=1.0)  # the mixtures' capture rate against each other in the meta-game
    pursuer_mixture: dict[str, float]
    evader_mixture: dict[str, float]
    best_pursuer: float = Field(ge=0.0, le=1.0)  # the BR pursuer's capture rate against the evader mixture
    best_evader: float = Field(ge=0.0, le=1.0)  # the pursuer mixture's capture rate against the BR evader
    nash_conv: float = Field(ge=-1.0, le=1.0)
    interval: list[float] = Field(min_length=2, max_length=2)  # NashConv's 95 % interval
    joined: dict[Role, str]  # the new member's checkpoint (out-relative) of each role


class PsroRecord(_Record):
    """``psro.json``: the start (a re-run must match it) and the iterations finished so far."""

    kind: str = Field(default="psro", pattern="^psro$")
    pursuers: list[Annotated[str, Field(max_length=4096)]] = Field(min_length=1, max_length=MAX_POPULATION)
    evaders: list[Annotated[str, Field(max_length=4096)]] = Field(min_length=1, max_length=MAX_POPULATION)
    scenario: str = Field(max_length=1000)
    scenario_hash: str = Field(max_length=200)
    cpu_minutes: float = Field(gt=0, le=MAX_CPU_MINUTES)
    seeds: list[int] = Field(min_length=1, max_length=100)
    warm: bool
    episodes: int = Field(ge=1, le=10**6)
    held_out: int = Field(ge=1, le=10**7)
    pursuer_solver: MetaSolver = "nash"
    evader_solver: MetaSolver = "nash"
    slack: float | None = Field(default=None, gt=0.0, le=1.0)  # the maxent meta-solver's (None: no maxent)
    iterations: list[Iteration] = Field(default_factory=list, max_length=MAX_ITERATIONS)

    @model_validator(mode="before")
    @classmethod
    def _one_pair(cls, data: Any) -> Any:
        """A record of pecli 0.11 and before started from one pair: ``pursuer`` and ``evader``."""
        if isinstance(data, dict) and "pursuers" not in data and "pursuer" in data and "evader" in data:
            data = {k: v for k, v in data.items() if k not in ("pursuer", "evader")} | {
                "pursuers": [data["pursuer"]],
                "evaders": [data["evader"]],
            }
        return data

    def settings(self) -> dict:
        return self.model_dump(exclude={"iterations"})


def iteration_folder(out: Path, index: int) -> Path:
    """``OUT/iter-01``: the ``index``-th iteration (from 1); ``nash:`` of it plays its meta-game's mixture."""
    return out / f"iter-{index:02d}"


def _stored(spec: str, out: Path, folder: Path) -> str:
    """How a member is written into ``folder/nash.json``: a file inside ``out`` relative to ``folder`` (so the
    whole PSRO folder can move), any other file by its absolute path, a policy string as given."""
    path = Path(spec)
    if not path.is_file():
        return spec
    resolved = path.resolve()
    if resolved.is_relative_to(out.resolve()):
        return os.path.relpath(resolved, folder.resolve())
    return str(resolved)


def _check(job: PsroJob) -> None:
    if not 1 <= job.iterations <= MAX_ITERATIONS:
        raise PecliError(f"--iterations must be from 1 to {MAX_ITERATIONS}, not {job.iterations}")
    check_cpu_minutes(job.cpu_minutes)
    if not 0.0 < job.slack <= 1.0:
        raise PecliError(f"the maxent mixture's slack must be in (0, 1], not {job.slack:g}")
    for solver in (job.pursuer_solver, job.evader_solver):
        if solver not in META_SOLVERS:
            raise PecliError(f"no meta-solver '{solver}' (known: {', '.join(META_SOLVERS)})")
    if not job.seeds or len(set(job.seeds)) != len(job.seeds) or min(job.seeds) < 0:
        raise PecliError("--seeds: one or more different non-negative seeds")
    from pecli.match import MAX_EPISODES

    if not 1 <= job.episodes <= MAX_EPISODES or not 1 <= job.held_out <= MAX_EPISODES:
        raise PecliError(f"the meta-game's and the held-out games' episodes must be from 1 to {MAX_EPISODES:,}")
    firsts: dict[Role, Sequence[str]] = {"pursuer": job.pursuers, "evader": job.evaders}
    for role, specs in firsts.items():
        if not 1 <= len(specs) <= MAX_POPULATION:
            raise PecliError(f"PSRO starts from 1 to {MAX_POPULATION} {role}s, not {len(specs)}")
        if len({player_spec(spec) for spec in specs}) != len(specs):
            raise PecliError(f"a {role} is named twice in the population PSRO starts from")
        for spec in specs:
            resolve_policy(spec, role, job.scenario, seed=0)  # plays this game and role, or one line why not
    if job.reuse is not None:
        pairings_cache(job.reuse, META_GAME_DIR)


def _read_record(path: Path) -> PsroRecord | None:
    return read_output_record(path, PsroRecord, "PSRO record")


def _fresh_record(job: PsroJob) -> PsroRecord:
    return PsroRecord(
        pursuers=[player_spec(spec) for spec in job.pursuers],
        evaders=[player_spec(spec) for spec in job.evaders],
        scenario=job.scenario.name,
        scenario_hash=job.scenario.fingerprint(),
        cpu_minutes=job.cpu_minutes,
        seeds=list(job.seeds),
        warm=job.warm,
        episodes=job.episodes,
        held_out=job.held_out,
        pursuer_solver=job.pursuer_solver,
        evader_solver=job.evader_solver,
        slack=job.slack if "maxent" in (job.pursuer_solver, job.evader_solver) else None,
    )


def meta_game(job: PsroJob, populations: dict[Role, list[str]], report: Callable[[str], None]) -> MetaGame:
    """Every pursuer of the populations against every evader (cached in ``out/meta-game``), solved, with each
    side's mixture by the job's meta-solvers."""
    grid = pairing_results(
        job.scenario,
        populations["pursuer"],
        populations["evader"],
        job.episodes,
        META_SEEDS,
        job.out / META_GAME_DIR,
        job.workers,
        on_result=lambda r, cached: (
            None if cached else report(f"meta-game: {r.pursuer} vs {r.evader}: {r.capture_rate:.3f}")
        ),
    )
    matrix = np.array(
        [
            [grid[(player_spec(p), player_spec(e))].capture_rate for e in populations["evader"]]
            for p in populations["pursuer"]
        ]
    )
    names = {role: [f"{role}-{k}" for k in range(len(populations[role]))] for role in ROLES}
    game = solve(names["pursuer"], names["evader"], matrix)
    return with_meta_solvers(game, job.pursuer_solver, job.evader_solver, job.slack)


def take_pairings(job: PsroJob, source: Path, populations: dict[Role, list[str]], report: Callable[[str], None]) -> int:
    """Copy the pairings of the populations' meta-game that the folder ``source`` has played and ``job.out``
    lacks; report how many, and why none matched when none did."""
    keys = pairing_keys(job.scenario, populations["pursuer"], populations["evader"], job.episodes, META_SEEDS)
    copied, lacking = reuse_pairings(pairings_cache(source, META_GAME_DIR), job.out / META_GAME_DIR, keys)
    if lacking:
        hint = (
            ""
            if copied
            else f" (a tournament's pairings match when it was played on {job.scenario.name} with -n "
            f"{job.episodes} --seeds 1 by this version of pecli)"
        )
        report(f"meta-game: {copied} of the {lacking} pairings not yet played taken from {source}{hint}")
    return copied


def write_mixture(job: PsroJob, game: MetaGame, populations: dict[Role, list[str]], folder: Path) -> Path:
    """``folder/nash.json``: each side's mixture (``nash:FOLDER`` plays it)."""
    folder.mkdir(parents=True, exist_ok=True)
    specs = {
        name: _stored(spec, job.out, folder)
        for names, members in ((game.pursuers, populations["pursuer"]), (game.evaders, populations["evader"]))
        for name, spec in zip(names, members)
    }
    path = folder / NASH_FILE
    atomic_write_json(path, mixture_record(job.scenario, game, specs))
    return path


def newest_checkpoint(population: Sequence[str]) -> Path | None:
    """The last checkpoint (``.zip``) of a population, the one a warm response starts from (``None``: none)."""
    return next((Path(spec) for spec in reversed(population) if spec.lower().endswith(".zip")), None)


def _responses(
    job: PsroJob, folder: Path, populations: dict[Role, list[str]], report: Callable[[str], None]
) -> PairResult:
    """The best responses to each side of the mixture in ``folder`` (trained in ``job.workers`` processes at once)
    and the mixtures' own games: their NashConv."""
    jobs: dict[Role, ExploitJob] = {}
    for role in ROLES:
        start = newest_checkpoint(populations[opponent_of(role)]) if job.warm else None
        jobs[role] = ExploitJob(
            target=f"nash:{folder}",
            role=role,
            scenario=job.scenario,
            out=folder / f"against-{role}",
            cpu_minutes=job.cpu_minutes,
            seeds=tuple(job.seeds),
            warm_start=start,
            fresh=start is None,
            episodes=job.held_out,
        )
    return pair_result(jobs, exploit_all(list(jobs.values()), report, job.workers), folder)


def psro(job: PsroJob, report: Callable[[str], None] = lambda line: None) -> list[Iteration]:
    """Run the iterations of ``job`` not yet in ``job.out`` (continuing a stopped one) and return them all;
    :class:`PecliError` if ``job.out`` holds PSRO from other players or settings."""
    _check(job)
    job.out.mkdir(parents=True, exist_ok=True)
    path = job.out / RECORD_FILE
    with locked(job.out, "PSRO"):
        record = _fresh_record(job)
        kept = _read_record(path)
        if kept is not None:
            if kept.settings() != record.settings():
                differ = [key for key, value in record.settings().items() if kept.settings().get(key) != value]
                raise PecliError(
                    f"{job.out} holds PSRO from other players or settings (its {', '.join(differ)}); use another --out"
                )
            record = kept
        atomic_write_json(path, record.model_dump(mode="json"))
        populations: dict[Role, list[str]] = {"pursuer": list(job.pursuers), "evader": list(job.evaders)}
        if job.reuse is not None:
            take_pairings(job, job.reuse, populations, report)
        for done in record.iterations:
            for role, member in done.joined.items():
                populations[role].append(str(job.out / member))
        for index in range(len(record.iterations) + 1, job.iterations + 1):
            folder = iteration_folder(job.out, index)
            report(
                f"iteration {index}/{job.iterations}: {len(populations['pursuer'])} pursuers, "
                f"{len(populations['evader'])} evaders"
            )
            game = meta_game(job, populations, report)
            write_mixture(job, game, populations, folder)
            pair = _responses(job, folder, populations, report)
            joined: dict[Role, str] = {}
            answers: dict[Role, ExploitResult] = {"pursuer": pair.against_pursuer, "evader": pair.against_evader}
            for answered, result in answers.items():
                learner = opponent_of(answered)
                checkpoint = folder / f"against-{answered}" / result.strongest().checkpoint
                populations[learner].append(str(checkpoint))
                joined[learner] = str(checkpoint.relative_to(job.out))
            iteration = Iteration(
                value=game.mixtures_rate,
                pursuer_mixture=game.support("pursuer"),
                evader_mixture=game.support("evader"),
                best_pursuer=pair.against_evader.strongest().capture_rate,
                best_evader=pair.against_pursuer.strongest().capture_rate,
                nash_conv=pair.nash_conv,
                interval=list(pair.interval),
                joined=joined,
            )
            record = record.model_copy(update={"iterations": [*record.iterations, iteration]})
            atomic_write_json(path, record.model_dump(mode="json"))
            low, high = iteration.interval
            report(
                f"iteration {index}: NashConv {iteration.nash_conv:.3f} [{low:.3f}, {high:.3f}] (BR pursuer "
                f"{iteration.best_pursuer:.3f}, BR evader holds the pursuers to {iteration.best_evader:.3f})"
            )
        draw_nash_conv(record.iterations, job.out / CURVE_FILE)
    return list(record.iterations)


def read_psro(out: Path) -> list[Iteration]:
    """The iterations recorded in ``out`` (none: an empty list), without training anything."""
    record = _read_record(out / RECORD_FILE)
    return [] if record is None else list(record.iterations)


def draw_nash_conv(iterations: Sequence[Iteration], path: Path) -> Path | None:
    """NashConv per iteration with its 95 % interval, and what each side's response reached (PNG)."""
    if not iterations:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.arange(1, len(iterations) + 1)
    nash_conv = np.array([it.nash_conv for it in iterations])
    low, high = (np.array([it.interval[k] for it in iterations]) for k in (0, 1))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.errorbar(x, nash_conv, yerr=[nash_conv - low, high - nash_conv], marker="o", capsize=3, label="NashConv")
    ax.plot(x, [it.best_pursuer for it in iterations], "^--", label="BR pursuer vs evader mixture")
    ax.plot(x, [it.best_evader for it in iterations], "v--", label="pursuer mixture vs BR evader")
    ax.plot(x, [it.value for it in iterations], "s:", label="the mixtures against each other")
    ax.set_xlabel("PSRO iteration")
    ax.set_ylabel("capture rate / NashConv")
    ax.set_xticks(x)
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)
    return path
