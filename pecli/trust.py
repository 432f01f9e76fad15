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


def trusted() -> bool:
    """Whether unpickling is allowed in this process."""
    return os.environ.get(TRUST_VARIABLE, "").strip().lower() not in ("", "0", "false", "no")


class UntrustedFileError(PecliError):
    """A file that only unpickling can read, refused without ``--trust`` (see :func:`untrusted`)."""


def untrusted(path: str | Path, why: str) -> UntrustedFileError:
    """The one-line refusal of ``path``, which only unpickling can read because ``why``."""
    return UntrustedFileError(f"{path}: {why}; unpickling runs any code its author put in it, so pecli refuses. If you "
                              f"trust where it came from, pass `pecli --trust ...` (or set {TRUST_VARIABLE}=1)")
