"""The dense active-set QP solver on problems that mix single-nonzero rows (bounds, scaled
bounds) with dense rows, against independent references.

* Small problems (n <= 5, m <= 9): every candidate active set is enumerated and its
  equality-constrained KKT system solved with numpy; the one that is primal and dual feasible
  is the exact optimum (unique: the cost is strictly convex). The solver must match it to
  EXACT_TOL.
* Larger problems: KKT residuals at EXACT_TOL and OSQP at 1e-10 tolerances (polished) within
  OSQP_TOL.
* Infeasible problems: the solver says ``infeasible`` exactly when an LP (HiGHS) finds no point.
Degenerate cases are drawn on purpose: duplicate rows, a bound and a dense row on the same
variable, single-nonzero rows with coefficients other than +-1, zero rows.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from mpcdrive.solvers.dense_qp import DenseQpSolver

EXACT_TOL = 1e-9
OSQP_TOL = 1e-6


def _random_rows(rng, n, m):
    """m rows over n variables: about half with a single nonzero (bounds of either sign, some
    scaled), the rest dense, some sparse with two nonzeros (rate rows); duplicates, a bound
    and a dense row on the same variable, and zero rows are mixed in."""
    C = np.zeros((m, n))
    for i in range(m):
        kind = rng.integers(0, 6)
        if kind <= 2:
            C[i, rng.integers(n)] = rng.choice([1.0, -1.0, 2.5, -0.3])
        elif kind == 3 and n >= 2:
            j = rng.integers(1, n)
            C[i, j], C[i, j - 1] = (1.0, -1.0) if rng.random() < 0.5 else (-1.0, 1.0)
        else:
            C[i] = rng.normal(size=n)
    if m >= 2 and rng.random() < 0.3:
        C[m - 1] = C[0]  # duplicate row
    if m >= 3 and rng.random() < 0.3:
        C[m - 2] = 0.0
        C[m - 2, int(np.argmax(np.abs(C[0])))] = 1.0  # a bound on a variable of a dense row
    return C


def _enumerated_optimum(H, g, C, b):
    """The exact minimizer of the strictly convex QP by enumerating active sets (small problems)."""
    n, m = g.size, b.size
    best = None
    for q in range(min(n, m) + 1):
        for S in itertools.combinations(range(m), q):
            A = C[list(S)]
            if q and np.linalg.matrix_rank(A, tol=1e-10) < q:
                continue
            K = np.block([[H, -A.T], [A, np.zeros((q, q))]])
            sol = np.linalg.solve(K, np.concatenate([-g, b[list(S)]]))
            z, lam = sol[:n], sol[n:]
            if (C @ z - b).min(initial=0.0) >= -1e-10 and lam.min(initial=0.0) >= -1e-10:
                if best is not None:
                    assert np.abs(best - z).max() < 1e-8, "two KKT points of a strictly convex QP"
                best = z
    return best


def _feasible(C, b):
    n = C.shape[1]
    res = linprog(np.zeros(n), A_ub=-C, b_ub=-b, bounds=[(None, None)] * n, method="highs")
    return res.status == 0


def _random_problem(rng, n, m, shift=1.0):
    M = rng.normal(size=(n, n))
    H = M @ M.T + 0.1 * np.eye(n)
    g = 3 * rng.normal(size=n)
    C = _random_rows(rng, n, m)
    b = C @ rng.normal(size=n) + rng.uniform(-1.0, shift, size=m)  # some rows violated at any z
    return H, g, C, b


def _kkt(H, g, C, b, r):
    stat = np.abs(H @ r.z + g - C.T @ r.lam).max()
    feas = max(0.0, -(C @ r.z - b).min(initial=0.0))
    comp = np.abs(r.lam * (C @ r.z - b)).max(initial=0.0)
    return stat, feas, comp


def test_small_mixed_qps_match_the_enumerated_exact_optimum():
    rng = np.random.default_rng(5)
    solver = DenseQpSolver(5, 9)
    checked = {"ok": 0, "infeasible": 0}
    for _ in range(400):
        n, m = int(rng.integers(1, 6)), int(rng.integers(1, 10))
        H, g, C, b = _random_problem(rng, n, m, shift=0.3 if rng.random() < 0.5 else 1.5)
        r = solver.solve(H, g, C, b)
        if not _feasible(C, b):
            assert r.status == "infeasible"
            checked["infeasible"] += 1
            continue
        assert r.status == "ok"
        z = _enumerated_optimum(H, g, C, b)
        assert z is not None
        scale = 1 + np.abs(z).max()
        assert np.abs(r.z - z).max() <= EXACT_TOL * scale
        assert r.lam.min() >= 0.0
        stat, feas, comp = _kkt(H, g, C, b, r)
        assert stat <= EXACT_TOL * (1 + np.abs(g).max() + np.abs(H).max()) and feas <= EXACT_TOL
        checked["ok"] += 1
    assert min(checked.values()) >= 40, checked  # both outcomes well covered


@pytest.mark.parametrize("seed", range(4))
def test_larger_mixed_qps_are_exact_and_agree_with_osqp(seed):
    import osqp

    rng = np.random.default_rng(100 + seed)
    solver = DenseQpSolver(60, 160)
    for _ in range(15):
        n, m = int(rng.integers(10, 61)), int(rng.integers(20, 161))
        H, g, C, b = _random_problem(rng, n, m, shift=0.5)
        r = solver.solve(H, g, C, b)
        if not _feasible(C, b):
            assert r.status == "infeasible"
            continue
        assert r.status == "ok"
        scale = 1 + np.abs(g).max() + np.abs(H).max()
        stat, feas, comp = _kkt(H, g, C, b, r)
        assert stat <= EXACT_TOL * scale and feas <= EXACT_TOL and comp <= 1e-8 * scale
        assert r.lam.min() >= 0.0
        o = osqp.OSQP()
        o.setup(
            sp.csc_matrix(np.triu(H)),
            g,
            sp.csc_matrix(C),
            b,
            np.full(m, np.inf),
            eps_abs=1e-10,
            eps_rel=1e-10,
            max_iter=200000,
            verbose=False,
            polishing=True,
        )
        zo = o.solve(raise_error=False).x
        assert np.abs(r.z - zo).max() <= OSQP_TOL * (1 + np.abs(zo).max())


def test_a_guessed_active_set_gives_the_same_solution():
    """Warm starts: with the optimum's own active set as the guess the solve takes no more
    iterations than cold (here: as many as rows it adds); with a random guess (good and bad
    rows mixed) the solution is still the cold one, and an infeasible QP is still infeasible."""
    rng = np.random.default_rng(300)
    solver = DenseQpSolver(40, 100)
    fewer = 0
    for _ in range(60):
        n, m = int(rng.integers(5, 41)), int(rng.integers(10, 101))
        H, g, C, b = _random_problem(rng, n, m, shift=0.5)
        cold = solver.solve(H, g, C, b)
        act = np.flatnonzero(cold.lam > 0)
        exact = solver.solve(H, g, C, b, active_guess=act)
        mixed = solver.solve(H, g, C, b, active_guess=rng.choice(m, size=int(rng.integers(0, m)), replace=False))
        for r in (exact, mixed):
            assert r.status == cold.status
            if cold.status == "ok":
                assert np.abs(r.z - cold.z).max() <= EXACT_TOL * (1 + np.abs(cold.z).max())
                assert np.abs(r.lam - cold.lam).max() <= 1e-7 * (1 + np.abs(cold.lam).max())
        if cold.status == "ok":
            assert exact.iterations <= cold.iterations
            fewer += exact.iterations < cold.iterations
    assert fewer >= 3  # the guess saves iterations where the cold solve drops rows
    with pytest.raises(ValueError, match="active_guess"):
        solver.solve(np.eye(2), np.zeros(2), np.eye(2), np.zeros(2), active_guess=[2])


def test_bounds_only_box_and_conflicting_bounds():
    """A box [lo, hi] on every variable (all rows single-nonzero): the optimum is the projection
    for a diagonal H; lo > hi on one variable is infeasible."""
    rng = np.random.default_rng(3)
    n = 12
    h = rng.uniform(0.5, 3.0, size=n)
    g = 4 * rng.normal(size=n)
    lo, hi = -rng.uniform(0.1, 1.0, n), rng.uniform(0.1, 1.0, n)
    C = np.vstack([np.eye(n), -np.eye(n), 2.0 * np.eye(n)])
    b = np.concatenate([lo, -hi, 2.0 * lo])  # the scaled copy of the lower bounds is degenerate
    r = DenseQpSolver(n, 3 * n).solve(np.diag(h), g, C, b)
    assert r.status == "ok"
    np.testing.assert_allclose(r.z, np.clip(-g / h, lo, hi), rtol=0, atol=1e-12)
    b[0] = hi[0] + 0.1
    assert DenseQpSolver(n, 3 * n).solve(np.diag(h), g, C, b).status == "infeasible"


def _lane_like_problem(rng, n_u, n_s):
    """The shape of the controller's soft-lane QP: inputs with bounds, pairs of opposite dense
    rows ``-a_k z_u + s_k >= .`` and ``a_k z_u + s_k >= .`` (row k reads the first k inputs) that
    share a slack column, and the slacks' sign rows -- pairs nearly dependent once both are
    active, the case where the active set changes through degenerate steps."""
    n = n_u + n_s
    M = rng.normal(size=(n_u, n_u))
    H = np.zeros((n, n))
    H[:n_u, :n_u] = M @ M.T / n_u + 0.05 * np.eye(n_u)
    H[n_u:, n_u:] = 2.0 * rng.uniform(1.0, 100.0) * np.eye(n_s)
    g = np.concatenate([3 * rng.normal(size=n_u), rng.uniform(0.0, 5.0, n_s)])
    rows, rhs = [], []
    for j in range(n_u):
        for sign in (1.0, -1.0):
            r = np.zeros(n)
            r[j] = sign
            rows.append(r)
            rhs.append(-1.0)
    width = rng.uniform(0.05, 0.5)
    for k in range(n_s):
        a = np.zeros(n)
        a[: max(1, (k + 1) * n_u // n_s)] = rng.normal(size=max(1, (k + 1) * n_u // n_s))
        off = rng.normal(scale=2.0)
        for sign in (-1.0, 1.0):
            r = sign * a
            r[n_u + k] = 1.0
            rows.append(r)
            rhs.append(sign * off - width)
    for k in range(n_s):
        r = np.zeros(n)
        r[n_u + k] = 1.0
        rows.append(r)
        rhs.append(0.0)
    return H, g, np.array(rows), np.array(rhs)


def test_soft_lane_shaped_qps_are_exact_and_agree_with_osqp():
    import osqp

    rng = np.random.default_rng(17)
    solver = DenseQpSolver(60, 200)
    for trial in range(200):
        n_u = int(rng.integers(5, 31))
        n_s = int(rng.integers(2, n_u + 1))
        H, g, C, b = _lane_like_problem(rng, n_u, n_s)
        r = solver.solve(H, g, C, b)
        assert r.status == "ok", trial  # slacks make every such problem feasible
        scale = 1 + np.abs(g).max() + np.abs(H).max()
        stat, feas, comp = _kkt(H, g, C, b, r)
        assert stat <= EXACT_TOL * scale and feas <= EXACT_TOL and comp <= 1e-8 * scale, trial
        o = osqp.OSQP()
        o.setup(
            sp.csc_matrix(np.triu(H)),
            g,
            sp.csc_matrix(C),
            b,
            np.full(b.size, np.inf),
            eps_abs=1e-10,
            eps_rel=1e-10,
            max_iter=200000,
            verbose=False,
            polishing=True,
        )
        zo = o.solve(raise_error=False).x
        assert np.abs(r.z - zo).max() <= OSQP_TOL * (1 + np.abs(zo).max()), trial


def _gi(H, g, C, b, rowspan):
    """:func:`gi_solve` on one QP with the given ``rowspan``: (status code, z)."""
    from mpcdrive.solvers.dense_qp import gi_solve, single_nonzero_columns

    n, m = len(g), len(b)
    z, lam = np.zeros(n), np.zeros(m)
    vec = np.zeros((4, n))
    code, _ = gi_solve(
        H, g, C, b, m, n, z, lam, np.zeros(n, np.int64), np.zeros(m, np.int64), single_nonzero_columns(C),
        np.ascontiguousarray(rowspan, np.int64), np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)),
        vec[0], vec[1], vec[2], vec[3], np.zeros(m), np.zeros(m), 10 * (n + m), 1e-9,
    )  # fmt: skip
    return code, z


def test_rows_read_only_where_they_may_be_nonzero_give_the_same_solution():
    """The rows of a condensed MPC QP at stage k reach the first k inputs and one slack: read
    only there (``rowspan``: leading columns, one more column) the solve is the one that reads
    every column. A span that leaves out a nonzero changes it: the span is what is read."""
    from mpcdrive.solvers.dense_qp import row_spans

    rng = np.random.default_rng(7)
    changed = 0
    for _ in range(40):
        nu, n_stage, n_slack = 2, int(rng.integers(3, 12)), 3
        nzu = nu * n_stage
        n = nzu + n_slack
        m = int(rng.integers(10, 60))
        M = rng.normal(size=(n, n))
        H, g = M @ M.T + 0.1 * np.eye(n), 3 * rng.normal(size=n)
        C, span = np.zeros((m, n)), np.zeros((m, 2), np.int64)
        for i in range(m):
            k = int(rng.integers(1, n_stage + 1))
            C[i, : k * nu] = rng.normal(size=k * nu)
            span[i] = (k * nu, -1)
            if rng.random() < 0.5:  # a soft row: its slack
                j = nzu + int(rng.integers(n_slack))
                C[i, j] = 1.0
                span[i, 1] = j
        b = C @ rng.normal(size=n) + rng.uniform(-1.0, 0.5, size=m)
        whole = np.column_stack([np.full(m, n), np.full(m, -1)])
        code_w, z_w = _gi(H, g, C, b, whole)
        code_s, z_s = _gi(H, g, C, b, span)
        assert code_s == code_w
        if code_w == 0:
            assert np.abs(z_s - z_w).max() <= EXACT_TOL * (1 + np.abs(z_w).max())
            short = span.copy()
            short[:, 0] = np.maximum(short[:, 0] - nu, 0)  # each row's last stage left out
            code_c, z_c = _gi(H, g, C, b, short)
            changed += code_c != 0 or np.abs(z_c - z_w).max() > 1e-6
        assert np.array_equal(row_spans(C)[:, 0], np.where(span[:, 1] >= 0, span[:, 1] + 1, span[:, 0]))
    assert changed >= 10
