"""The Hamilton–Jacobi baseline: solver cost and accuracy, what made the old players weak, capture matrices, Table II.

    python benchmarks/bench_hj.py solve            # solve time, CPU, peak memory, accuracy of every model
    python benchmarks/bench_hj.py causes           # the old players' weakness, one suspected cause at a time
    python benchmarks/bench_hj.py matrix --pursuer P.zip --evader E.zip    # full and partial observation
        [--full-pursuer P.zip --full-evader E.zip]                        # players of the full-information game
    python benchmarks/bench_hj.py table2 --pursuer P.zip --evader E.zip    # Table II by the documented commands
    python benchmarks/bench_hj.py ratings [--full-pursuer P.zip ...]        # how the hj evader rates its inputs
    python benchmarks/bench_hj.py solve --quick    # small grids and horizons, a smoke run

``solve``: every solve runs in a fresh process on one thread (OMP_NUM_THREADS=1, XLA on one
thread). Peak memory is the largest total of live NumPy/SciPy allocations during the solve
(``tracemalloc``); for hj-reachability, whose XLA buffers the tracer does not see, the growth of
the process's maximum resident set during the solve. Times are the median of ``--repeats``
solves for rel4d (one solve for the larger models); "CPU" is the process's CPU time. Accuracy is
measured on 20 000 random states (relative positions in the arena's middle, |r_i| ≤ 7 m; relative
velocities within the limits) against the closed form of the equal-acceleration game: the discrete-time one for the
NumPy solver, which plays the game's dt, and the continuous-time one for hj-reachability, which
solves the PDE. rel6d and abs8d have no closed form (they clip each player's speed; abs8d has
walls), so they get no accuracy columns.

``causes``: under full observation (both sensor ranges 30 m), 500 games per pairing (seed 0),
each row changes one thing of the players found weak before (rel4d, the default grid, the
gradient rule): the grid, the horizon, the model (rel6d keeps each player's speed limit, abs8d the
walls), the rule that turns the value into inputs. "chase" is the rule those players fell back
on (full acceleration along the sign of ∂V/∂r of the default rel4d value, per axis: a lead
pursuit towards the closest approach, or a flight from it).

``matrix``: the default ``hj`` players (abs8d) and the others (``hj:model=rel4d``, the heuristics,
"chase", the learned checkpoints given) in a capture matrix of 500 games per cell (seed 0), under
full observation (sensor ranges 30 m; a learned player keeps the 3.75 m sensor it was trained
with, since a checkpoint only plays the game it learned, while its opponent sees it everywhere;
``--full-pursuer``/``--full-evader`` add players trained on ``point_mass_full.yaml``, which see
everywhere too) and under ``point_mass.yaml`` (3.75 m). ``table2`` runs the command sequence of docs/hj.md
(``pecli hj solve``, ``pecli tournament``, ``pecli hj table``) and prints the table beside the paper's.

``ratings``: under full observation, 500 games per cell (seed 0), the ``hj`` evader with each way of
rating an input over the pursuer's nine (the worst, the average, blends, the best outcome it leaves)
against the pursuers that do not catch it every time: chase, the interceptor, ``hj:model=rel4d``,
pure pursuit and the learned ``--full-pursuer`` checkpoints.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import numpy as np  # noqa: E402

from pecli.hj import Problem, Solution, solve_cached  # noqa: E402
from pecli.hj.oracle import continuous_value, discrete_value  # noqa: E402
from pecli.hj.reachability import available, solve_with_hj_reachability  # noqa: E402
from pecli.hj.solver import solve  # noqa: E402
from pecli.match import play_match  # noqa: E402
from pecli.policies import resolve_policy  # noqa: E402
from pecli.policies.hj import INPUTS, HJPolicy, choose  # noqa: E402
from pecli.scenario import Scenario, load_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EPISODES = 500
PAPER_TABLE_II = {
    ("optimal control", "optimal control"): 0.47,
    ("optimal control", "ours"): 0.50,
    ("ours", "optimal control"): 0.83,
    ("ours", "ours"): 0.80,
}


# ---------------------------------------------------------------------- solve
def accuracy(problem: Problem, values: np.ndarray) -> dict[str, float]:
    """Sign agreement and mean |error| (m) against both closed forms, on 20 000 random rel4d states."""
    rng = np.random.default_rng(1)
    r, w = rng.uniform(-7.0, 7.0, (20_000, 2)), rng.uniform(-5.0, 5.0, (20_000, 2))
    zeros = np.zeros_like(r)
    solved = problem.grid.interpolate(values, problem.grid.points(zeros, zeros, r, w))
    game = problem.game
    out = {}
    for name, exact in (
        ("discrete", discrete_value(r, w, problem.steps, game.dt, game.capture_distance)),
        ("continuous", continuous_value(r, w, problem.steps * game.dt, game.capture_distance)),
    ):
        out[f"sign_{name}"] = float(np.mean((solved <= 0) == (exact <= 0)))
        out[f"error_{name}"] = float(np.mean(np.abs(solved - exact)))
    return out


def one(config: str, model: str, sizes: tuple[int, int], steps: int | None, backend: str) -> dict:
    """Solve once in this process; seconds, CPU seconds, peak memory growth and accuracy."""
    scenario = load_scenario(config)
    problem = Problem.for_scenario(scenario, model, sizes, steps=steps, backend=backend)  # type: ignore[arg-type]
    problem.grid  # noqa: B018
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if backend == "numpy":
        tracemalloc.start()
    start, cpu = time.perf_counter(), time.process_time()
    values = solve_with_hj_reachability(problem) if backend == "hj-reachability" else solve(problem)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    if backend == "numpy":
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    else:
        peak = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024  # KiB -> MiB
    result = {
        "backend": backend,
        "model": model,
        "grid": problem.grid.describe(),
        "nodes": problem.grid.size,
        "steps": problem.steps,
        "seconds": seconds,
        "cpu": cpu_seconds,
        "peak_mb": peak,
        "capture_share": float(np.mean(values <= 0)),
    }
    if model == "rel4d":
        result |= accuracy(problem, values)
    return result


def measure(config: str, model: str, sizes: tuple[int, int], steps: int | None, backend: str, repeats: int) -> dict:
    """Median over ``repeats`` fresh processes."""
    runs = []
    for _ in range(repeats):
        command = [sys.executable, __file__, "--one", config, model, f"{sizes[0]},{sizes[1]}", str(steps or 0), backend]
        done = subprocess.run(command, capture_output=True, text=True, check=True)
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    best = dict(runs[0])
    for key in ("seconds", "cpu", "peak_mb"):
        best[key] = statistics.median(run[key] for run in runs)
    best["runs"] = repeats
    return best


def solve_table(args: argparse.Namespace) -> None:
    steps = 20 if args.quick else None
    cases = [  # (backend, model, sizes, repeats)
        ("numpy", "rel4d", (41, 21) if not args.quick else (21, 11), args.repeats),
        ("numpy", "rel4d", (81, 21) if not args.quick else (41, 11), args.repeats),
        ("numpy", "rel6d", (21, 11) if not args.quick else (11, 5), 1),
        ("numpy", "rel6d", (41, 11) if not args.quick else (21, 5), 1),
        ("numpy", "abs8d", (11, 5) if not args.quick else (7, 3), 1),
        ("numpy", "abs8d", (15, 5) if not args.quick else (9, 3), 1),
        ("numpy", "rel4d", (21, 11), args.repeats),  # the grid hj-reachability solves below
    ]
    if available():
        cases.append(("hj-reachability", "rel4d", (21, 11), 1))
    else:
        print('hj-reachability is not installed (pip install "pecli[hj]"): its row is skipped', file=sys.stderr)
    results = []
    for backend, model, sizes, repeats in cases:
        results.append(measure(args.config, model, sizes, steps, backend, repeats))
        print(f"done: {backend} {model} {results[-1]['grid']}: {results[-1]['seconds']:.1f} s", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"scenario {args.config}, {platform.machine()}, numpy {np.__version__}, one thread per solve")
    print(
        "| backend | model | grid | nodes | steps | solve s | CPU s | peak MB | capture share | runs "
        "| sign vs discrete | error vs discrete (m) | sign vs continuous | error vs continuous (m) |"
    )
    print("| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in results:
        exact = (
            [
                f"{r[k]:.4f}" if k.startswith("sign") else f"{r[k]:.3f}"
                for k in ("sign_discrete", "error_discrete", "sign_continuous", "error_continuous")
            ]
            if "sign_discrete" in r
            else ["-"] * 4
        )
        print(
            f"| {r['backend']} | {r['model']} | {r['grid']} | {r['nodes']:,} | {r['steps']} | {r['seconds']:.2f} "
            f"| {r['cpu']:.2f} | {r['peak_mb']:.0f} | {r['capture_share']:.3f} | {r['runs']} | "
            + " | ".join(exact)
            + " |"
        )
    if results[-1]["backend"] == "hj-reachability":
        numpy_run, jax_run = results[-2:]
        print(
            f"\non {numpy_run['grid']}: numpy {jax_run['seconds'] / numpy_run['seconds']:.0f}x faster than "
            f"hj-reachability (CPU {jax_run['cpu'] / numpy_run['cpu']:.0f}x); mean error "
            f"{numpy_run['error_discrete']:.3f} m (vs the discrete closed form) against "
            f"{jax_run['error_continuous']:.3f} m (hj-reachability vs the continuous one)"
        )


# ---------------------------------------------------------------------- players
def seeing(scenario: Scenario, roles: tuple[str, ...] = ("pursuer", "evader")) -> Scenario:
    """``scenario`` with the sensors of ``roles`` at 30 m: they see the whole arena."""
    update = {}
    for role in roles:
        agent = scenario.agent(role)
        update[role] = agent.model_copy(update={"sensor": agent.sensor.model_copy(update={"range": 30.0})})
    return scenario.model_copy(update=update)


class GradientRule(HJPolicy):
    """The first HJ players: per axis, full input along the sign of ∂V/∂v (read where the positions
    will be after this step), and where that gradient is flat (≤ 1e-3 s on both axes) along the sign of ∂V/∂r.
    rel4d and rel6d only (their last axis per half is the relative position)."""

    name = "hj-gradient"
    chase_only = False  # True: the flat-gradient rule everywhere ("chase")

    def _act(self, view):
        opp_pos, opp_vel = self._estimate(view)
        dt = self.scenario.dt
        own_next, opp_next = view.own_pos + dt * view.own_vel, opp_pos + dt * opp_vel
        if self.role == "pursuer":
            points = self.grid.points(own_next, view.own_vel, opp_next, opp_vel)
        else:
            points = self.grid.points(opp_next, opp_vel, own_next, view.own_vel)
        half = len(self.grid.x_axes)
        goal = -1.0 if self.role == "pursuer" else 1.0  # the pursuer lowers V
        velocity_sign = -1.0 if self.grid.model == "rel4d" and self.role == "pursuer" else 1.0  # w = v_e - v_p
        position_sign = -1.0 if self.role == "pursuer" else 1.0  # r = e - p
        drive = goal * velocity_sign * self._gradient(points, self.grid.velocity_axes(self.role))
        flat = np.max(np.abs(drive), axis=1) <= 1e-3
        if self.chase_only:
            flat[:] = True
        drive[flat] = goal * position_sign * self._gradient(points[flat], (half - 1, 2 * half - 1))
        return np.sign(drive)

    def _gradient(self, points: np.ndarray, axes: tuple[int, int]) -> np.ndarray:
        """Central differences of the interpolated value along ``axes``, one node apart (one-sided at the edges)."""
        out = np.empty((points.shape[0], 2))
        points = np.clip(points, [a.low for a in self.grid.axes], [a.high for a in self.grid.axes])
        for j, k in enumerate(axes):
            axis = self.grid.axes[k]
            ahead, behind = points.copy(), points.copy()
            ahead[:, k] = np.minimum(points[:, k] + axis.spacing, axis.high)
            behind[:, k] = np.maximum(points[:, k] - axis.spacing, axis.low)
            values = self.solution.values
            out[:, j] = (self.grid.interpolate(values, ahead) - self.grid.interpolate(values, behind)) / (
                ahead[:, k] - behind[:, k]
            )
        return out


class RatesEstimates(HJPolicy):
    """The outcome rule also where the opponent is unseen: the estimate rated as if it were the state."""

    def _act(self, view):
        opp_pos, opp_vel = self._estimate(view)
        own = np.concatenate([view.own_pos, view.own_vel], axis=1).T
        opp = np.concatenate([opp_pos, opp_vel], axis=1).T
        scores, distances = self.outcomes(*((own, opp) if self.role == "pursuer" else (opp, own)))
        if self.role == "pursuer":
            return INPUTS[choose(scores.mean(axis=2), distances.mean(axis=2))]
        return INPUTS[self._evader_choice(scores, distances)]


class KeepsEstimates(HJPolicy):
    """An estimate within the player's own sensing range stays where it is."""

    def _out_of_sight(self, view, estimate):
        return estimate


