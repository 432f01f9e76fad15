"""Tournaments: every pursuer against every evader (or a random sample), as batched matches.

    players = find_players(["zoo/"], scenario, baselines=True)
    pairings = schedule(players, sample=None)
    results = run_tournament(scenario, pairings, episodes=500, seeds=[0, 1, 2], out=Path("runs/tournament"))

Each pairing plays ``episodes`` games per seed as one batch (:func:`pecli.match.play_match`). Game
``i`` under seed ``s`` starts from the same state in every pairing, so the comparison is paired.
Finished pairings are cached as JSON in ``out/pairings/``: an interrupted tournament resumes,
and a grown zoo only plays its new pairings. One tournament writes ``out`` at a time (a folder
lock, :mod:`pecli.locks`), and worker processes end with their driver, whatever signal ends it.
"""

from __future__ import annotations

import json
import os
import random
import signal
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from pecli import __version__
from pecli.errors import PecliError
from pecli.io import atomic_write_json, file_digest, read_json, text_digest
from pecli.locks import locked
from pecli.match import play_match
from pecli.metagame import MetaGame, solve
from pecli.policies import resolve_policy
from pecli.policies.mix import player_label
from pecli.policies.registry import BUILTINS, family_of
from pecli.process import die_with, one_torch_thread
from pecli.records import PairingRow, TournamentRecord, validated
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario
from pecli.stats import Rating, bradley_terry, ties_with_best
from pecli.zoo import (
    LAST,
    RESUME_DIR,
    CheckpointMeta,
    ZooError,
    checkpoint_problem,
    read_metadata,
    run_of,
)

CACHE_SCHEMA = 2  # bump when the same players and seeds would play other games (2: mixed beliefs' draws)
RESULTS_FILE = "results.json"  # a tournament's pairings and ratings (pecli.reports.write_reports)
PAIRINGS_DIR = "pairings"  # a tournament's cache of played pairings, one <key>.json each (pairing_key)
MAX_PAIRING_BYTES = 1 << 16  # a cached pairing is a few hundred bytes
KEY_LENGTH = 24  # hex digits of a pairing_key

BASELINES: dict[Role, tuple[str, ...]] = {
    "pursuer": ("pure-pursuit",),
    "evader": ("random-walk", "greedy", "rash"),
}


@dataclass(frozen=True)
class Player:
    """One entrant: how to build it (``spec``), what to call it, and what identifies it for the cache."""

    name: str
    spec: str
    role: Role
    identity: str  # built-in name, class path, or the checkpoint file's content hash


@dataclass(frozen=True)
class PairingResult:
    """Outcome of one pursuer against one evader over all seeds."""

    pursuer: str
    evader: str
    episodes: int
    captures: int
    time_to_capture_mean: float
    time_to_capture_std: float  # population std over all episodes (a timeout counts 1.0)

    @property
    def capture_rate(self) -> float:
        return self.captures / self.episodes


@dataclass
class Discovery:
    """Players found under some paths, and what was passed over (with the reason)."""

    players: dict[Role, list[Player]]
    skipped: list[str]


def _playable_meta(path: Path, scenario: Scenario) -> CheckpointMeta | str:
    """The metadata of the checkpoint at ``path`` if it can play ``scenario``, else why not (reads metadata only)."""
    try:
        meta = read_metadata(path)
    except ZooError as exc:
        return str(exc)
    if problem := checkpoint_problem(path):
        return f"{path}: {problem}"
    if meta.scenario_hash != scenario.fingerprint():
        return f"{path}: trained on scenario '{meta.scenario}', not '{scenario.name}'"
    return meta


def _checkpoint_player(path: Path, scenario: Scenario, skipped: list[str]) -> Player | None:
    meta = _playable_meta(path, scenario)
    if isinstance(meta, str):
        skipped.append(meta)
        return None
    return Player(
        name=_checkpoint_name(path, meta), spec=str(path.resolve()), role=meta.role, identity=file_digest(path)
    )


