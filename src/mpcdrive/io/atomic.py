"""Atomic file and directory output: a reader sees complete files or none.

Files are written to a temporary sibling, flushed to disk (``fsync``) and moved into place with
``os.replace`` (atomic on POSIX and Windows when source and target share a file system, which a
sibling always does).  :func:`atomic_output_dir` does the same for a whole run directory, so an
interrupted run leaves either its complete output or nothing.

Every temporary path (and every parent directory made for one) is known to :func:`discard_unfinished`
from before it exists until it is committed or removed: a process that must end at once (a signal
handler that cannot let an exception unwind through the code it interrupted) calls it to leave
nothing half-written behind.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path

__all__ = ["OutputPathError", "atomic_output_dir", "atomic_write_bytes", "atomic_write_text", "discard_unfinished"]


class OutputPathError(OSError):
    """An output cannot be made where it was asked for (a file where a folder must be, no
    permission, a read-only file system); the message names the path as given and why, never
    the temporary name. Nothing was written."""


def _unwritable(given: Path, e: OSError) -> OutputPathError:
    blocker = next((a for a in (given, *given.parents) if a.exists()), None)
    why = f"{blocker} is a file, not a folder" if blocker is not None and not blocker.is_dir() else e.strerror or str(e)
    return OutputPathError(f"cannot write {given}: {why}")


#: temporary paths that exist (or are about to) and are not committed yet, and the parent
#: directories made for them, in the order made: what :func:`discard_unfinished` removes
_UNFINISHED: dict[Path, None] = {}
_MADE_PARENTS: dict[Path, None] = {}


def discard_unfinished() -> None:
    """Remove every temporary file and directory this process has not committed yet, then every
    parent directory made for one that is empty now. Safe to call at any moment (also from a
    signal handler, between any two statements of the writer: a path not created yet or already
    renamed is skipped); never raises."""
    for tmp in list(_UNFINISHED):
        if tmp.is_dir() and not tmp.is_symlink():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                tmp.unlink()
    _remove_made_parents()


def _remove_made_parents() -> None:
    for parent in reversed(list(_MADE_PARENTS)):
        with contextlib.suppress(OSError):
            parent.rmdir()  # only when empty
            _MADE_PARENTS.pop(parent, None)


def _make_parents(directory: Path) -> None:
    """``directory.mkdir(parents=True, exist_ok=True)``, remembering the directories it made."""
    missing = [d for d in (directory, *directory.parents) if not d.exists()]
    for d in reversed(missing):
        _MADE_PARENTS[d] = None
        d.mkdir(exist_ok=True)


def _forget_parents(committed: Path) -> None:
    """Once ``committed`` is in place, the parents made for it belong to it and are no longer
    discarded -- up to an unfinished output it lies in, whose parents are still that output's."""
    unfinished = {u.resolve() for u in _UNFINISHED}  # (resolved: a path may be given through a link)
    made = {m.resolve(): m for m in _MADE_PARENTS}
    for d in committed.resolve().parents:
        if d in unfinished:
            return
        if d in made:
            _MADE_PARENTS.pop(made[d], None)


def _reserve(directory: Path, prefix: str, make) -> Path:
    """A new temporary path ``directory/<prefix><random>.tmp``, registered before ``make(path)``
    creates it (so an interruption between the two cannot leave it unknown)."""
    while True:
        tmp = directory / f"{prefix}{secrets.token_hex(4)}.tmp"
        _UNFINISHED[tmp] = None
        try:
            make(tmp)
            return tmp
        except FileExistsError:
            _UNFINISHED.pop(tmp, None)


def _fsync_dir(directory: Path) -> None:
    """Flush a directory entry to disk where the platform allows it (POSIX); else do nothing."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; create the parent directory if needed.

    The bytes go to a temporary file in the same directory, which is fsynced and then renamed
    over ``path``.  On any error the temporary file is removed and ``path`` is left untouched
    (:class:`OutputPathError` when the file cannot be made there). Returns the path written.
    """
    target = Path(path)
    fds: list[int] = []
    try:
        _make_parents(target.parent.absolute())
        tmp = _reserve(
            target.parent.absolute(),
            f".{target.name}.",
            lambda p: fds.append(os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)),  # umask applies
        )
    except OSError as e:
        _remove_made_parents()
        raise _unwritable(target, e) from None
    try:
        with os.fdopen(fds[0], "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        _forget_parents(target.absolute())
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        _remove_made_parents()
        raise
    finally:
        _UNFINISHED.pop(tmp, None)
    _fsync_dir(target.parent)
    return target


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`); newlines as given."""
    return atomic_write_bytes(path, text.encode(encoding))


def _check_free(final: Path) -> None:
    if final.exists():
        if not final.is_dir():
            raise FileExistsError(f"output path {final} exists and is not a directory")
        if any(final.iterdir()):
            raise FileExistsError(
                f"output directory {final} already exists and is not empty; choose another --out or remove it"
            )


@contextlib.contextmanager
def atomic_output_dir(final_dir: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary sibling directory that becomes ``final_dir`` only on success.

    Write every output file of a run into the yielded directory.  When the ``with`` block ends
    without an exception the directory is renamed to ``final_dir``; when it raises (including
    ``KeyboardInterrupt``) the temporary directory is deleted and the exception propagates, so
    ``final_dir`` holds complete output or does not exist. The yielded path is absolute (a
    relative ``final_dir`` is taken from the working directory at the call), and the directory
    gets the permissions the user's umask gives a new directory.

    Raises ``FileExistsError`` (before the block runs, and again before the rename) when
    ``final_dir`` exists and is not an empty directory, :class:`OutputPathError` (before the
    block runs) when it cannot be made there.  An existing empty directory is replaced.
    """
    final = Path(final_dir).absolute()
    _check_free(final)
    try:
        _make_parents(final.parent)
        tmp = _reserve(final.parent, f".{final.name}.", lambda p: p.mkdir(0o777))  # umask applies
    except OSError as e:
        _remove_made_parents()
        raise _unwritable(Path(final_dir), e) from None
    try:
        yield tmp
        _check_free(final)
        if final.exists():
            final.rmdir()  # empty (checked above); rename onto a directory is not portable
        os.replace(tmp, final)
        _forget_parents(final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_made_parents()
        raise
    finally:
        _UNFINISHED.pop(tmp, None)
    _fsync_dir(final.parent)