class Chase(GradientRule):
    """ "chase": the old players' fallback everywhere (needs a rel4d or rel6d solution)."""

    name = "chase"
    chase_only = True


def solution_for(
    scenario: Scenario,
    model: str,
    sizes: tuple[int, int] | None = None,
    steps: int | None = None,
) -> Solution:
    """The cached solution of that problem (solved and cached if missing)."""
    problem = Problem.for_scenario(scenario, model, sizes, steps=steps)  # type: ignore[arg-type]
    started = time.process_time()
    solution, path, reused = solve_cached(problem, scenario.name)
    if not reused:
        print(f"solved {problem.describe()} in {time.process_time() - started:.0f} CPU s: {path}", file=sys.stderr)
    return solution


def rate(scenario: Scenario, pursuer, evader, episodes: int, seed: int = 0) -> tuple[float, float]:
    result, _ = play_match(scenario, pursuer, evader, episodes=episodes, seed=seed)
    return result.capture_rate, result.time_to_capture_mean


# ---------------------------------------------------------------------- causes
def causes(args: argparse.Namespace) -> None:
    base = load_scenario("point_mass")
    full = seeing(base)
    default = solution_for(base, "rel4d")
    variants = [  # (label, model, sizes, steps, rule)
        ("before: rel4d 81,21, T = 100, gradient rule", "rel4d", None, None, GradientRule),
        ("finer grid: rel4d 161,41", "rel4d", (161, 41), None, GradientRule),
        ("shorter horizon: rel4d T = 30", "rel4d", None, 30, GradientRule),
        ("longer horizon: rel4d T = 300", "rel4d", None, 300, GradientRule),
        ("speed limits: rel6d 41,11", "rel6d", None, None, GradientRule),
        ("the input rule: rel4d, outcome rule", "rel4d", None, None, HJPolicy),
        ("speed limits and rule: rel6d, outcome rule", "rel6d", None, None, HJPolicy),
        ("walls: abs8d 15,5, outcome rule (now the default)", "abs8d", None, None, HJPolicy),
        ("walls, coarser: abs8d 11,5", "abs8d", (11, 5), None, HJPolicy),
        ("walls, coarsest: abs8d 9,3, T = 40 (the tests' grid)", "abs8d", (9, 3), 40, HJPolicy),
    ]
    columns = ["hj vs hj", "chase vs hj", "pure-pursuit vs hj", "hj vs chase", "hj vs greedy"]
    rows = []
    for label, model, sizes, steps, rule in variants:
        solution = solution_for(base, model, sizes, steps)

        def player(role, solution=solution, rule=rule):
            return rule(full, role, solution)

        pairings = [
            (player("pursuer"), player("evader")),
            (Chase(full, "pursuer", default), player("evader")),
            (resolve_policy("pure-pursuit", "pursuer", full), player("evader")),
            (player("pursuer"), Chase(full, "evader", default)),
            (player("pursuer"), resolve_policy("greedy", "evader", full)),
        ]
        rows.append((label, [rate(full, p, e, args.episodes) for p, e in pairings]))
        print(f"done: {label}", file=sys.stderr)
    print(f"full observation, capture rate (time-to-capture / T), {args.episodes} games per cell, seed 0\n")
    print("| players | " + " | ".join(columns) + " |")
    print("| --- |" + " ---: |" * len(columns))
    for label, cells in rows:
        print(f"| {label} | " + " | ".join(f"{r:.3f} ({t:.2f})" for r, t in cells) + " |")

    # partial observation (point_mass.yaml): the two rules for an unseen opponent, one at a time
    arena = solution_for(base, "abs8d")
    greedy = resolve_policy("greedy", "evader", base)
    pairings = [
        ("hj vs hj", HJPolicy(base, "pursuer", arena), HJPolicy(base, "evader", arena)),
        ("hj vs greedy", HJPolicy(base, "pursuer", arena), greedy),
        (
            "hj vs an hj evader that rates its estimate",
            HJPolicy(base, "pursuer", arena),
            RatesEstimates(base, "evader", arena),
        ),
        ("an hj pursuer that rates its estimate vs greedy", RatesEstimates(base, "pursuer", arena), greedy),
        (
            "an hj pursuer that keeps its estimate in sight vs hj",
            KeepsEstimates(base, "pursuer", arena),
            HJPolicy(base, "evader", arena),
        ),
        ("an hj pursuer that keeps its estimate in sight vs greedy", KeepsEstimates(base, "pursuer", arena), greedy),
    ]
    print(f"\npoint_mass.yaml (sensor ranges 3.75 m), abs8d 15,5, {args.episodes} games per cell, seed 0\n")
    print("| pursuer vs evader | capture (time-to-capture / T) |")
    print("| --- | ---: |")
    for label, pursuer, evader in pairings:
        capture, time_to_capture = rate(base, pursuer, evader, args.episodes)
        print(f"| {label} | {capture:.3f} ({time_to_capture:.2f}) |")


