"""Fuzzing every reader of a file pecli did not just write: whatever the bytes, the answer is a value or one
:class:`PecliError` (a clear line at the CLI), never another exception.

The files are those a zoo, a tournament or an experiment folder from elsewhere holds: checkpoint metadata, a
learner's durable state, ``run.json``, ``selfplay.json``, a Nash mixture, a best-response record, a pairing cache,
a tournament's ``results.json``, a run's evaluation log, an export's sidecar, a run's ``config.yaml``; and the
values of ``--set``. Inputs are arbitrary JSON (deep, wide, wrong types, huge integers), arbitrary bytes, and
well-formed records with one field replaced.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pecli.errors import PecliError

FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
)
json_values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=10), inner, max_size=5)),
    max_leaves=30,
)
documents = st.one_of(
    json_values.map(lambda value: json.dumps(value)),
    st.binary(max_size=200).map(lambda data: data.decode("latin-1")),
    st.integers(min_value=1, max_value=5000).map(lambda depth: "[" * depth + "]" * depth),
    st.integers(min_value=4301, max_value=6000).map(lambda digits: "9" * digits),
)


def _replace_one(record: dict, draw_value) -> dict:
    return {**record, **draw_value}


def records_like(record: dict) -> st.SearchStrategy[str]:
    """``record`` with one top-level field replaced by any JSON value, or dropped, as JSON text."""
    keys = st.sampled_from(sorted(record))
    replaced = st.tuples(keys, json_values).map(lambda kv: json.dumps({**record, kv[0]: kv[1]}))
    dropped = keys.map(lambda key: json.dumps({k: v for k, v in record.items() if k != key}))
    return st.one_of(replaced, dropped, documents)


def only_clear_errors(read, *args) -> None:
    """Call the reader: a value, or a :class:`PecliError` with one line of text; anything else fails the test."""
    try:
        read(*args)
    except PecliError as exc:
        assert str(exc) and "\n" not in str(exc).strip()


META = {
    "role": "pursuer",
    "steps": 10,
    "episodes": 1,
    "algo": "td3",
    "belief": "none",
    "scenario": "quick",
    "scenario_hash": "x",
    "opponent": "greedy",
    "frame_skip": 2,
    "frame_stack": 2,
    "history_length": 200,
    "history_stride": 10,
    "policy_kwargs": {"net_arch": [16, 16], "n_critics": 2},
}
STATE = {
    "steps": 10,
    "episodes": 1,
    "n_updates": 0,
    "cpu_seconds": 1.0,
    "model": "model-000000010.zip",
    "format": 1,
    "extra": {},
}
SELFPLAY = {
    "seed": 0,
    "curriculum_steps": 10,
    "pools": {"pursuer": {"role": "pursuer", "entries": [{"name": "greedy", "spec": "greedy", "generation": 0}]}},
    "turns": [],
    "cpu_hours": None,
}
NASH = {
    "kind": "nash",
    "scenario": "quick",
    "scenario_hash": "x",
    "value": 0.5,
    "pursuer": [{"name": "p", "spec": "pure-pursuit", "weight": 1.0}],
    "evader": [{"name": "e", "spec": "greedy", "weight": 1.0}],
}
PAIRING = {
    "pursuer": "p",
    "evader": "e",
    "episodes": 10,
    "captures": 3,
    "time_to_capture_mean": 0.5,
    "time_to_capture_std": 0.1,
}

RESULTS = {
    "scenario": "quick",
    "episodes_per_seed": 10,
    "seeds": [0],
    "pairings": [{**PAIRING, "pursuer": "p", "evader": "e"}],
    "ratings": [
        {"name": "p", "role": "pursuer", "spec": "pure-pursuit", "elo": 1510.0, "stderr": 30.0},
        {"name": "e", "role": "evader", "spec": "greedy", "elo": 1490.0, "stderr": 30.0},
    ],
}


@FUZZ
@given(text=records_like(META))
def test_checkpoint_metadata(tmp_path: Path, text: str) -> None:
    from pecli.zoo import read_metadata

    (tmp_path / "c.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(read_metadata, tmp_path / "c.zip")


@FUZZ
@given(text=records_like(STATE))
def test_durable_state(tmp_path: Path, text: str) -> None:
    from pecli.rl.durable import DurableState

    (tmp_path / "state.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    (tmp_path / "model-000000010.zip").write_bytes(b"")
    only_clear_errors(DurableState(tmp_path).read)


@FUZZ
@given(text=records_like({"command": "train", "role": "pursuer", "opponent": "greedy", "seed": 0}))
def test_run_record(tmp_path: Path, text: str) -> None:
    from pecli.zoo import Run

    (tmp_path / "run.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(Run(tmp_path).job)


@FUZZ
@given(text=records_like(SELFPLAY))
def test_selfplay_state(tmp_path: Path, text: str) -> None:
    from pecli.rl.selfplay import read_state
    from pecli.zoo import Run

    (tmp_path / "selfplay.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(read_state, Run(tmp_path))


@FUZZ
@given(text=records_like(NASH))
def test_nash_mixture(tmp_path: Path, quick, text: str) -> None:
    from pecli.policies import resolve_policy

    (tmp_path / "nash.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(resolve_policy, f"nash:{tmp_path}", "pursuer", quick)


@FUZZ
@given(text=records_like(PAIRING))
def test_pairing_cache(tmp_path: Path, text: str) -> None:
    from pecli.tournament import Player, _cached

    (tmp_path / "p.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    result = _cached(
        tmp_path / "p.json", Player("p", "pure-pursuit", "pursuer", "x"), Player("e", "greedy", "evader", "y")
    )
    if result is not None:  # believed only when it is what a pairing can give
        assert 0 <= result.captures <= result.episodes and math.isfinite(result.time_to_capture_mean)


@FUZZ
@given(text=records_like(RESULTS))
def test_tournament_results(tmp_path: Path, text: str) -> None:
    from pecli.tournament import read_results, tournament_ratings

    (tmp_path / "results.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(read_results, tmp_path)
    assert isinstance(tournament_ratings(tmp_path), dict)  # an unreadable file rates nothing, and raises nothing


@pytest.mark.parametrize(
    "rating",
    [{"spec": "a\x00b.zip"}, {"elo": 1e6}, {"stderr": 1e300}, {"spec": "x" * ((1 << 20) + 1)}],
)
def test_a_rating_no_tournament_gives_is_refused(tmp_path: Path, rating: dict) -> None:
    from pecli.tournament import read_results, tournament_ratings

    data = {**RESULTS, "ratings": [{**RESULTS["ratings"][0], **rating}, RESULTS["ratings"][1]]}
    (tmp_path / "results.json").write_text(json.dumps(data))
    with pytest.raises(PecliError, match="damaged tournament's results"):
        read_results(tmp_path)
    assert tournament_ratings(tmp_path) == {}


def test_one_name_may_be_a_pursuer_and_an_evader(tmp_path: Path) -> None:
    from pecli.reports import table_two
    from pecli.tournament import read_results

    ratings = [{**r, "name": "x"} for r in RESULTS["ratings"]]
    data = {**RESULTS, "ratings": ratings, "pairings": [{**PAIRING, "pursuer": "x", "evader": "x"}]}
    (tmp_path / "results.json").write_text(json.dumps(data))
    record = read_results(tmp_path)
    assert len(record.ratings) == 2 and table_two(record).row_count == 1


@FUZZ
@given(
    text=st.one_of(
        documents, st.text(max_size=300).map(lambda rows: f"steps,cpu_seconds,wall_seconds,capture_rate\n{rows}")
    )
)
def test_evaluation_log(tmp_path: Path, text: str) -> None:
    from pecli.rl.evaluations import read_evaluations

    (tmp_path / "eval_pursuer.csv").write_text(text, encoding="utf-8", errors="surrogatepass")
    for row in read_evaluations(tmp_path / "eval_pursuer.csv"):
        assert row.steps >= 0 and 0 <= row.capture_rate <= 1 and math.isfinite(row.cpu_seconds)


@FUZZ
@given(text=documents)
def test_export_sidecar(tmp_path: Path, text: str) -> None:
    from pecli.runtime import read_sidecar

    (tmp_path / "m.onnx.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(read_sidecar, tmp_path / "m.onnx")


@FUZZ
@given(text=st.one_of(documents, st.text(max_size=300)))
def test_run_config(tmp_path: Path, text: str) -> None:
    from pecli.zoo import Run

    (tmp_path / "config.yaml").write_text(text, encoding="utf-8", errors="surrogatepass")
    only_clear_errors(Run(tmp_path).scenario)


@FUZZ
@given(
    key=st.sampled_from(["steps", "gamma", "net_arch", "selfplay.rounds", "curriculum.enabled", "nope.x"]),
    value=st.one_of(st.text(max_size=40), documents.map(lambda text: text[:6000])),
)
def test_set_values(quick, key: str, value: str) -> None:
    from pecli.rl.train import parse_overrides, with_overrides

    def apply() -> None:
        with_overrides(quick, parse_overrides([f"{key}={value}"]))

    only_clear_errors(apply)


@pytest.mark.parametrize("reader", ["exploit"])
def test_a_best_response_record_from_elsewhere_is_refused(tmp_path: Path, reader: str) -> None:
    from pecli.exploit import _read_record

    for text in ("[" * 5000 + "]" * 5000, json.dumps({"kind": "exploit", "responses": {"x": 1}}), "9" * 5000):
        (tmp_path / "exploit.json").write_text(text)
        only_clear_errors(_read_record, tmp_path / "exploit.json")


@settings(max_examples=25, deadline=None)
@given(
    episodes=st.one_of(st.integers(min_value=-3, max_value=30), st.text(max_size=8)),
    seed=st.one_of(st.integers(min_value=-3, max_value=2**40), st.text(max_size=8)),
    pursuer=st.one_of(
        st.sampled_from(["pure-pursuit", "interceptor", "greedy", "nash:", "hj:x=1", "a:b"]), st.text(max_size=12)
    ),
    evader=st.one_of(st.sampled_from(["greedy", "hider", "random-walk", "x.zip", "x.onnx"]), st.text(max_size=12)),
    config=st.one_of(st.just("quick"), st.text(max_size=12)),
)
def test_play_options(episodes, seed, pursuer: str, evader: str, config: str) -> None:
    """``pecli play`` with any option values: a result, one ``error:`` line or a usage error, never an internal
    error (module:Class strings are left out: importing a module a user names is what they asked for)."""
    from typer.testing import CliRunner

    from pecli.cli import app

    if ":" in pursuer and pursuer.split(":")[0] not in ("nash", "hj"):
        pursuer = pursuer.replace(":", "_")
    if ":" in evader:
        evader = evader.replace(":", "_")
    result = CliRunner().invoke(
        app, ["play", "-n", str(episodes), "--seed", str(seed), "-p", pursuer, "-e", evader, "-c", config, "--json"]
    )
    assert result.exit_code in (0, 1, 2), result.output
    assert (
        "internal error" not in result.output
        and not isinstance(result.exception, Exception)
        or isinstance(result.exception, SystemExit)
    ), result.output