def _exported_player(path: Path, scenario: Scenario, skipped: list[str]) -> Player | None:
    """An exported model (``.onnx`` with its sidecar) as a player, named after its checkpoint plus ``.onnx``."""
    from pecli.runtime import read_sidecar

    try:
        sidecar = read_sidecar(path)
        role, exported_for = sidecar["role"], sidecar["scenario"]
        run, fingerprint, model_hash = (
            sidecar["checkpoint"].get("run"),
            exported_for["fingerprint"],
            sidecar["model_sha256"],
        )
    except PecliError as exc:
        skipped.append(str(exc))
        return None
    except (KeyError, TypeError, AttributeError):
        skipped.append(f"{path}: incomplete sidecar")
        return None
    identity = file_digest(path)
    if not str(model_hash).startswith(identity):
        skipped.append(f"{path}: does not match its sidecar (damaged or changed model)")
        return None
    if fingerprint != scenario.fingerprint() or role not in ROLES:
        skipped.append(f"{path}: exported for scenario '{exported_for.get('name')}', not '{scenario.name}'")
        return None
    name = f"{run}/{role}/{path.stem}.onnx" if run else path.name
    return Player(name=name, spec=str(path.resolve()), role=role, identity=identity)


def _file_player(path: Path, scenario: Scenario, skipped: list[str]) -> Player | None:
    """A checkpoint (``.zip``) or an exported model (``.onnx``) given by its path."""
    if path.suffix.lower() == ".onnx":
        return _exported_player(path, scenario, skipped)
    return _checkpoint_player(path, scenario, skipped)


def _unique_names(players: list[Player]) -> list[Player]:
    """Players whose names collide (two runs of one name in two zoos) get as much of their path as tells them
    apart (``zoo-a/ours/pursuer/final``); the whole path only where nothing less does."""
    groups: dict[str, list[Player]] = {}
    for player in players:
        groups.setdefault(player.name, []).append(player)
    renamed: dict[str, str] = {}  # identity -> name
    for name, group in groups.items():
        if len(group) < 2:
            continue
        paths = [Path(p.spec).with_suffix("").parts for p in group]
        for depth in range(name.count("/") + 2, max(len(parts) for parts in paths) + 1):
            names = ["/".join(parts[-depth:]) for parts in paths]
            if len(set(names)) == len(names):
                break
        else:
            names = [str(Path(p.spec).with_suffix("")) for p in group]
        renamed.update({p.identity: n for p, n in zip(group, names)})
    return [replace(p, name=renamed[p.identity]) if p.identity in renamed else p for p in players]


def _checkpoint_name(path: Path, meta: CheckpointMeta) -> str:
    """A checkpoint's player name, relative to its zoo: ``run/folder/checkpoint`` (``ours/pursuer/final``,
    ``league/exploiter-evader/round-003``); the run and role of its metadata for a file outside a run folder."""
    if (run := run_of(path)) is not None:
        return f"{run.path.name}/{path.parent.name}/{path.stem}"
    return f"{meta.run}/{meta.role}/{path.stem}" if meta.run else path.stem


def find_players(
    paths: Iterable[str], scenario: Scenario, baselines: bool = False, both_sides: bool = True
) -> Discovery:
    """Players from zoo folders, run folders, checkpoint files, exported models, ``module:Class`` strings
    and policy families such as ``hj`` (which join both sides when they play both roles), in the order named.

    A folder contributes every checkpoint with metadata below it, except ``last`` and a run's durable
    state (``resume/``), copies of checkpoints; exported models (``.onnx``) join only when named.
    Checkpoints of another scenario, and files without metadata, are skipped and listed. With ``both_sides``
    a side without players is a :class:`PecliError` (else the caller checks).
    """
    players: dict[Role, list[Player]] = {role: [] for role in ROLES}
    skipped: list[str] = []
    if baselines:
        for role, names in BASELINES.items():
            players[role] += [Player(name=n, spec=n, role=role, identity=f"builtin:{n}") for n in names]
    for entry in paths:
        for player in _entry_players(entry, scenario, skipped):
            if player is not None and player.identity not in {p.identity for p in players[player.role]}:
                players[player.role].append(player)
    for role in ROLES:
        if not players[role] and both_sides:
            hint = "" if baselines else " (add --baselines to include the built-in heuristics)"
            if skipped:
                hint += f"; {len(skipped)} checkpoint(s) skipped, e.g. {skipped[0]}"
            raise PecliError(f"no {role} to play: the tournament needs at least one of each side{hint}")
        players[role] = _unique_names(players[role])
    return Discovery(players=players, skipped=skipped)


