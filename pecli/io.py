"""Atomic file writes (a file is either its old self or complete, never half-written) and content hashes."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from pydantic import BaseModel, ValidationError

from pecli.text import article


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


RecordT = TypeVar("RecordT", bound="BaseModel")
_UMASK = _read_umask()  # read once at import: os.umask() changes a process-wide setting


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix) to write to; on success it replaces ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
    try:
        yield Path(tmp)
        with open(tmp, "rb") as handle:  # on disk before it takes the real name
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def atomic_write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON to ``path`` atomically."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


def path_inside(path: str | Path, room: str | Path) -> bool:
    """Whether ``path`` is ``room`` or lies inside it once every link is resolved: a file a record names from a
    stranger's zoo is read only inside that zoo."""
    real, home = Path(os.path.realpath(path)), Path(os.path.realpath(room))
    return real == home or home in real.parents


def text_digest(text: str, length: int = 16) -> str:
    """The first ``length`` hex digits of the SHA-256 of ``text`` (UTF-8): a short, stable name for content."""
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def file_digest(path: str | Path, length: int = 20) -> str:
    """The first ``length`` hex digits of the SHA-256 of a file's content."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:length]


MAX_RECORD_BYTES = 64 << 20  # a JSON record pecli reads back: results, mixtures, best-response summaries


def read_bounded(path: Path, what: str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (a link to one is followed): :class:`~pecli.errors.PecliError` in one
    line naming ``what`` if it is something else (a FIFO would block, a device never end) or holds more than
    ``max_bytes``, whatever size the file system reports; :class:`OSError` if it cannot be read."""
    import stat

    from pecli.errors import PecliError

    if not stat.S_ISREG(path.stat().st_mode):
        raise PecliError(f"{path}: not a regular file, so no {what}")
    with path.open("rb") as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise PecliError(f"{path}: more bytes than {article(what)} can be ({max_bytes:,})")
    return data


def read_json(path: str | Path, what: str, max_bytes: int = MAX_RECORD_BYTES) -> Any:
    """The JSON in ``path``, read as data: :class:`~pecli.errors.PecliError` (one line naming ``what``) if it is
    missing, larger than ``max_bytes``, not JSON or nested too deep to parse."""
    from pecli.errors import PecliError

    path = Path(path)
    try:
        return json.loads(read_bounded(path, what, max_bytes).decode("utf-8"))
    except FileNotFoundError:
        raise PecliError(f"{path}: no {what} there") from None
    except (OSError, ValueError, RecursionError) as exc:  # ValueError: not JSON, or an integer of > 4300 digits
        reason = "nested too deep" if isinstance(exc, RecursionError) else str(exc)
        raise PecliError(f"{path}: damaged {what} ({reason})") from None


def first_problem(exc: ValidationError, top: str = "top level") -> str:
    """``key.path: message`` of a pydantic error's first problem (``top`` for the record as a whole)."""
    first = exc.errors()[0]
    return f"{'.'.join(str(part) for part in first['loc']) or top}: {first['msg']}"


def read_output_record(path: Path, model: type[RecordT], what: str) -> RecordT | None:
    """An output folder's record at ``path`` validated as ``model`` (a pydantic model); None if there is none yet;
    :class:`~pecli.errors.PecliError` in one line (``not a <what> ...; use another --out``) if it is not one."""
    from pydantic import ValidationError

    from pecli.errors import PecliError

    if not path.is_file():
        return None
    try:
        return model.model_validate(read_json(path, what))
    except ValidationError as exc:
        raise PecliError(f"{path}: not {article(what)} ({first_problem(exc)}); use another --out") from None
