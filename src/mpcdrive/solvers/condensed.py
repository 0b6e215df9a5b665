"""Compiled solve pieces of the condensed MPC QP, beyond the dense active-set kernel.

The controller (:mod:`mpcdrive.control.fast_step`) builds, each step, the stage data of a
linear-quadratic problem -- dynamics ``x_{k+1} = A_k x_k + B_k u_k + c_k``, state cost
``x' W_k x - 2 q_k' x``, input cost ``(u - u_ref)' R (u - u_ref)`` -- and its condensed form
onto the inputs (and slacks): ``minimize 1/2 z' H z + g' z  subject to  C z >= b``. The
functions here only consume that data; none knows a model, a path or how the rows were made.

* :func:`riccati`: the unconstrained minimizer of the stage problem (no input-rate cost, no
  slack) by the backward Riccati recursion, O(N); with :func:`plan_feasible` (input, rate and
  state bounds within a tolerance) the controller takes it as the QP's solution when it
  violates no bound, and skips condensing.
* :func:`soft_solve`: the condensed QP whose soft rows (grouped, one slack per group) get
  slacks only where they can be nonzero, by the exact-penalty condition on the multipliers of
  :func:`~mpcdrive.solvers.dense_qp.gi_solve`.

Compiled with numba (``cache=True``), working in caller-provided buffers: nothing is allocated
per solve.
"""

from __future__ import annotations

import math

from numba import njit

from .dense_qp import gi_solve


@njit(cache=True)
def riccati(N, nx, nu, A, B, c, qt, uref, Wq, Rm, x, P, p, K, kf, PA, M, G, q, z):
    """Unconstrained minimizer of the tracking cost (no Rc, no slack) by the backward Riccati
    recursion ``V_k(x) = x'P_k x + 2 p_k'x + const``, ``u_k = K_k x_k + kf_k``: O(N) work.
    The state cost of x_k is ``x' Wq[k-1] x - 2 qt[k-1]' x``.

    Scratch: PA (nx, nx), M (nu, nx), G (nu, nu), q (nx,). Writes z[:N nu] = U of the minimizer
    (rolled out from x) and uses p[1:] for the rolled-out states. Returns False if some
    ``R + B'PB`` is not numerically positive definite."""
    for i in range(nx):
        for j in range(nx):
            P[N, i, j] = Wq[N - 1, i, j]
        p[N, i] = -qt[N - 1, i]
    for k in range(N - 1, -1, -1):
        # q = P c + p ; PA = P A ; M = B'PA ; G = R + B'PB ; h = B'q - R ur (in kf[k])
        for i in range(nx):
            t = p[k + 1, i]
            for j in range(nx):
                t += P[k + 1, i, j] * c[k, j]
            q[i] = t
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += P[k + 1, i, l] * A[k, l, j]
                PA[i, j] = t
        for a in range(nu):
            for j in range(nx):
                t = 0.0
                for l in range(nx):
                    t += B[k, l, a] * PA[l, j]
                M[a, j] = t
            for e in range(nu):
                t = Rm[a, e]
                for l in range(nx):
                    pb = 0.0
                    for m_ in range(nx):
                        pb += P[k + 1, l, m_] * B[k, m_, e]
                    t += B[k, l, a] * pb
                G[a, e] = t
            t = 0.0
            for l in range(nx):
                t += B[k, l, a] * q[l]
            for e in range(nu):
                t -= Rm[a, e] * uref[k, e]
            kf[k, a] = t
        # G = L L' (in place, lower); K = -G^{-1} M ; kf = -G^{-1} h
        for j in range(nu):
            t = G[j, j]
            for l in range(j):
                t -= G[j, l] * G[j, l]
            if not (t > 1e-14 * max(1.0, abs(G[j, j]))):
                return False
            G[j, j] = math.sqrt(t)
            for i in range(j + 1, nu):
                t = G[i, j]
                for l in range(j):
                    t -= G[i, l] * G[j, l]
                G[i, j] = t / G[j, j]
        for col in range(nx + 1):
            for a in range(nu):
                q_a = M[a, col] if col < nx else kf[k, a]
                for l in range(a):
                    q_a -= G[a, l] * (K[k, l, col] if col < nx else kf[k, l])
                if col < nx:
                    K[k, a, col] = q_a / G[a, a]
                else:
                    kf[k, a] = q_a / G[a, a]
            for a in range(nu - 1, -1, -1):
                t = K[k, a, col] if col < nx else kf[k, a]
                for l in range(a + 1, nu):
                    t -= G[l, a] * (K[k, l, col] if col < nx else kf[k, l])
                if col < nx:
                    K[k, a, col] = t / G[a, a]
                else:
                    kf[k, a] = t / G[a, a]
        for a in range(nu):
            for col in range(nx):
                K[k, a, col] = -K[k, a, col]
            kf[k, a] = -kf[k, a]
        if k >= 1:
            # P_k = W_k + A'PA + M'K ; p_k = -W_k r_k + A'q + M'kf
            for i in range(nx):
                t = -qt[k - 1, i]
                for l in range(nx):
                    t += A[k, l, i] * q[l]
                for a in range(nu):
                    t += M[a, i] * kf[k, a]
                p[k, i] = t
                for j in range(nx):
                    t = Wq[k - 1, i, j]
                    for l in range(nx):
                        t += A[k, l, i] * PA[l, j]
                    for a in range(nu):
                        t += M[a, i] * K[k, a, j]
                    P[k, i, j] = t
    # roll out u_k = K_k x_k + kf_k from x (states staged in p[k + 1])
    for k in range(N):
        for a in range(nu):
            t = kf[k, a]
            for j in range(nx):
                t += K[k, a, j] * (x[j] if k == 0 else p[k, j])
            z[k * nu + a] = t
        for i in range(nx):
            t = c[k, i]
            for j in range(nx):
                t += A[k, i, j] * (x[j] if k == 0 else p[k, j])
            for a in range(nu):
                t += B[k, i, a] * z[k * nu + a]
            q[i] = t
        for i in range(nx):
            p[k + 1, i] = q[i]
    return True