def _entry_players(entry: str, scenario: Scenario, skipped: list[str]) -> list[Player | None]:
    """The players one entry of :func:`find_players` names (``None`` for a checkpoint skipped)."""
    path = Path(entry)
    if family_of(entry) is not None or (path.is_file() and path.suffix.lower() not in (".zip", ".onnx")):
        return list(_policy_players(entry, scenario))
    if path.is_dir():
        return [_checkpoint_player(p, scenario, skipped) for p in _checkpoints_under(path)]
    if path.is_file():
        player = _file_player(path, scenario, skipped)
        if player is None:
            raise PecliError(skipped[-1])
        return [player]
    if ":" in entry or entry in BUILTINS:
        return [_class_player(entry, scenario)]
    raise PecliError(f"no such file or folder: {entry}")


def _checkpoints_under(folder: Path) -> list[Path]:
    """The checkpoints in ``folder`` and below that can be players (not ``last`` or a run's durable state)."""
    found = [p for p in sorted(folder.rglob("*.zip")) if p.stem != LAST and RESUME_DIR not in p.parts]
    if not found:
        raise PecliError(f"no checkpoints under {folder}")
    return found


def check_saved_players(entry: str, scenario: Scenario) -> None:
    """For a checkpoint, an exported model or a folder of checkpoints: :class:`PecliError` unless it gives at
    least one player of ``scenario``. Loads no network: a folder's checkpoints are read for their metadata
    up to the first good one, a single file as the tournament would list it; other entries are not checked."""
    path = Path(entry)
    if family_of(entry) is not None:
        return
    if path.is_dir():
        problems = []
        for checkpoint in _checkpoints_under(path):
            meta = _playable_meta(checkpoint, scenario)
            if not isinstance(meta, str):
                return
            problems.append(meta)
        raise PecliError(
            f"no checkpoint of scenario '{scenario.name}' under {entry} ({len(problems)} skipped, e.g. {problems[0]})"
        )
    if path.suffix.lower() in (".zip", ".onnx"):
        _entry_players(entry, scenario, [])  # one file: PecliError with the reason it cannot play


def _class_player(spec: str, scenario: Scenario) -> Player:
    if spec in BUILTINS:
        roles = BUILTINS[spec].roles
        return Player(name=spec, spec=spec, role=roles[0], identity=f"builtin:{spec}")
    for role in ROLES:
        try:
            resolve_policy(spec, role, scenario)
        except PecliError as exc:
            if "plays" in str(exc):
                continue
            raise
        return Player(name=spec, spec=spec, role=role, identity=f"class:{spec}")
    raise PecliError(f"'{spec}' plays neither role")


def _policy_players(spec: str, scenario: Scenario) -> list[Player]:
    """A policy family (``hj``, ``hj:...``) or a policy file other than a checkpoint (an HJ ``.npz``): one
    player for every role it can play, named ``<spec>/<role>``, identified by what decides its play."""
    path = Path(spec)
    if path.is_file():
        spec = str(path.resolve())
    players = []
    for role in ROLES:
        try:
            policy = resolve_policy(spec, role, scenario)
        except PecliError as exc:
            if "cannot play" in str(exc) or " plays " in str(exc):
                continue
            raise
        identity = getattr(policy, "identity", None) or f"class:{spec}"
        name = f"{path.stem if path.is_file() else player_label(spec)}/{role}"
        players.append(Player(name=name, spec=spec, role=role, identity=identity))
    if not players:
        raise PecliError(f"'{spec}' plays neither role")
    return players


def schedule(
    players: dict[Role, list[Player]], sample: int | None = None, seed: int = 0
) -> list[tuple[Player, Player]]:
    """Pairings ``(pursuer, evader)``: the full grid, or each checkpoint against ``sample`` random opponents.

    With ``sample`` (the paper's ranking, 32 there) every learned player meets ``sample`` players of
    the other side drawn without replacement (all of them if there are fewer); built-in and class
    players are only drawn as opponents.
    """
    pursuers, evaders = players["pursuer"], players["evader"]
    if sample is None:
        return [(p, e) for e in evaders for p in pursuers]
    if sample < 1:
        raise PecliError("--sample must be at least 1")
    rng = random.Random(seed)
    chosen: set[tuple[str, str]] = set()
    for role, own, other in (("pursuer", pursuers, evaders), ("evader", evaders, pursuers)):
        for player in own:
            if player.identity.startswith(("builtin:", "class:")):
                continue
            for opponent in rng.sample(other, min(sample, len(other))):
                pair = (player, opponent) if role == "pursuer" else (opponent, player)
                chosen.add((pair[0].identity, pair[1].identity))
    if not chosen:
        raise PecliError("--sample draws opponents for checkpoints only, and there are none: play the full grid")
    return [(p, e) for e in evaders for p in pursuers if (p.identity, e.identity) in chosen]


