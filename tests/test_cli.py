"""The command line through typer's test runner, and once as a real process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pecli import __version__
from pecli.cli import app
from pecli.policies import builtin_names

runner = CliRunner()


def invoke(*args: str):
    return runner.invoke(app, list(args))


def test_version() -> None:
    result = invoke("--version")
    assert result.exit_code == 0 and result.stdout.strip() == f"pecli {__version__}"


def test_help_lists_grouped_commands() -> None:
    result = invoke("--help")
    assert result.exit_code == 0
    for text in ("play", "config", "Play and evaluate", "Scenarios"):
        assert text in result.stdout


def _options(command, path: tuple[str, ...] = ()):
    """(command path, long names, short names) of every option of every command under ``command``."""
    if hasattr(command, "list_commands"):
        for name in command.list_commands(None):
            yield from _options(command.get_command(None, name), (*path, name))
        return
    for param in command.params:
        if param.param_type_name == "option":
            names = [*param.opts, *param.secondary_opts]
            yield " ".join(path), [n for n in names if n.startswith("--")], [n for n in names if not n.startswith("--")]


def test_a_short_flag_means_one_option_in_every_command() -> None:
    import typer

    shorts: dict[str, set[str]] = {}
    longs: dict[str, set[tuple[str, ...]]] = {}
    for _, long_names, short_names in _options(typer.main.get_command(app)):
        for short in short_names:
            shorts.setdefault(short, set()).update(long_names)
        for long in long_names:
            longs.setdefault(long, set()).add(tuple(short_names))
    assert {s: ls for s, ls in shorts.items() if len(ls) > 1} == {}
    assert {ln: ss for ln, ss in longs.items() if len(ss) > 1} == {}
    assert shorts["-o"] == {"--out"} and shorts["-n"] == {"--episodes"}


def test_help_shows_a_type_beside_an_option_that_takes_a_value_and_none_beside_a_flag() -> None:
    lines = runner.invoke(app, ["experiment", "exploit", "--help"], env={"COLUMNS": "200"}).stdout.splitlines()
    options = [line.lstrip("│ ") for line in lines if line.startswith("│")]  # the options' rows, not the text
    (warm,) = (line for line in options if line.startswith("--warm"))
    (minutes,) = (line for line in options if line.startswith("--cpu-minutes"))
    assert "<" not in warm.split("Also")[0] and "<float>" in minutes


def test_play_help_names_every_builtin_player_of_each_side() -> None:
    shown = runner.invoke(app, ["play", "--help"], env={"COLUMNS": "400"}).stdout
    pursuer, evader = (line for line in shown.splitlines() if "A built-in name" in line)
    assert all(name in pursuer for name in builtin_names("pursuer")) and "blindside" not in pursuer
    assert all(name in evader for name in builtin_names("evader")) and "wall-runner" in evader


def test_experiment_run_help_names_every_builtin_experiment() -> None:
    from pecli.scenario import builtin_experiments

    shown = " ".join(runner.invoke(app, ["experiment", "run", "--help"], env={"COLUMNS": "400"}).stdout.split())
    assert "strength-small" in builtin_experiments()
    assert all(name in shown for name in builtin_experiments())


def test_play_json() -> None:
    result = invoke("play", "--pursuer", "pure-pursuit", "--evader", "greedy", "-c", "quick", "-n", "40", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert set(data) == {"capture_rate", "time_to_capture_mean", "time_to_capture_std", "episodes"}
    assert data["episodes"] == 40 and 0.0 <= data["capture_rate"] <= 1.0
    again = invoke("play", "-c", "quick", "-n", "40", "--json")
    assert json.loads(again.stdout) == data  # defaults: pure-pursuit vs greedy, seed 0


def test_play_table() -> None:
    result = invoke("play", "-c", "quick", "-n", "10", "--evader", "rash")
    assert result.exit_code == 0
    assert "capture rate" in result.stdout and "pure-pursuit vs rash" in result.stdout


@pytest.mark.parametrize("suffix", [".png", ".gif"])
def test_play_render(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"episodes{suffix}"
    result = invoke("play", "-c", "quick", "-n", "3", "-e", "rash", "--render", str(out))  # rash: caught in 5 s
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 1000
    assert out.read_bytes()[:4] == (b"\x89PNG" if suffix == ".png" else b"GIF8")
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left behind


@pytest.mark.parametrize(
    ("args", "played", "drawn", "said"),
    [
        (["-n", "8", "--render", "x.png"], 8, 8, "wrote x.png: the 8 episodes"),
        (["-n", "20", "--render", "x.png"], 20, 16, "the first 16 of the 20 episodes (a drawing holds at most 16)"),
        (["--render", "x.png"], 100, 16, "the first 16 of the 100 episodes"),
        (["--render", "x.gif"], 1, 1, "wrote x.gif: the episode"),  # a GIF shows one episode: one is played
        (["-n", "5", "--render", "x.gif"], 5, 1, "wrote x.gif: episode 1 of the 5"),
    ],
)
def test_play_render_draws_what_it_plays(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, args: list[str], played: int, drawn: int, said: str
) -> None:
    import pecli.render

    calls: list[tuple[int, str]] = []

    def draw(recording, path, episodes=1, title=None, **_):  # records what play asks to draw, writes nothing
        calls.append((min(episodes, recording.steps.shape[0]), title))
        return path

    monkeypatch.setattr(pecli.render, "draw_episodes", draw)
    monkeypatch.setattr(pecli.render, "animate_episode", draw)
    monkeypatch.chdir(tmp_path)
    result = invoke("play", "-c", "quick", "--json", *args)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["episodes"] == played
    assert calls == [(drawn, "pure-pursuit vs greedy on quick (seed 0)")]
    assert said in result.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["play", "--pursuer", "greedy"], "'greedy' plays evader, not pursuer"),
        (["play", "--evader", "nobody"], "unknown policy 'nobody'"),
        (["play", "-c", "missing.yaml"], "config not found: missing.yaml"),
        (["play", "-n", "0"], "--episodes must be at least 1"),
        (["play", "--render", "out.mp4"], "--render must end in .png or .gif"),
        (["config", "check", "nope"], "config not found"),
        (["play", "-c", "quick", "-n", "2", "--render", "/proc/no/such/out.png"], "/proc/no"),
        (["play", "--pursuer", "configs"], "configs is a folder: give a checkpoint in it"),
    ],
)
def test_user_errors_are_one_line_and_exit_1(args: list[str], message: str) -> None:
    result = invoke(*args)
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0] and lines[0].startswith("error:")
    assert "Traceback" not in result.output


def test_bad_config_file_names_key_and_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\narena: {width: 16, height: 16, depth: 3}\n")
    result = invoke("play", "-c", str(bad))
    assert result.exit_code == 1
    assert f"{bad}: arena.depth: unknown key" in result.output


def test_config_commands() -> None:
    listed = invoke("config", "list")
    assert listed.exit_code == 0 and "point_mass" in listed.stdout
    shown = invoke("config", "show", "paper")
    assert shown.exit_code == 0 and "steer_rate_max: 3.2" in shown.stdout
    checked = invoke("config", "check", "paper", "quick")
    assert checked.exit_code == 0 and checked.stdout.count("ok") == 2


def test_config_check_lists_every_problem_and_play_names_the_first(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: k\npursuer: {kind: tank}\n")
    checked = invoke("config", "check", str(bad))
    lines = checked.output.strip().splitlines()
    assert checked.exit_code == 1 and len(lines) == 3, checked.output
    assert any("pursuer: kind must be one of 'car', 'point_mass', not 'tank'" in line for line in lines)
    played = invoke("play", "-c", str(bad))
    assert played.exit_code == 1 and "(and 2 more problems)" in played.output
    (tmp_path / "empty.yaml").write_text("")
    empty = invoke("config", "check", str(tmp_path / "empty.yaml"))
    assert empty.exit_code == 1 and "not an empty file" in empty.output


def test_output_with_no_terminal_keeps_whole_table_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Under nohup or cron Rich would cut tables to 80 columns (run names elided): 200 there, the terminal's
    width where one is attached, and ``COLUMNS`` wins over both."""
    import io

    from rich.console import Console
    from rich.table import Table

    from pecli.cli.common import PIPE_WIDTH, _width

    def no_terminal(fd: int) -> os.terminal_size:
        raise OSError("not a terminal")

    monkeypatch.delenv("COLUMNS", raising=False)
    monkeypatch.setattr(os, "get_terminal_size", no_terminal)
    assert _width() == PIPE_WIDTH
    table = Table("run", "status")
    table.add_row("bimdn-simultaneous-s2-" + "x" * 80, "running")
    out = io.StringIO()
    Console(file=out, width=_width()).print(table)
    assert "x" * 80 in out.getvalue()  # at Rich's default of 80 columns the name is cut
    monkeypatch.setenv("COLUMNS", "100")
    assert _width() is None
    monkeypatch.delenv("COLUMNS")
    monkeypatch.setattr(os, "get_terminal_size", lambda fd: os.terminal_size((120, 40)))
    assert _width() is None


