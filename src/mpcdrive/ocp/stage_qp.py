"""The stage QP of one step, as a typed container that compiled solvers take whole.

:class:`StageQp` is what the step assembly (:mod:`mpcdrive.ocp.assembly`) writes each step and
what a solver (:func:`mpcdrive.solvers.condensed.condensed_solve`) reads: per stage the affine
model, the costs, the input bounds, the road rows and the obstacle rows, in the notation of
``ocp.qp``. Its arrays are allocated once per controller (:func:`new_stage_qp`) and updated in
place; :meth:`StageQp.struct` is the same memory as one numba struct (see
:mod:`mpcdrive._structs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from .._structs import define_struct, to_struct
from .problem import MpcProblem


@dataclass(frozen=True, eq=False)
class StageQp:
    """One step's stage QP (N stages, nx states, nu inputs).

    Dynamics ``x_{k+1} = A_k x_k + B_k u_k + c_k``: ``A`` (N, nx, nx), ``B`` (N, nx, nu), ``c``
    (N, nx). State cost of x_1..x_N ``x' We_k x - 2 qt_k' x``: ``We`` (N, nx, nx), ``qt`` (N, nx)
    (the weights plus an obstacle cost's convex model), with the state references ``xref``
    (N+1, nx) they were made from. Input cost ``(u_k - uref_k)' R (u_k - uref_k) + (u_k -
    u_{k-1})' Rc (u_k - u_{k-1})``: ``R``, ``Rc`` (nu, nu), ``uref`` (N, nu). Input bounds per
    stage ``ulo``, ``uhi`` (N, nu) inside the problem's ``u_min``, ``u_max`` (nu,) (a bound is a
    row only where the problem's is finite); rate limit ``dmax`` (nu,) per step; state bounds
    ``x_min``, ``x_max`` (nx,). With ``lane`` the road rows of x_1..x_N ``lane_lo_k +
    lane_dlo_k psi_k <= lane_n_k . (x, y) - lane_b_k <= lane_hi_k + lane_dhi_k psi_k`` [m] in the
    body's yaw relative to the road, ``psi_k = yaw - ybar_k - lane_t_k . ((x, y) - pbar_k)``
    [rad]: its yaw off that of the linearization trajectory ``Xlin`` (N+1, nx) (ybar, pbar), less
    the road's turn over the distance moved along it (``lane_t`` (N, 2) [1/m]: the path's
    curvature times its tangent, so a car that goes further into a bend meets the road turned
    further); slack weights ``w2_lane`` (quadratic) and ``w1_lane`` (linear). ``nrow`` obstacle rows per stage
    ``rowa_kq . (x, y, yaw)_k >= rowb_kq`` (``rowb`` -inf: unused), slack weights ``w2_obs``,
    ``w1_obs``.
    """

    N: int
    nx: int
    nu: int
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    We: np.ndarray
    qt: np.ndarray
    xref: np.ndarray
    R: np.ndarray
    Rc: np.ndarray
    uref: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    ulo: np.ndarray
    uhi: np.ndarray
    dmax: np.ndarray
    x_min: np.ndarray
    x_max: np.ndarray
    lane: bool
    lane_n: np.ndarray
    lane_b: np.ndarray
    lane_lo: np.ndarray
    lane_hi: np.ndarray
    lane_dlo: np.ndarray
    lane_dhi: np.ndarray
    lane_t: np.ndarray
    Xlin: np.ndarray
    nrow: int
    rowa: np.ndarray
    rowb: np.ndarray
    w2_lane: float
    w1_lane: float
    w2_obs: float
    w1_obs: float

    def struct(self):
        """The compiled struct of this stage QP (the same arrays)."""
        return to_struct(self, _build_stage_qp)

    def posed_for(self, problem: MpcProblem) -> StageQp:
        """This step posed for ``problem``, a problem of the same size (e.g. the fallback's
        relaxed one, :func:`mpcdrive.control.fallback.relaxed_problem`): this stage QP's per-step
        arrays (the same arrays, not copies: what is written here is seen there) with
        ``problem``'s constant parts (:data:`CONSTANT_FIELDS`). Raises ``ValueError`` for a
        problem of another size."""
        if (problem.N, problem.nx, problem.nu, bool(problem.lane)) != (self.N, self.nx, self.nu, self.lane):
            raise ValueError(
                f"a stage QP of N={self.N}, nx={self.nx}, nu={self.nu} cannot be posed for a problem of "
                f"N={problem.N}, nx={problem.nx}, nu={problem.nu}"
            )
        other = new_stage_qp(problem, self.nrow)
        return replace(self, **{f: getattr(other, f) for f in CONSTANT_FIELDS})


#: the fields of a :class:`StageQp` that its problem sets once (the rest are written each step;
#: ``R`` and ``Rc`` are the problem's unless a step scales its steering's, :func:`weigh_steering`)
CONSTANT_FIELDS = ("u_min", "u_max", "dmax", "x_min", "x_max", "w2_lane", "w1_lane", "w2_obs", "w1_obs")


def steering_weight_factor(v_mps: float, speed_mps: float | None) -> float:
    """The factor on the problem's steering weights at the speed ``v_mps`` [m/s]:
    ``(v / speed_mps)^4`` above ``speed_mps``, else 1 (and 1 for None, or a speed that is not a
    number): the weights that hold the lateral loop's bandwidth at that of ``speed_mps``
    (:class:`~mpcdrive.control.MpcConfig`, ``steer_weight_speed_mps``)."""
    if speed_mps is None or not v_mps > speed_mps:
        return 1.0
    return float((v_mps / speed_mps) ** 4)


def weigh_steering(qp: StageQp, problem: MpcProblem, i_steer: int, factor: float) -> None:
    """Write ``problem``'s input weights into ``qp.R``, ``qp.Rc`` with the steering input's
    (index ``i_steer``) scaled by ``factor`` (>= 1): ``S R S`` with ``S`` the identity but
    ``sqrt(factor)`` at the steering, as if the steering were measured in a unit ``sqrt(factor)``
    times larger (the diagonal entry ``factor`` times, the cross terms ``sqrt(factor)`` times; the
    weights stay positive definite)."""
    r = math.sqrt(factor)
    for mine, base in ((qp.R, problem.R), (qp.Rc, problem.Rc)):
        mine[...] = base
        mine[i_steer, :] *= r
        mine[:, i_steer] *= r


def new_stage_qp(problem: MpcProblem, obstacle_rows: int = 0) -> StageQp:
    """A stage QP sized for ``problem`` with ``obstacle_rows`` rows per stage, holding its
    constant parts (weights, bounds, slack weights); the per-step arrays are zero, the unused
    obstacle rows -inf."""
    N, nx, nu = problem.N, problem.nx, problem.nu
    z = np.zeros
    f = np.ascontiguousarray
    return StageQp(
        N=N,
        nx=nx,
        nu=nu,
        A=z((N, nx, nx)),
        B=z((N, nx, nu)),
        c=z((N, nx)),
        We=problem.stage_weights(),
        qt=z((N, nx)),
        xref=z((N + 1, nx)),
        R=np.array(problem.R, dtype=float),  # copies: a step may scale them (weigh_steering)
        Rc=np.array(problem.Rc, dtype=float),
        uref=z((N, nu)),
        u_min=f(problem.u_min, dtype=float),
        u_max=f(problem.u_max, dtype=float),
        ulo=np.tile(problem.u_min, (N, 1)).astype(float),
        uhi=np.tile(problem.u_max, (N, 1)).astype(float),
        dmax=f(problem.du_max_per_s * problem.dt_s, dtype=float),
        x_min=f(problem.x_min, dtype=float),
        x_max=f(problem.x_max, dtype=float),
        lane=bool(problem.lane),
        lane_n=z((N, 2)),
        lane_b=z(N),
        lane_lo=z(N),
        lane_hi=z(N),
        lane_dlo=z(N),
        lane_dhi=z(N),
        lane_t=z((N, 2)),
        Xlin=z((N + 1, nx)),
        nrow=int(obstacle_rows),
        rowa=z((N, max(obstacle_rows, 1), 3)),
        rowb=np.full((N, max(obstacle_rows, 1)), -np.inf),
        w2_lane=float(problem.lane_slack_weight),
        w1_lane=float(problem.lane_slack_weight_l1),
        w2_obs=float(problem.obstacle_slack_weight),
        w1_obs=float(problem.obstacle_slack_weight_l1),
    )


_StageQpType, _StageQpStruct = define_struct(StageQp, __name__)


@njit(cache=True)
def _build_stage_qp(values):
    return _StageQpStruct(*values)
