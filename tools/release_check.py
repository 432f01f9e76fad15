"""Build the sdist and the wheel, install the wheel in a fresh virtual environment outside the repository, run it.

``make release-check`` calls it; CI runs it after the tests. The wheel is built from the sdist (as ``python -m
build`` does), so a file missing from the sdist fails here. The new environment takes pecli's dependencies from
the development environment (a path file, no network) and pecli itself only from the wheel; ``pip check`` then
verifies that the wheel's declared requirements are met by them. Exits non-zero with one line on the first failure.
"""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
import tarfile
import tempfile
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
IN_SDIST = ("LICENSE", "README.md", "CHANGELOG.md", "configs/paper.yaml", "configs/experiments/table1-small.yaml")


def run(command: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    """``command``'s stdout; exits with one line when it fails."""
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["(no output)"]
        sys.exit(f"release check: `{' '.join(command)}` failed: {tail[0]}")
    return done.stdout


def version() -> str:
    """The version in ``pecli/__init__.py``, the one place it is written."""
    for line in (ROOT / "pecli" / "__init__.py").read_text().splitlines():
        if line.startswith("__version__"):
            return line.split("=", 1)[1].strip().strip("\"'")
    sys.exit("release check: no __version__ in pecli/__init__.py")


def main() -> None:
    expected = version()
    with tempfile.TemporaryDirectory(prefix="pecli-release-") as tmp:
        work = Path(tmp)
        dist = work / "dist"
        run([sys.executable, "-m", "build", "--outdir", str(dist), str(ROOT)], cwd=work)
        sdists, wheels = sorted(dist.glob("*.tar.gz")), sorted(dist.glob("*.whl"))
        if len(sdists) != 1 or len(wheels) != 1 or expected not in wheels[0].name:
            sys.exit(f"release check: expected one sdist and one wheel of {expected}, got {sorted(dist.iterdir())}")
        with tarfile.open(sdists[0]) as archive:
            names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
        missing = [name for name in IN_SDIST if name not in names]
        if missing:
            sys.exit(f"release check: the sdist lacks {', '.join(missing)}")

        env_dir = work / "env"
        venv.create(env_dir, with_pip=True)
        python = env_dir / "bin" / "python"
        site = Path(run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], work).strip())
        (site / "pecli-dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")  # after its own
        run([str(python), "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", str(wheels[0])], cwd=work)
        checked = subprocess.run([str(python), "-m", "pip", "check"], cwd=work, capture_output=True, text=True)
        unmet = [line for line in checked.stdout.splitlines() if line.lower().startswith("pecli ")]
        if unmet:  # only pecli's own requirements: the new environment's pip and setuptools are older than torch's
            sys.exit(f"release check: {unmet[0]}")

        pecli = env_dir / "bin" / "pecli"
        where = run([str(python), "-c", "import pecli; print(pecli.__file__)"], cwd=work).strip()
        if not where.startswith(str(env_dir)):
            sys.exit(f"release check: pecli imported from {where}, not from the new environment")
        shown = run([str(pecli), "--version"], cwd=work).strip()
        if shown != f"pecli {expected}":
            sys.exit(f"release check: `pecli --version` says {shown!r}, expected 'pecli {expected}'")
        listed = run([str(pecli), "config", "list"], cwd=work)
        if "paper" not in listed or "quick" not in listed:
            sys.exit("release check: the built-in scenarios are not installed with the wheel")
        played = json.loads(run([str(pecli), "play", "-c", "quick", "-n", "20", "--json"], cwd=work))
        if played.get("episodes") != 20:
            sys.exit(f"release check: `pecli play` reported {played}")
        run([str(python), "-c", "from pecli.runtime import Controller"], cwd=work)
        print(f"release check: {sdists[0].name} and {wheels[0].name} build, install outside the repository and run")


if __name__ == "__main__":
    main()