def test_sigterm_stops_like_ctrl_c_inside_the_block_and_restores_the_handler_after() -> None:
    """Every long command (train, selfplay, tune, tournament, experiment) saves and says how to resume on
    Ctrl-C; ``sigterm_stops`` gives ``kill`` that path, and only for as long as the command runs."""
    import signal

    from pecli.cli.common import sigterm_stops

    def before(signum: int, frame: object) -> None:
        raise AssertionError("the old handler ran inside the block")

    previous = signal.signal(signal.SIGTERM, before)
    try:
        with pytest.raises(KeyboardInterrupt):
            with sigterm_stops():
                os.kill(os.getpid(), signal.SIGTERM)
        assert signal.getsignal(signal.SIGTERM) is before  # also when the block ended by the interrupt
        with sigterm_stops():
            pass
        assert signal.getsignal(signal.SIGTERM) is before
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_help_paragraphs_wrap_at_the_terminal_not_where_the_source_wrapped() -> None:
    """Typer's rich help keeps a docstring's line breaks: every command's text is reflowed into paragraphs."""
    from pecli.cli.app import reflow

    assert (
        reflow("""One line.

        A paragraph wrapped
        in the source.
        """)
        == "One line.\n\nA paragraph wrapped in the source."
    )
    assert reflow("Title.\n\n\b\nkept\nas is") == "Title.\n\n\b\nkept\nas is"
    groups = [group.typer_instance for group in app.registered_groups]
    commands = [*app.registered_commands, *(command for group in groups for command in group.registered_commands)]
    docs = [c.callback.__doc__ for c in commands if c.callback.__doc__]
    assert len(docs) > 20 and all("\n" not in doc.replace("\n\n", "") for doc in docs)
    shown = runner.invoke(app, ["selfplay", "--help"], env={"COLUMNS": "200"})
    assert "however the run stops, --resume continues from its newest checkpoint" in shown.stdout