@njit(cache=True)
def plan_feasible(N, nx, nu, z, Xr, u_prev, u_lo, u_hi, dmax, x_min, x_max, tol):
    """Whether inputs z (N nu) and states Xr[1..N] satisfy the per-stage input bounds u_lo,
    u_hi (N, nu), the rate and the state bounds within tol (NaN never does)."""
    for k in range(N):
        for a in range(nu):
            u = z[k * nu + a]
            if not (u >= u_lo[k, a] - tol and u <= u_hi[k, a] + tol):
                return False
            prev = u_prev[a] if k == 0 else z[(k - 1) * nu + a]
            if not (abs(u - prev) <= dmax[a] + tol):
                return False
        for i in range(nx):
            v = Xr[k + 1, i]
            if not (v >= x_min[i] - tol and v <= x_max[i] + tol):
                return False
    return True


@njit(cache=True)
def _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, every) -> bool:
    """Flag (kpos = 1) every slack group (``every``; else every group without a slack, kpos 0)
    whose rows' multipliers sum to more than its slack's l1 weight; True if none does (zero
    slacks are then optimal there)."""
    for grp in range(2 * N):
        gsum[grp] = 0.0
    for rr in range(m_soft, m):
        gsum[rgrp[rr]] += lam[rr]
    done = True
    for grp in range(2 * N):
        if (every or kpos[grp] == 0) and gsum[grp] > (w1l if grp < N else w1o):
            kpos[grp] = 1
            done = False
    return done


