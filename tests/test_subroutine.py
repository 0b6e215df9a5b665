"""Subroutines: compiled only inside their compiled callers (mpcdrive._subroutine)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from mpcdrive._subroutine import Subroutine, subroutine
from mpcdrive.planning.frenet import grid_at


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


# -- borrowed arguments: no reference counting where nothing counted is made or handed back --


@subroutine
def _tail_element(a, i):
    tail = a[1:]  # a view of an argument: borrowed
    return tail[i] * 2.0


@subroutine
def _fresh(n):
    return np.zeros(n)  # allocates and hands the array back: keeps the counts


@subroutine
def _sum_of_fresh(n):
    x = _fresh(n)  # receives a counted value from a call: keeps the counts (else it leaks)
    return x.sum() + n


@subroutine
def _iterated(a):
    s = 0.0
    for v in a:  # an iterator over an array holds a reference: keeps the counts
        s += v
    return s


@subroutine
def _same(a):
    return a  # hands an argument back: keeps the counts


@subroutine
def _store_first(box, a):
    box[0] = a  # stores a counted value where it outlives the call: keeps the counts
    return 0.0


@njit
def _store_caller(a):
    box = [np.zeros(1)]
    _store_first(box, a)
    return box[0][0]


@njit
def _borrow_caller(a, n):
    return _tail_element(a, 1) + _sum_of_fresh(n) + _iterated(a) + _same(a)[0]


def _only(sub):
    (flag,) = sub.borrows.values()
    return flag


def test_borrowing_where_safe_and_counting_elsewhere():
    a = np.arange(3.0)
    assert _borrow_caller(a, 3) == pytest.approx(2.0 * 2.0 + 3.0 + 3.0 + 0.0, rel=0, abs=1e-12)
    assert _only(_tail_element) is True
    assert _only(_fresh) is False
    assert _only(_sum_of_fresh) is False
    assert _only(_iterated) is False
    assert _only(_same) is False
    assert _store_caller(np.array([7.0])) == 7.0
    assert _only(_store_first) is False
    # a subroutine that reads arrays and returns a number, as most of the planner's do
    _caller(np.arange(5.0))
    assert all(_weighted_sum.borrows.values())


def test_borrowing_loses_no_allocation():
    """Every array the borrowing tree allocates is freed again: a caller that took a fresh array
    from a call without counting it down would leak one per call."""
    from numba.core.runtime import _nrt_python, rtsys

    a = np.arange(3.0)
    _borrow_caller(a, 3)
    was_on = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats()
        for _ in range(50):
            _borrow_caller(a, 3)
        after = rtsys.get_allocation_stats()
    finally:
        if not was_on:
            _nrt_python.memsys_disable_stats()
    allocated = after.alloc - before.alloc
    assert allocated >= 50  # _fresh allocates at every call
    assert after.free - before.free == allocated
    assert after.mi_alloc - before.mi_alloc == after.mi_free - before.mi_free


def test_explicit_counting_option_is_kept():
    """``_nrt`` given by the caller of the decorator decides (no second lowering)."""

    @subroutine(_nrt=True)
    def counted(a):
        return a[0]

    @njit
    def call(a):
        return counted(a)

    assert call(np.ones(2)) == 1.0
    assert _only(counted) is False


_grid_at_counted = subroutine(_nrt=True)(grid_at.py_func)  # numba's own lowering of the same


@njit
def _grid_at_both(grid, tab, s):
    return grid_at(grid, tab, s) - _grid_at_counted(grid, tab, s)


def _nrt_calls(module) -> list[str]:
    """The NRT functions the module's code calls (counting, destructors...)."""
    return re.findall(r"call [^\n]*@(NRT_\w+)", str(module))


def test_borrowing_code_has_no_counting_calls():
    """The code of a borrowing subroutine (the planner's grid lookup: several returns, where
    numba's lowering keeps its counts) calls nothing of NRT, where numba's own lowering of the
    same function counts its array arguments in and out; both compute the same."""
    grid, tab = np.array([0.0, 0.5, 4.0, 2.0]), np.array([0.0, 10.0, 20.0, 30.0])
    for s in (-1.0, 0.75, 9.0):
        assert _grid_at_both(grid, tab, s) == 0.0
    assert grid_at.py_func(grid, tab, 0.75) == pytest.approx(15.0, rel=0, abs=1e-12)
    for args, link in grid_at._links.items():
        assert grid_at.borrows[args]
        assert _nrt_calls(link._library._final_module) == []
    for args, link in _grid_at_counted._links.items():
        assert not _grid_at_counted.borrows[args]
        assert "NRT_incref" in _nrt_calls(link._library._final_module)