def test_python_dash_m_and_console_script() -> None:
    result = subprocess.run([sys.executable, "-m", "pecli", "--version"], capture_output=True, text=True, check=False)
    assert result.returncode == 0 and result.stdout.strip() == f"pecli {__version__}"


@pytest.mark.parametrize(
    "args, message",
    [
        (["train", "pursuerr"], "Invalid value for 'role': 'pursuerr' is not one of 'pursuer', 'evader'."),
        (["exploit", "--role", "both", "a", "b"], "'both' is not one of 'pursuer', 'evader'."),
        (["play", "--nope"], "No such option: --nope"),
        (["train"], "Missing argument 'role'. Choose from: pursuer, evader"),
        (["zoo", "lst"], "No such command 'lst'."),
    ],
)
def test_a_usage_error_is_one_line(args: list[str], message: str) -> None:
    result = invoke(*args)
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]
    assert "Value error" not in lines[0] and "╭" not in result.output  # no validator prefix, no boxed panel
    assert f"see `pecli {args[0]} --help`" in lines[0]


def test_a_usage_error_is_one_line_from_the_shell() -> None:
    """The entry point itself (not only the test runner) shows a misspelt role as one plain line."""
    result = subprocess.run(
        [sys.executable, "-m", "pecli", "train", "pursuerr"], capture_output=True, text=True, check=False
    )
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: Invalid value for 'role': 'pursuerr' is not one of")


def test_an_internal_error_is_one_line_and_exit_code_3(monkeypatch: pytest.MonkeyPatch) -> None:
    """A bug is told apart from a refused input (1) and a usage error (2); PECLI_DEBUG shows its traceback."""
    import typer

    from pecli.cli.common import DEBUG_VARIABLE, INTERNAL_ERROR_EXIT, user_errors

    broken = typer.Typer()

    @broken.command()
    @user_errors
    def fails() -> None:
        raise ZeroDivisionError("a bug")

    monkeypatch.delenv(DEBUG_VARIABLE, raising=False)
    result = runner.invoke(broken, [])
    assert result.exit_code == INTERNAL_ERROR_EXIT == 3
    assert result.output.strip().splitlines() == [
        "internal error: ZeroDivisionError: a bug (set PECLI_DEBUG=1 to see the traceback, and please report it)"
    ]
    monkeypatch.setenv(DEBUG_VARIABLE, "1")
    debugged = runner.invoke(broken, [])
    assert debugged.exit_code == 3 and "Traceback" in debugged.output and "ZeroDivisionError: a bug" in debugged.output
