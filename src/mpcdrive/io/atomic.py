"""Atomic file and directory output: a reader sees complete files or none.

Files are written to a temporary sibling, flushed to disk (``fsync``) and moved into place with
``os.replace`` (atomic on POSIX and Windows when source and target share a file system, which a
sibling always does).  :func:`atomic_output_dir` does the same for a whole run directory, so an
interrupted run leaves either its complete output or nothing.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_output_dir", "atomic_write_bytes", "atomic_write_text"]


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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; create the parent directory if needed.

    The bytes go to a temporary file in the same directory, which is fsynced and then renamed
    over ``path``.  On any error the temporary file is removed and ``path`` is left untouched.
    Returns the path written.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # as open() would make it (mkstemp makes 0600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_name)
        raise
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
    ``final_dir`` exists and is not an empty directory.  An existing empty directory is replaced.
    """
    final = Path(final_dir).absolute()
    _check_free(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=final.parent))
    try:
        tmp.chmod(0o777 & ~_umask())  # mkdtemp makes 0700
        yield tmp
        _check_free(final)
        if final.exists():
            final.rmdir()  # empty (checked above); rename onto a directory is not portable
        os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _fsync_dir(final.parent)