# ---------------------------------------------------------------------- the evader's rating
class Rating(HJPolicy):
    """The ``hj`` evader with another rating of its inputs over the pursuer's nine (``scores`` axis 1)."""

    def __init__(self, scenario: Scenario, solution: Solution, rate) -> None:
        super().__init__(scenario, "evader", solution)
        self.rate = rate

    def _evader_choice(self, scores: np.ndarray, distances: np.ndarray) -> np.ndarray:
        return choose(-self.rate(scores), -distances.mean(axis=1))


def _softmax_mean(scores: np.ndarray, temperature: float) -> np.ndarray:
    weights = np.exp((scores - scores.max(axis=1, keepdims=True)) / temperature)
    return (weights * scores).sum(axis=1) / weights.sum(axis=1)


RATINGS = {
    "worst": lambda s: s.min(axis=1),
    "average (rules 2)": lambda s: s.mean(axis=1),
    "half average, half best": lambda s: 0.5 * s.mean(axis=1) + 0.5 * s.max(axis=1),
    "softmax-weighted, 5 steps": lambda s: _softmax_mean(s, 5.0),
    "best (now)": lambda s: s.max(axis=1),
}


def ratings(args: argparse.Namespace) -> None:
    base = load_scenario("point_mass")
    full = seeing(base)
    arena = solution_for(full, "abs8d")
    pursuers = [
        ("chase", "chase"),
        ("interceptor", "interceptor"),
        ("hj rel4d", "hj:model=rel4d"),
        ("pure-pursuit", "pure-pursuit"),
    ]
    pursuers += [(f"learned full ({Path(p).parent.parent.name})", p) for p in args.full_pursuer]
    print(f"full observation: capture rate of the hj evader, {args.episodes} games per cell, seed 0\n")
    print("| evader's rating | " + " | ".join(label for label, _ in pursuers) + " |")
    print("| --- |" + " ---: |" * len(pursuers))
    for name, rule in RATINGS.items():
        cells = [
            rate(full, make_player(spec, "pursuer", full, base, 0), Rating(full, arena, rule), args.episodes)[0]
            for _, spec in pursuers
        ]
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cells) + " |", flush=True)