def pairing_key(scenario: Scenario, pursuer: Player, evader: Player, episodes: int, seeds: Sequence[int]) -> str:
    """Cache key of a pairing: everything that decides its outcome."""
    text = json.dumps(
        [__version__, CACHE_SCHEMA, scenario.fingerprint(), pursuer.identity, evader.identity, episodes, list(seeds)]
    )
    return text_digest(text, KEY_LENGTH)


def play_pairing(
    scenario: Scenario, pursuer: Player, evader: Player, episodes: int, seeds: Sequence[int]
) -> PairingResult:
    """Play ``episodes`` batched games per seed; both policies act on the whole batch."""
    captured, times = [], []
    p = resolve_policy(pursuer.spec, "pursuer", scenario)
    e = resolve_policy(evader.spec, "evader", scenario)
    one_torch_thread()
    for seed in seeds:  # play_match reseeds both policies from the seed
        result, _ = play_match(scenario, p, e, episodes=episodes, seed=seed)
        captured.append(result.captured)
        times.append(result.time_to_capture)
    all_captured, all_times = np.concatenate(captured), np.concatenate(times)
    return PairingResult(
        pursuer=pursuer.name,
        evader=evader.name,
        episodes=int(all_captured.size),
        captures=int(all_captured.sum()),
        time_to_capture_mean=float(all_times.mean()),
        time_to_capture_std=float(all_times.std()),
    )


def _cached(path: Path, pursuer: Player, evader: Player) -> PairingResult | None:
    """A cached pairing result, or ``None`` if there is none or it is not what a pairing can give (then it is
    played again)."""
    if not path.is_file():
        return None
    try:
        data = read_json(path, "cached pairing", max_bytes=MAX_PAIRING_BYTES)
        if not isinstance(data, dict):
            return None
        row = validated(PairingRow, {**data, "pursuer": pursuer.name, "evader": evader.name}, path, "cached pairing")
    except PecliError:
        return None
    return PairingResult(**row.model_dump())


def pairings_cache(folder: Path, *within: str) -> Path:
    """The cache of played pairings in ``folder``: a tournament's ``--out`` (``folder/pairings``) or, for each
    name in ``within``, ``folder/NAME/pairings`` (where a tournament is run inside another job's folder);
    :class:`PecliError` if it holds none of them."""
    places = [Path(PAIRINGS_DIR), *(Path(name) / PAIRINGS_DIR for name in within)]
    for place in places:
        if (folder / place).is_dir():
            return folder / place
    raise PecliError(f"{folder} holds no played pairings (no {' or '.join(f'{p}/' for p in places)} in it)")


def reuse_pairings(found: Path, out: Path, keys: Iterable[str]) -> tuple[int, int]:
    """Copy the pairings ``keys`` (:func:`pairing_keys`) that ``out``'s cache (a :func:`run_tournament` output)
    lacks from another cache of played pairings, ``found`` (:func:`pairings_cache`); return how many were copied
    and how many were lacking.

    A pairing's file name is its key, a digest of everything that decides its games (scenario, players, games,
    seeds, pecli version), so a copied result is used only by an identical pairing; what it holds is checked
    when it is read (:func:`_cached`). Files are read as a pairing's JSON, bounded in size; links and files
    that are no such JSON are left.
    """
    cache = out / PAIRINGS_DIR
    cache.mkdir(parents=True, exist_ok=True)
    lacking = sorted({key for key in keys if not (cache / f"{key}.json").is_file()})
    copied = 0
    for key in lacking:
        path = found / f"{key}.json"
        if path.is_symlink() or not path.exists():
            continue
        try:
            data = read_json(path, "cached pairing", max_bytes=MAX_PAIRING_BYTES)
        except PecliError:
            continue  # damaged or too large: played again
        atomic_write_json(cache / f"{key}.json", data)
        copied += 1
    return copied, len(lacking)


