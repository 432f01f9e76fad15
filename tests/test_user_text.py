"""What users read names no step of how pecli was made: no "session", "issue 18", "#18" or "SPEC §3" in the
documentation, the README, the changelog, the site's configuration, the generated reference or any command's
``--help``. Cite the paper by section, table or equation instead.

Only user text is checked: code may well say ``InferenceSession``.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROCESS_WORDS = [
    re.compile(r"\bsessions?\b", re.IGNORECASE),  # session, Session 34 (not InferenceSession, session_latest)
    re.compile(r"\bissues?[\s-]+#?\d+", re.IGNORECASE),  # issue 18, issue-18, issues 20 and 21, Issue #5
    re.compile(r"(?<![\w&/#])#\d+\b"),  # #18 (not &#8217; or a heading)
    re.compile(r"\bSPEC\b"),  # SPEC, SPEC §4
]


def process_words(text: str, where: str) -> list[str]:
    """``where:line: the line`` for every line of ``text`` that holds a process word."""
    return [
        f"{where}:{number}: {line.strip()}"
        for number, line in enumerate(text.splitlines(), 1)
        if any(pattern.search(line) for pattern in PROCESS_WORDS)
    ]


def file_hits(*paths: Path) -> list[str]:
    return [
        hit for path in paths for hit in process_words(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))
    ]


def help_texts() -> dict[str, str]:
    """``pecli ... --help`` of every command and group, as the terminal shows it (wide, so nothing wraps)."""
    import typer
    from typer.testing import CliRunner

    from pecli.cli import app

    paths: list[list[str]] = []

    def walk(command, path: list[str]) -> None:
        paths.append(path)
        for name, sub in (getattr(command, "commands", None) or {}).items():
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    runner, texts = CliRunner(), {}
    for path in paths:
        result = runner.invoke(
            app, [*path, "--help"], prog_name="pecli", env={"COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
        )
        assert result.exit_code == 0, (path, result.output)
        texts[" ".join(["pecli", *path, "--help"])] = result.output
    return texts


def test_the_checks_catch_what_they_should_and_nothing_else():
    caught = [
        "Session 34 trained it",
        "in this session",
        "issue 18's targets",
        "the issue-18 pursuers",
        "issues 20 and 21",
        "see #18",
        "(SPEC §4)",
        "SPEC section 3",
    ]
    spared = [
        "an onnxruntime InferenceSession",
        "/tmp/ray/session_latest/logs",
        "a known issue",
        "&#8217;",
        "## 18 rounds",
        "spec.py",
        "the paper's Table I (section V-B)",
    ]
    assert all(process_words(text, "t") for text in caught)
    assert not any(process_words(text, "t") for text in spared)


def test_docs_name_no_process_words():
    pages = sorted((ROOT / "docs").rglob("*.md"))
    assert pages
    hits = file_hits(*pages)
    assert not hits, "process words in docs/ (cite the paper instead):\n" + "\n".join(hits)


def test_readme_and_site_config_name_no_process_words():
    hits = file_hits(ROOT / "README.md", ROOT / "mkdocs.yml")
    assert not hits, "process words in README.md or mkdocs.yml:\n" + "\n".join(hits)


def test_help_names_no_process_words():
    hits = [hit for where, text in help_texts().items() for hit in process_words(text, where)]
    assert not hits, "process words in --help:\n" + "\n".join(hits)


def test_generated_reference_names_no_process_words():
    """The site's generated pages: the built-in scenarios and experiments with their descriptions, every key."""
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "tools" / "docs_hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    names = ("builtin-scenarios", "scenario-fields", "builtin-experiments", "experiment-fields")
    hits = [hit for name in names for hit in process_words(hooks.GENERATORS[name](), f"<!-- pecli:{name} -->")]
    assert not hits, "process words in the generated reference:\n" + "\n".join(hits)


def test_changelog_names_no_process_words():
    hits = file_hits(ROOT / "CHANGELOG.md")
    assert not hits, "process words in CHANGELOG.md:\n" + "\n".join(hits)


def test_code_and_configs_name_no_issues():
    """Comments and docstrings of the code, the benchmarks and the shipped configs cite no issue or SPEC (code may
    say ``session``: an onnxruntime session, an experiment's sessions)."""
    not_session = PROCESS_WORDS[1:]
    files = [
        path
        for base in ("pecli", "benchmarks", "tools", "configs", "examples", "wrappers", "tests")
        for path in sorted((ROOT / base).rglob("*"))
        if path.suffix in (".py", ".yaml", ".sh") and path.name != "test_user_text.py"
    ]
    assert len(files) > 100
    hits = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in files
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if any(pattern.search(line) for pattern in not_session)
    ]
    hits += [hit for path in sorted((ROOT / "configs").rglob("*.yaml")) for hit in file_hits(path)]
    assert not hits, "process words in code or configs:\n" + "\n".join(hits)