# ---------------------------------------------------------------------- matrices
def players(args: argparse.Namespace, base: Scenario) -> dict[str, list[tuple[str, str]]]:
    """``(label, spec)`` per role; "chase" stands for the old fallback rule on the default rel4d solution."""
    out = {
        "pursuer": [
            ("hj", "hj"),
            ("hj rel4d", "hj:model=rel4d"),
            ("chase", "chase"),
            ("pure-pursuit", "pure-pursuit"),
            ("random-walk", "random-walk"),
            ("interceptor", "interceptor"),
        ],
        "evader": [
            ("hj", "hj"),
            ("hj rel4d", "hj:model=rel4d"),
            ("chase (flee)", "chase"),
            ("greedy", "greedy"),
            ("random-walk", "random-walk"),
            ("rash", "rash"),
            ("wall-runner", "wall-runner"),
        ],  # circler and blindside flee like greedy from a point mass
    }
    for role, path in (("pursuer", args.pursuer), ("evader", args.evader)):
        if path:
            out[role].append((f"learned ({Path(path).parent.parent.name})", str(path)))
    return out


def full_players(args: argparse.Namespace) -> dict[str, list[tuple[str, str]]]:
    """The learned players trained under full observation (``point_mass_full.yaml``), per role."""
    return {
        role: [(f"learned full ({Path(path).parent.parent.name})", str(path))] if path else []
        for role, path in (("pursuer", args.full_pursuer), ("evader", args.full_evader))
    }