def _worker_init(driver: int) -> None:
    """A pairing worker: it ends with its ``driver`` (:func:`pecli.process.die_with`) and ignores SIGINT, so
    that the driver handles Ctrl-C and stops it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with(driver)


@contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` spawned processes that never outlive this one.

    Each worker ends when this process dies, even by SIGKILL (:func:`_worker_init`). An exception in
    the ``with`` block (Ctrl-C, SIGTERM turned into ``KeyboardInterrupt``, an error) stops the workers
    at once instead of waiting for their pairings; a normal exit waits for them.
    """
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=get_context("spawn"), initializer=_worker_init, initargs=(os.getpid(),)
    )
    try:
        yield pool
    except BaseException:
        processes = list(getattr(pool, "_processes", None) or {})  # pids; Python 3.14 has terminate_workers()
        pool.shutdown(wait=False, cancel_futures=True)
        for pid in processes:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        pool.shutdown(wait=True)
        raise
    pool.shutdown(wait=True)


PairingJob = tuple[Scenario, Player, Player, int, list[int]]
"""The arguments of :func:`play_pairing`: scenario, pursuer, evader, episodes per seed, seeds."""

PairingExecutor = Callable[[Sequence[PairingJob]], Iterable[tuple[int, PairingResult | PecliError]]]
"""Plays pairing jobs anywhere and yields ``(index of the job, its result or its PecliError)`` as each ends,
in any order. :func:`local_executor` plays them on this machine; ``pecli experiment`` passes one that plays
them as Ray tasks."""


def _play_job(job: PairingJob) -> PairingResult:
    return play_pairing(*job)


def local_executor(workers: int = 1) -> PairingExecutor:
    """Pairings played in this process (``workers`` 1) or in a pool of ``workers`` spawned processes."""

    def execute(jobs: Sequence[PairingJob]) -> Iterator[tuple[int, PairingResult | PecliError]]:
        if workers > 1 and len(jobs) > 1:
            with worker_pool(workers) as pool:
                futures = {pool.submit(_play_job, job): index for index, job in enumerate(jobs)}
                for future in as_completed(futures):
                    try:
                        yield futures[future], future.result()
                    except PecliError as exc:  # keep playing the others; each finished pairing is cached
                        yield futures[future], exc
        else:
            for index, job in enumerate(jobs):
                try:
                    yield index, _play_job(job)
                except PecliError as exc:
                    yield index, exc

    return execute


@dataclass
class TournamentResults:
    """Everything a tournament produced: pairings, ratings, the players and the settings."""

    scenario: Scenario
    players: dict[Role, list[Player]]
    pairings: list[PairingResult]
    ratings: list[Rating]
    episodes: int
    seeds: list[int]

    def grid(self) -> dict[tuple[str, str], PairingResult]:
        return {(r.pursuer, r.evader): r for r in self.pairings}

    def best_in_row(self) -> set[tuple[str, str]]:
        """Pairings whose pursuer is the best against that evader or ties with it (z-test, p > 0.05)."""
        marked: set[tuple[str, str]] = set()
        by_evader: dict[str, list[PairingResult]] = {}
        for result in self.pairings:
            by_evader.setdefault(result.evader, []).append(result)
        for row in by_evader.values():
            ties = ties_with_best([r.captures for r in row], [r.episodes for r in row])
            marked |= {(r.pursuer, r.evader) for r, tie in zip(row, ties) if tie}
        return marked

    def meta_game(self) -> MetaGame:
        """The zoo's meta-game (:mod:`pecli.metagame`) solved: every pursuer against every evader;
        :class:`PecliError` if a pairing was not played (a ``--sample`` tournament)."""
        grid = self.grid()
        pursuers = [p.name for p in self.players["pursuer"]]
        evaders = [e.name for e in self.players["evader"]]
        missing = [(p, e) for p in pursuers for e in evaders if (p, e) not in grid]
        if missing:
            raise PecliError(
                f"the Nash equilibrium needs every pairing; {len(missing)} were not played "
                f"(e.g. {missing[0][0]} vs {missing[0][1]}): leave out --sample"
            )
        matrix = np.array([[grid[p, e].capture_rate for e in evaders] for p in pursuers])
        return solve(pursuers, evaders, matrix)

    def to_json(self) -> dict[str, Any]:
        best = self.best_in_row()
        paths = {p.name: p.spec for role in ROLES for p in self.players[role]}
        return {
            "scenario": self.scenario.name,
            "scenario_hash": self.scenario.fingerprint(),
            "episodes_per_seed": self.episodes,
            "seeds": self.seeds,
            "pairings": [
                {**asdict(r), "capture_rate": r.capture_rate, "best_in_row": (r.pursuer, r.evader) in best}
                for r in self.pairings
            ],
            "ratings": [
                {**asdict(r), "role": _role_of(self.players, r.name), "spec": paths[r.name]} for r in self.ratings
            ],
        }


