"""The Hamilton–Jacobi players against every other player: capture matrices and the HJ targets.

    python benchmarks/bench_hj_matrix.py matrix --pursuer P.zip --evader E.zip    # full and partial observation
        [--full-pursuer P.zip --full-evader E.zip]                               # players of the full-information game

``matrix``: the default ``hj`` players (abs8d) and the others (``hj:model=rel4d``, the heuristics,
"chase", the learned checkpoints given) in a capture matrix of 500 games per cell (seed 0), under
full observation (sensor ranges 30 m; a learned player keeps the 3.75 m sensor it was trained
with, since a checkpoint only plays the game it learned, while its opponent sees it everywhere;
``--full-pursuer``/``--full-evader`` add players trained on ``point_mass_full.yaml``, which see
everywhere too) and under ``point_mass.yaml`` (3.75 m).
"chase" is the rule the first HJ players fell back on (``hj_players.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

from hj_players import make_player, rate, solution_for  # noqa: E402

from pecli.scenario import Scenario, load_scenario  # noqa: E402

EPISODES = 500


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
                    scenario = base.with_sensor_range(30.0, roles)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
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
    matrix(parser.parse_args())


if __name__ == "__main__":
    main()