def make_player(spec: str, role: str, scenario: Scenario, base: Scenario, seed: int):
    if spec == "chase":
        return Chase(scenario, role, solution_for(base, "rel4d"))
    return resolve_policy(spec, role, scenario, seed=seed)


def matrix(args: argparse.Namespace) -> None:
    base = load_scenario("point_mass")
    solution_for(base, "abs8d")
    solution_for(base, "rel4d")
    limited, full = players(args, base), full_players(args)
    # the checkpoints that keep point_mass.yaml's 3.75 m sensor in the full-observation matrix
    short = {spec for role in limited for _, spec in limited[role] if spec.endswith(".zip")}
    seeing_all = {spec for role in full for _, spec in full[role]}
    results = {}
    for observation in args.observation:
        roster = {role: limited[role] + (full[role] if observation == "full" else []) for role in limited}
        table = {}
        for p_label, p_spec in roster["pursuer"]:
            for e_label, e_spec in roster["evader"]:
                if {p_spec, e_spec} & short and {p_spec, e_spec} & seeing_all:
                    continue  # a 3.75 m checkpoint against one trained seeing: neither game is the other's
                if observation == "full":  # a learned player keeps the sensor it was trained with
                    roles = tuple(role for role, spec in (("pursuer", p_spec), ("evader", e_spec)) if spec not in short)
                    scenario = seeing(base, roles)
                else:
                    scenario = base
                pursuer = make_player(p_spec, "pursuer", base if p_spec in short else scenario, base, 1)
                evader = make_player(e_spec, "evader", base if e_spec in short else scenario, base, 2)
                table[f"{p_label} | {e_label}"] = rate(scenario, pursuer, evader, args.episodes)
            print(f"done: {observation} {p_label}", file=sys.stderr)
        results[observation] = table
        print(
            f"\n{observation} observation: capture rate (time-to-capture / T), {args.episodes} games per cell, "
            "seed 0; pursuers in columns, evaders in rows\n"
        )
        pursuers = [label for label, _ in roster["pursuer"]]
        print("| evader \\ pursuer | " + " | ".join(pursuers) + " |")
        print("| --- |" + " ---: |" * len(pursuers))
        for e_label, _ in roster["evader"]:
            cells = [table.get(f"{p} | {e_label}") for p in pursuers]
            print(f"| {e_label} | " + " | ".join(f"{c[0]:.3f} ({c[1]:.2f})" if c else "—" for c in cells) + " |")
        print_targets(table, roster, short if observation == "full" else set())
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