def _role_of(players: dict[Role, list[Player]], name: str) -> Role:
    return "pursuer" if any(p.name == name for p in players["pursuer"]) else "evader"


def rate(players: dict[Role, list[Player]], pairings: Sequence[PairingResult]) -> list[Rating]:
    """Bradley–Terry ratings of every player that played, from all its results (a capture is a pursuer's win)."""
    played = {r.pursuer for r in pairings} | {r.evader for r in pairings}
    names = [p.name for role in ROLES for p in players[role] if p.name in played]
    index = {name: i for i, name in enumerate(names)}
    results = [(index[r.pursuer], index[r.evader], r.captures, r.episodes) for r in pairings]
    return sorted(bradley_terry(names, results), key=lambda r: -r.elo)


def run_tournament(
    scenario: Scenario,
    players: dict[Role, list[Player]],
    pairings: Sequence[tuple[Player, Player]],
    episodes: int,
    seeds: Sequence[int],
    out: Path,
    workers: int = 1,
    on_result: Callable[[PairingResult, bool], None] | None = None,
    executor: PairingExecutor | None = None,
) -> TournamentResults:
    """Play every pairing not yet cached in ``out/pairings``; ``on_result(result, was_cached)`` reports each.

    ``executor`` plays the pairings not cached (default: :func:`local_executor` with ``workers``).
    ``out`` is locked while the tournament runs: :class:`~pecli.locks.FolderLocked` if another process
    is writing it.
    """
    cache = out / PAIRINGS_DIR
    cache.mkdir(parents=True, exist_ok=True)
    with locked(out, "tournament output"):
        results: dict[str, PairingResult] = {}
        todo: list[tuple[str, PairingJob]] = []
        for pursuer, evader in pairings:
            key = pairing_key(scenario, pursuer, evader, episodes, seeds)
            result = _cached(cache / f"{key}.json", pursuer, evader)
            if result is not None:
                results[key] = result
                if on_result is not None:
                    on_result(result, True)
            else:
                todo.append((key, (scenario, pursuer, evader, episodes, list(seeds))))

        def finish(key: str, result: PairingResult) -> None:
            atomic_write_json(cache / f"{key}.json", asdict(result))
            results[key] = result
            if on_result is not None:
                on_result(result, False)

        failures: list[str] = []
        play = executor if executor is not None else local_executor(workers)
        outcomes = iter(play([job for _, job in todo]))
        try:
            for index, outcome in outcomes:
                if isinstance(outcome, PecliError):
                    failures.append(str(outcome))
                else:
                    finish(todo[index][0], outcome)
        finally:  # an exception here (Ctrl-C, SIGTERM) stops the executor's workers now, not when collected
            if (close := getattr(outcomes, "close", None)) is not None:
                close()
        if failures:
            more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
            raise PecliError(f"{failures[0]}{more}; the pairings that finished are cached for --resume")
        ordered = [results[pairing_key(scenario, p, e, episodes, seeds)] for p, e in pairings]
        return TournamentResults(
            scenario=scenario,
            players=players,
            pairings=ordered,
            ratings=rate(players, ordered),
            episodes=episodes,
            seeds=list(seeds),
        )


PLAYER_FILES = (".zip", ".onnx", ".npz")  # checkpoints, exported models, HJ solutions


