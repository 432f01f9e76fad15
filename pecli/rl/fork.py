"""Fork a stopped self-play run: a whole copy in another zoo, to train on as one arm of an A/B whose control is the
original, trained on alike (``pecli zoo fork``). Scripted players given with ``add`` join its pools as the ones a run
starts with (generation 0), so a run started before pecli had them can be tried with them; other settings go into
the copy's ``config.yaml`` by hand (a resumed run refuses settings that changed)."""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

from pecli.errors import PecliError
from pecli.io import atomic_write_json
from pecli.policies.registry import BUILTINS
from pecli.rl.handover import STATE_FILE
from pecli.rl.state import read_state_file


def fork_run(source: Path, to: Path, add: Sequence[str] = ()) -> Path:
    """Copy the stopped self-play run ``source`` to ``to/<its name>``, the scripted players ``add`` in its pools;
    returns the copy. The copy appears whole or not at all; :class:`PecliError` in one line if it cannot."""
    target = to / source.name
    state_path = source / STATE_FILE
    if not state_path.is_file():
        raise PecliError(f"{source}: not a self-play run (no {STATE_FILE})")
    if target.exists():
        raise PecliError(f"{target} exists: fork to another zoo")
    state = read_state_file(state_path)
    pools = state.pools
    for name in add:
        if name not in BUILTINS:
            raise PecliError(f"cannot add {name}: not a scripted player ({', '.join(BUILTINS)})")
        for role in BUILTINS[name].roles:
            try:
                pools[role].add(name, name, generation=0)
            except ValueError as error:  # it holds it already
                raise PecliError(f"{source.name}: {error}") from None
    to.mkdir(parents=True, exist_ok=True)
    partial = to / f".{source.name}.partial"
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(source, partial, symlinks=True)
    atomic_write_json(partial / STATE_FILE, state.to_dict())
    partial.rename(target)
    return target


def run_cpu_hours(run: Path) -> float:
    """CPU hours a self-play run has recorded in its finished turns (0 for a run without a readable state)."""
    try:
        return read_state_file(run / STATE_FILE).cpu_seconds() / 3600
    except PecliError:
        return 0.0