def print_targets(
    table: dict[str, tuple[float, float]], roster: dict[str, list[tuple[str, str]]], short: set[str]
) -> None:
    """The HJ targets: the hj pursuer captures at least as often as the best heuristic pursuer against
    every evader, and the hj evader is caught at most as often as the best heuristic evader by every pursuer.
    An opponent in ``short`` (a checkpoint keeping its 3.75 m sensor under full observation) plays another
    game than the value's, and its row says so instead."""

    def heuristic(label: str) -> bool:
        return not label.startswith(("hj", "learned"))

    def verdict(met: bool, spec: str) -> str:
        return ("yes" if met else "no") + (
            " (its 3.75 m sensor: not the full-information game)" if spec in short else ""
        )

    print("\n| opponent | hj | best heuristic | target met |\n| --- | ---: | --- | --- |")
    for e_label, e_spec in roster["evader"]:
        best = max((table[f"{p} | {e_label}"][0], p) for p, _ in roster["pursuer"] if heuristic(p))
        ours = table[f"hj | {e_label}"][0]
        print(f"| evader {e_label} | {ours:.3f} | {best[0]:.3f} ({best[1]}) | {verdict(ours >= best[0], e_spec)} |")
    for p_label, p_spec in roster["pursuer"]:
        best = min((table[f"{p_label} | {e}"][0], e) for e, _ in roster["evader"] if heuristic(e))
        ours = table[f"{p_label} | hj"][0]
        print(f"| pursuer {p_label} | {ours:.3f} | {best[0]:.3f} ({best[1]}) | {verdict(ours <= best[0], p_spec)} |")