@njit(cache=True)
def soft_solve(
    H,
    g,
    C,
    b,
    m,
    m_soft,
    rgrp,
    N,
    nzu,
    kpos,
    w2l,
    w1l,
    w2o,
    w1o,
    gsum,
    z,
    lam,
    active,
    isact,
    rowcol,
    L,
    J,
    Rq,
    d,
    zdir,
    r,
    uq,
    sq,
    rown,
    max_iter,
    tol,
):
    """The condensed QP with soft rows, their slacks only where they can be nonzero.

    ``H[:nzu, :nzu]``, ``g[:nzu]`` are the input part; rows ``[0, m)`` of ``C z >= b`` the
    constraints, of which rows ``[m_soft, m)`` are soft: row ``rr`` belongs to slack group
    ``rgrp[rr]`` (the lane rows of step k to group k, slack weights ``w2l`` quadratic, ``w1l``
    linear; the obstacle rows of step k to group N + k, weights ``w2o``, ``w1o``), one slack per
    group shared by its rows, as in ``ocp.qp``. First the inputs alone, soft rows hard: if that
    solves and no group's multipliers sum to more than its slack's l1 weight, zero slacks satisfy
    the optimality conditions of the soft problem (exact penalty), so it is its solution. Else
    slacks are given to the groups flagged in ``kpos`` (1 = slack; the caller flags those the
    linearization violates), plus every group whose multipliers exceed the weight, and solved
    again until no group without a slack exceeds it (or with a slack on every group that has
    rows: the full problem). The slacks' sign rows follow row m (``rowcol`` names their single
    nonzero; the other rows written per step are marked dense there). z[:nzu] holds the inputs."""
    code, iters = gi_solve(
        H, g, C, b, m, nzu, z, lam, active, isact, rowcol, L, J, Rq, d, zdir, r, uq, sq, rown, max_iter, tol
    )
    if code == 0 and _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, True):
        return 0, iters
    full = False
    for _round in range(2 * N + 1):
        nk = 0
        if full or (code != 0 and _round == 0):
            # no (useful) flags: a slack on every group that has rows
            nflag = 0
            for grp in range(2 * N):
                nflag += 1 if kpos[grp] != 0 else 0
            if full or nflag == 0:
                for grp in range(2 * N):
                    kpos[grp] = 0
                for rr in range(m_soft, m):
                    kpos[rgrp[rr]] = 1
                full = True
        for grp in range(2 * N):
            if kpos[grp] != 0:
                kpos[grp] = nk + 1  # 1-based slack position
                nk += 1
        n2 = nzu + nk
        for a in range(nk):
            jj = nzu + a
            for cc in range(n2):
                H[jj, cc] = 0.0
                H[cc, jj] = 0.0
        for grp in range(2 * N):
            if kpos[grp] > 0:
                jj = nzu + kpos[grp] - 1
                H[jj, jj] = 2.0 * (w2l if grp < N else w2o)
                g[jj] = w1l if grp < N else w1o
        for rr in range(m_soft, m):
            for cc in range(nzu, n2):
                C[rr, cc] = 0.0
            grp = rgrp[rr]
            if kpos[grp] > 0:
                C[rr, nzu + kpos[grp] - 1] = 1.0
        for a in range(nk):
            rr = m + a
            for cc in range(n2):
                C[rr, cc] = 0.0
            C[rr, nzu + a] = 1.0
            b[rr] = 0.0
            rowcol[rr] = nzu + a
        code, it2 = gi_solve(
            H, g, C, b, m + nk, n2, z, lam, active, isact, rowcol, L, J, Rq, d, zdir, r, uq, sq, rown, max_iter, tol
        )
        iters += it2
        if code != 0:
            if full:
                return code, iters
            full = True
            continue
        for grp in range(2 * N):
            if kpos[grp] > 0:
                kpos[grp] = 1
        if _group_excess(lam, m_soft, m, rgrp, N, w1l, w1o, gsum, kpos, False):
            return 0, iters
    return 3, iters


# numba keys this module's cache to this file only; soft_solve links in code from dense_qp
from .. import _jitcache  # noqa: E402
from . import dense_qp as _dense_qp  # noqa: E402

_jitcache.refresh(soft_solve, [f for f in (_dense_qp.__file__,) if f is not None])
