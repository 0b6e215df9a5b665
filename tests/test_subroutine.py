"""Subroutines: compiled only inside their compiled callers (mpcdrive._subroutine)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from mpcdrive._subroutine import Subroutine, subroutine


@subroutine
def _weighted_sum(a, n, w):
    s = 0.0
    for i in range(n):
        s += w * a[i]
    return s


@subroutine
def _twice_head(a, n):
    # constant arguments: typed as literals, as for a @njit callee
    return _weighted_sum(a, n, 2.0)


@njit
def _caller(a):
    return _twice_head(a, 3) + _weighted_sum(a, a.shape[0], 1.0)


@subroutine(fastmath=True)
def _fast_dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@njit
def _dot_caller(a, b):
    return _fast_dot(a, b)


@subroutine
def _bad(a):
    return a.no_such_attribute


@njit
def _bad_caller(a):
    return _bad(a)


def test_compiled_result_matches_python():
    a = np.arange(1.0, 6.0)
    expected = 2.0 * (1 + 2 + 3) + a.sum()
    assert _caller(a) == pytest.approx(expected, rel=0, abs=1e-12)
    assert _caller.py_func(a) == pytest.approx(expected, rel=0, abs=1e-12)


def test_called_from_python_runs_compiled_copy():
    a = np.arange(4.0)
    assert _weighted_sum(a, 4, 0.5) == pytest.approx(3.0)
    assert _weighted_sum._python_entry is not None  # the @njit copy was made and used
    assert _weighted_sum._python_entry.signatures


def test_constant_arguments_specialize():
    _caller(np.arange(5.0))
    kinds = {tuple(str(t) for t in sig[1:]) for sig in _weighted_sum._compiled}
    # one copy for the constant size 3 and weight 2.0 of _twice_head, one for run-time values
    assert any("Literal[int](3)" in k[0] for k in kinds)
    assert any(k[0] == "int64" for k in kinds)


def test_linked_without_finalizing_its_own_library():
    """The point of a subroutine: its library is never optimized and emitted by itself."""
    _caller(np.arange(5.0))
    assert _twice_head._links
    for link in [*_twice_head._links.values(), *_weighted_sum._links.values()]:
        assert link._library._finalized is False
    # the caller's library holds the code
    assert _caller.overloads[_caller.signatures[0]].library._finalized


def test_options_reach_the_compiled_code():
    """``fastmath=True`` reaches the compile: the subroutine's arithmetic carries LLVM's fast-math
    flags, and a subroutine without the option has none."""
    a, b = np.arange(3.0), np.ones(3)
    assert _dot_caller(a, b) == pytest.approx(3.0)
    _caller(np.arange(5.0))
    (cres,) = _fast_dot._compiled.values()
    assert "fmul fast" in cres.library.get_llvm_str()
    plain = "".join(c.library.get_llvm_str() for c in _weighted_sum._compiled.values())
    assert "fmul " in plain and "fmul fast" not in plain


def test_typing_error_surfaces_in_the_caller():
    with pytest.raises(TypingError, match="no_such_attribute"):
        _bad_caller(np.arange(3.0))


def test_is_a_subroutine_with_the_function_name():
    assert isinstance(_weighted_sum, Subroutine)
    assert _weighted_sum.__name__ == "_weighted_sum"
    assert "_weighted_sum" in repr(_weighted_sum)


@subroutine
def _expensive_branch(a):
    return a.no_such_attribute  # a typing error if it were ever typed


@subroutine
def _by_kind(kind, a):
    if kind == 6:
        return _expensive_branch(a)
    return a[0]


@njit
def _by_kind_caller(a):
    return _by_kind(3, a)


def test_constant_argument_prunes_the_branch_not_taken():
    # the kind-6 branch would not type; with the constant 3 it is dropped before typing
    assert _by_kind_caller(np.array([4.0, 5.0])) == 4.0
    assert not _expensive_branch._compiled