# ---------------------------------------------------------------------- Table II
def table2(args: argparse.Namespace) -> None:
    """The documented command sequence (docs/hj.md), then the table beside the paper's."""
    pecli = str(Path(sys.executable).with_name("pecli"))
    out = Path(args.out)
    commands = [
        [pecli, "hj", "solve", "-c", "point_mass"],
        [
            pecli,
            "tournament",
            "-c",
            "point_mass",
            "--episodes",
            str(args.episodes),
            "--seeds",
            str(args.seeds),
            "--workers",
            "1",
            "--resume",
            "--out",
            str(out),
            args.pursuer,
            args.evader,
            f"hj:belief={args.pursuer}",
            f"hj:belief={args.evader}",
            "hj",
        ],
        [pecli, "hj", "table", str(out)],
    ]
    for command in commands:
        print(
            "$ " + " ".join(Path(command[0]).name if i == 0 else part for i, part in enumerate(command)),
            file=sys.stderr,
        )
        subprocess.run(command, check=True, stdout=None if command[1:3] == ["hj", "table"] else subprocess.DEVNULL)
    data = json.loads((out / "results.json").read_text())
    cells = {(p["pursuer"], p["evader"]): p for p in data["pairings"]}
    names = {
        "optimal control": {
            "pursuer": _player_name(data, f"hj:belief={args.pursuer}", "pursuer"),
            "evader": _player_name(data, f"hj:belief={args.evader}", "evader"),
        },
        "ours": {
            "pursuer": _player_name(data, args.pursuer, "pursuer"),
            "evader": _player_name(data, args.evader, "evader"),
        },
    }
    print("\n| pursuer vs evader | pecli capture (time-to-capture, σ) | paper capture |")
    print("| --- | ---: | ---: |")
    for (pursuer, evader), paper in PAPER_TABLE_II.items():
        cell = cells.get((names[pursuer]["pursuer"], names[evader]["evader"]))
        ours = (
            f"{cell['capture_rate']:.3f} ({cell['time_to_capture_mean']:.2f}, {cell['time_to_capture_std']:.2f})"
            if cell
            else "-"
        )
        print(f"| {pursuer} vs {evader} | {ours} | {paper:.2f} |")


