"""Keep numba's on-disk cache honest about dependencies.

numba invalidates a cached function when *its own* source file changes, not when a function it
calls or inlines (in another file) changes. The compiled controller links in the model equations,
the path geometry and the QP solver from other modules, so after an edit of one of those a stale
cache would silently keep the old machine code. :func:`drop_stale_cache` fingerprints the
dependency sources and deletes the module's cache files when the fingerprint changed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path


def drop_stale_cache(cache_dir: str | Path, stem: str, dependencies: Iterable[str | Path]) -> bool:
    """Delete ``cache_dir/<stem>.*.nbi|nbc`` unless the SHA-1 of the ``dependencies``' contents
    matches the one recorded at the last call; record it. Returns True when files were dropped
    (or no fingerprint was recorded yet). Never raises for an unwritable cache directory."""
    h = hashlib.sha1()
    for p in sorted(str(d) for d in dependencies):
        h.update(p.encode())
        h.update(Path(p).read_bytes())
    digest = h.hexdigest()
    cache_dir = Path(cache_dir)
    stamp = cache_dir / f"{stem}.deps-sha1"
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    try:
        for f in list(cache_dir.glob(f"{stem}.*.nbi")) + list(cache_dir.glob(f"{stem}.*.nbc")):
            f.unlink(missing_ok=True)
        cache_dir.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        pass
    return True


def _cache_location(function) -> tuple[Path, str] | None:
    """(cache directory, file stem) of a compiled ``function``'s module -- a ``@njit`` dispatcher
    or a ``@subroutine``, both with ``py_func`` -- as numba's own cache locator finds it for the
    Python function; None if this numba cannot say."""
    try:
        from numba.core.caching import FunctionCache

        py_func = function.py_func
        return Path(FunctionCache(py_func)._cache_path), Path(py_func.__code__.co_filename).stem
    except (AttributeError, ImportError, RuntimeError):
        return None


def refresh(function, dependencies: Iterable[str | Path]) -> None:
    """:func:`drop_stale_cache` for the module of a compiled ``function`` (see
    :func:`_cache_location`): its own file, the ``dependencies`` and the subroutine mechanism
    (``_subroutine.py``, which shapes all compiled code) are fingerprinted. Does nothing if
    numba cannot locate the cache."""
    where = _cache_location(function)
    if where is None:
        return
    cache_dir, stem = where
    own = function.py_func.__code__.co_filename
    drop_stale_cache(cache_dir, stem, [*dependencies, own, Path(__file__).with_name("_subroutine.py")])


def has_cache(dispatcher) -> bool:
    """True when numba's cache holds an index for ``dispatcher`` (a later process loads it instead
    of compiling); False when none is found or this numba keeps it elsewhere."""
    where = _cache_location(dispatcher)
    if where is None:
        return False
    cache_dir, stem = where
    return any(cache_dir.glob(f"{stem}.{dispatcher.py_func.__name__}-*.nbi"))