def player_spec(policy: str | Path) -> str:
    """How a tournament names a player's ``spec``: a player file (a checkpoint ``.zip``, an exported ``.onnx``, an
    HJ ``.npz``) by its resolved path, anything else as given (a policy string such as ``greedy``)."""
    return str(Path(policy).resolve()) if str(policy).lower().endswith(PLAYER_FILES) else str(policy)


def _grid_players(
    scenario: Scenario, pursuers: Sequence[str | Path], evaders: Sequence[str | Path]
) -> dict[Role, list[Player]]:
    """The players of :func:`pairing_results`; :class:`PecliError` for one that cannot play its side."""
    discovery = find_players([str(p) for p in [*pursuers, *evaders]], scenario, baselines=True)
    found = discovery.players
    wanted = {"pursuer": {player_spec(p) for p in pursuers}, "evader": {player_spec(e) for e in evaders}}
    players: dict[Role, list[Player]] = {role: [p for p in found[role] if p.spec in wanted[role]] for role in found}
    missing = [(spec, role) for role in ROLES for spec in sorted(wanted[role] - {p.spec for p in players[role]})]
    if missing:
        why = f" ({discovery.skipped[0]})" if discovery.skipped else ""
        raise PecliError(f"{missing[0][0]} cannot play {missing[0][1]} in {scenario.name}{why}")
    return players


def pairing_keys(
    scenario: Scenario,
    pursuers: Sequence[str | Path],
    evaders: Sequence[str | Path],
    episodes: int,
    seeds: Sequence[int],
) -> list[str]:
    """The cache keys of every pursuer against every evader, as :func:`pairing_results` would play them."""
    players = _grid_players(scenario, pursuers, evaders)
    return [pairing_key(scenario, p, e, episodes, seeds) for p in players["pursuer"] for e in players["evader"]]


def pairing_results(
    scenario: Scenario,
    pursuers: Sequence[str | Path],
    evaders: Sequence[str | Path],
    episodes: int,
    seeds: Sequence[int],
    out: Path,
    workers: int = 1,
    on_result: Callable[[PairingResult, bool], None] | None = None,
) -> dict[tuple[str, str], PairingResult]:
    """Every pursuer against every evader, each given as a checkpoint path or a policy string.

    The games are a :func:`run_tournament` cached in ``out`` (a second call plays only new pairings).
    Returns each pairing's result keyed by ``(player_spec(pursuer), player_spec(evader))``.
    """
    players = _grid_players(scenario, pursuers, evaders)
    pairings = [(p, e) for p in players["pursuer"] for e in players["evader"]]
    grid = run_tournament(scenario, players, pairings, episodes, seeds, out, workers, on_result).grid()
    return {(p.spec, e.spec): grid[(p.name, e.name)] for p, e in pairings}


def read_results(path: Path) -> TournamentRecord:
    """A tournament's ``results.json`` (``path`` itself, or ``path/results.json`` for its folder), validated;
    :class:`PecliError` in one line if it is not one."""
    path = path / RESULTS_FILE if path.is_dir() else path
    return validated(TournamentRecord, read_json(path, "tournament's results"), path, "tournament's results")


def tournament_ratings(zoo: Path) -> dict[str, dict[str, Any]]:
    """Ratings of checkpoints from the newest readable tournament under ``zoo`` (``**/results.json``).

    Ratings of different tournaments sit on different scales, so only one tournament is used; a file that is no
    tournament's results (damaged, or a rating of NaN) is passed over. Keys are resolved checkpoint paths, and
    ``role:spec`` for players that are not files (a policy string such as ``random-walk`` can play both roles).
    """
    for results in sorted(zoo.rglob(RESULTS_FILE), key=lambda p: p.stat().st_mtime, reverse=True):
        if results.is_symlink() or not results.is_file():
            continue
        try:
            record = read_results(results)
        except PecliError:
            continue
        found = {}
        for rating in record.ratings:
            entry = {**rating.model_dump(), "results": str(results)}
            spec = Path(rating.spec)
            if spec.suffix == ".zip":
                path = spec if spec.is_absolute() else results.parent / spec
                try:
                    found[str(path.resolve())] = {**entry, "spec": str(path)}
                except (OSError, RuntimeError):  # a link loop, or a path too long for this system
                    continue
            else:  # a built-in, family or module:Class player, keyed by role and policy string
                found[f"{rating.role}:{rating.spec}"] = entry
        return found
    return {}