def _player_name(data: dict, spec: str, role: str) -> str:
    """The tournament's name for the ``role`` player given as ``spec`` (a checkpoint's path, or a policy string)."""
    for rating in data.get("ratings", []):
        given = rating.get("spec", "")
        same = given == spec or (spec.endswith(".zip") and Path(given).resolve() == Path(spec).resolve())
        if same and rating.get("role") == role:
            return rating["name"]
    return spec


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        config, model, sizes, steps, backend = sys.argv[2:7]
        grid = tuple(int(n) for n in sizes.split(","))
        print(json.dumps(one(config, model, grid, int(steps) or None, backend)))  # type: ignore[arg-type]
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    s = sub.add_parser("solve", help="solve time, CPU, memory and accuracy of every model")
    s.add_argument("--config", default="point_mass")
    s.add_argument("--repeats", type=int, default=3, help="solves per rel4d case (the larger models: one)")
    s.add_argument("--quick", action="store_true", help="small grids and a 20-step horizon, for a smoke test")
    s.add_argument("--json", action="store_true", help="print the results as JSON")
    c = sub.add_parser("causes", help="the old players' weakness, one suspected cause at a time")
    c.add_argument("--episodes", type=int, default=EPISODES)
    m = sub.add_parser("matrix", help="capture matrices under full and partial observation")
    m.add_argument("--pursuer", help="a learned pursuer checkpoint (.zip) to add")
    m.add_argument("--evader", help="a learned evader checkpoint (.zip) to add")
    m.add_argument(
        "--full-pursuer",
        help="a learned pursuer trained under full observation "
        "(benchmarks/point_mass_full.yaml), for the full-observation matrix",
    )
    m.add_argument("--full-evader", help="a learned evader trained under full observation, likewise")
    m.add_argument("--episodes", type=int, default=EPISODES)
    m.add_argument("--observation", nargs="+", choices=("full", "partial"), default=["full", "partial"])
    m.add_argument("--json", help="also write the matrices to this JSON file")
    t = sub.add_parser("table2", help="Table II through the documented commands, beside the paper's")
    t.add_argument("--pursuer", required=True, help="the learned (BiMDN) pursuer checkpoint")
    t.add_argument("--evader", required=True, help="the learned (BiMDN) evader checkpoint")
    t.add_argument("--episodes", type=int, default=EPISODES)
    t.add_argument("--seeds", type=int, default=3)
    t.add_argument("--out", default=str(ROOT / "runs" / "table2"))
    r = sub.add_parser("ratings", help="the hj evader's rating of its inputs, one way at a time")
    r.add_argument("--full-pursuer", nargs="*", default=[], help="learned pursuers trained under full observation")
    r.add_argument("--episodes", type=int, default=EPISODES)
    args = parser.parse_args()
    {"solve": solve_table, "causes": causes, "matrix": matrix, "table2": table2, "ratings": ratings}[args.step](args)


if __name__ == "__main__":
    main()
