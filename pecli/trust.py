"""Whether the user allowed pecli to unpickle files (``pecli --trust`` or ``PECLI_TRUST=1``).

pecli's own files are data: checkpoints are weights plus JSON, buffers are plain arrays, HJ solutions
are ``.npz`` without pickle. Only files written by an older pecli need unpickling, which runs any
code their author put in them; pecli refuses them unless the user says they trust them.
"""

from __future__ import annotations

import os
from pathlib import Path

from pecli.errors import PecliError

TRUST_VARIABLE = "PECLI_TRUST"


YES = ("1", "true", "yes")
NO = ("", "0", "false", "no")


def trusted() -> bool:
    """Whether unpickling (and importing code a file names) is allowed in this process: ``PECLI_TRUST`` is
    exactly one of ``1``, ``true``, ``yes`` (any case); unset or ``0``, ``false``, ``no`` is no, and anything else
    is refused in one line rather than guessed (``off`` must not mean yes)."""
    value = os.environ.get(TRUST_VARIABLE, "").strip().lower()
    if value in YES:
        return True
    if value in NO:
        return False
    raise PecliError(
        f"{TRUST_VARIABLE}={os.environ[TRUST_VARIABLE]!r}: set it to 1, true or yes to trust files "
        "that need unpickling, or leave it unset (0, false or no)"
    )


class UntrustedFileError(PecliError):
    """A file that only unpickling can read, refused without ``--trust`` (see :func:`untrusted`)."""


def untrusted(path: str | Path, why: str) -> UntrustedFileError:
    """The one-line refusal of ``path``, which only unpickling can read because ``why``."""
    return UntrustedFileError(
        f"{path}: {why}; unpickling runs any code its author put in it, so pecli refuses. If you "
        f"trust where it came from, pass `pecli --trust ...` (or set {TRUST_VARIABLE}=1)"
    )
