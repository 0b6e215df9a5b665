"""The planner's arrays, allocated once and handed to compiled code as one struct.

:class:`PlannerWork` holds the road on a uniform arc-length grid (built once), the inputs of a
replanning (the car's Frenet state, the obstacles' tracks, the goal; written in place each time),
the candidates and the chosen maneuver (written by :func:`~.kernels.plan`). Index constants name
the slots of the small scalar arrays.
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np
from numba import njit

from .._structs import define_struct, to_struct
from ..ocp.relations import REL_AHEAD, REL_BEHIND, REL_CLEAR, REL_LEFT, REL_RIGHT

#: lane kinds (``lane_kind``)
LANE_ROUTE, LANE_SAME, LANE_ONCOMING = 0, 1, 2
#: longitudinal profile kinds (``lon_kind``)
LON_REFERENCE, LON_SPEED, LON_STOP, LON_FOLLOW, LON_GOAL = 0, 1, 2, 3, 4
LON_NAMES = ("reference", "speed", "stop", "follow", "goal")
#: relations of the chosen maneuver to an obstacle at a step (``relation``) are the codes the
#: controller's obstacle rows take (:mod:`mpcdrive.ocp.relations`: REL_*)
__all__ = ["REL_AHEAD", "REL_BEHIND", "REL_CLEAR", "REL_LEFT", "REL_RIGHT", "PlannerWork", "new_work"]

#: columns of ``lat_coef``: the quintic's six coefficients, then a pass's return to another lane
#: (LAT_BACK: where along the move [m] it starts, inf: no return; LAT_BACK_LEN: its length [m];
#: LAT_BACK_LANE: the lane it returns to)
LAT_BACK, LAT_BACK_LEN, LAT_BACK_LANE = 6, 7, 8
LAT_COLS = 9
# slots of ``ego`` (E_MOVE_*: the last choice's move, its lane, offset and where it ends [m];
# E_MOVE_END nan: none to go on with)
E_S, E_D, E_SLOPE, E_CURV, E_V, E_A, E_T, E_LANE, E_PREV_LANE, E_PREV_OFF, E_MOVE_LANE, E_MOVE_OFF, E_MOVE_END = range(
    13
)
# slots of ``goal``
G_HAS, G_S_LO, G_S_HI, G_D_LO, G_D_HI, G_T_LO, G_T_HI, G_V_LO, G_V_HI, G_HAS_YAW, G_YAW_LO, G_YAW_HI = range(12)
#: the time [s] a car drifting towards the road's edge has to turn back: over it a maneuver may
#: use the road's margin (``checks._road_allowance``)
TURN_BACK_S = 1.0
# slots of ``par`` (vehicle and settings)
(
    P_HL,
    P_HW,
    P_CO,
    P_KAPPA_MAX,
    P_KAPPA_RATE,
    P_A_MAX,
    P_D_MAX,
    P_V_MAX,
    P_FRICTION,
    P_A_COMF,
    P_D_COMF,
    P_MARGIN,
    P_ROAD_MARGIN,
    P_TIME_GAP,
    P_STANDSTILL,
    P_STOP_V,
    P_LAT_MIN,
    P_SHIFT,
    P_ONCOMING,
    P_C_CHANGE,
    P_C_OFFROUTE,
    P_C_ONCOMING,
    P_C_SWITCH,
    P_C_GAP,
    P_C_GOAL,
    P_JERK_REF,
    P_LAT_REF,
    P_ROAD_START,
    P_ROAD_END,
    P_BAND_K,
    P_CREEP,
    P_R_DISC,
    P_C_RATE,
    P_REAR,
    P_ROWS_EXCESS,
    P_TURN_BACK,
) = range(36)
N_PAR = 36
# slots of ``result``
(
    R_I,
    R_J,
    R_COST,
    R_TTC,
    R_SAFE,
    R_CHECKED,
    R_SAFE_COUNT,
    R_COMBOS,
    R_LANE,
    R_OFF,
    R_KIND,
    R_TARGET,
    R_GOAL,
    R_RATE,
) = range(14)
N_RESULT = 14

MAX_LAT = 64
MAX_LON = 64
MAX_LANES = 12
MAX_OBS = 64
PARALLEL_M = 0.5
"""How far [m] an obstacle may drift sideways over the horizon and still count as keeping to its
line (a parked car, a car in its lane): a tenth of a lane width, well inside a car's lane keeping."""
#: how close [m, m, m/s] (along, across, speed) the car must be to the last maneuver for a
#: replanning to go on from it rather than from the car: about what the controller's tracking
#: leaves (a lateral error above the road's margin starts afresh from the car)
PLAN_TOLERANCE = (1.0, 0.3, 1.0)


@dataclass(frozen=True, eq=False)
class PlannerWork:
    """Arrays of one planner (module docstring). Shapes: G grid points, L lanes, K + 1 samples
    (t = 0, dt, ..., K dt after the replanning), O obstacle slots."""

    # the road, on the grid s = g_s0 + g_ds * i
    grid: np.ndarray  # (4,) s0 [m], ds [m], n points, 1 / ds [1/m]
    g_kappa: np.ndarray  # (G,) path curvature [1/m]
    g_heading: np.ndarray  # (G,) path heading [rad] (unwrapped)
    g_vref: np.ndarray  # (G,) wanted speed along the path [m/s]
    g_bend: np.ndarray  # (G,) 1 / the speed [s/m] above which the path bends faster than the car steers
    g_tref: np.ndarray  # (G,) time [s] the wanted speed takes from the grid's start (inf past a stop)
    lane_left: np.ndarray  # (L, G) lane edges [m] (offsets from the path, positive left)
    lane_right: np.ndarray  # (L, G)
    lane_line: np.ndarray  # (L, G) the line driven in each lane [m]
    lane_kind: np.ndarray  # (L,) LANE_*
    same_left: np.ndarray  # (G,) edges of the lanes going the car's way
    same_right: np.ndarray  # (G,)
    all_left: np.ndarray  # (G,) edges of all lanes (the oncoming ones too)
    all_right: np.ndarray  # (G,)
    edge_win: np.ndarray  # (4, G) the four edges above at their tightest within a body's reach (road_windows)
    par: np.ndarray  # (N_PAR,) vehicle and settings
    lat_lengths_s: np.ndarray  # (nT,) durations of lateral moves [s]
    speed_s: np.ndarray  # (nV,) durations of speed changes [s]
    dt: np.ndarray  # (1,) check grid [s]
    discs: np.ndarray  # (nd,) centres [m] along the body of the controller's footprint discs
    # one replanning's inputs
    ego: np.ndarray  # (11,) E_*
    goal: np.ndarray  # (12,) G_*
    ob_s: np.ndarray  # (O, K+1) obstacle centre arc length [m] (NaN: absent)
    ob_e: np.ndarray  # (O, K+1) lateral offset [m]
    ob_hl: np.ndarray  # (O, K+1) half extent along the path [m]
    ob_hw: np.ndarray  # (O, K+1) half extent across [m]
    ob_or: np.ndarray  # (O, K+1, 4) cos, sin of the yaw to the path, own half length, half width [m]
    ob_n: np.ndarray  # (1,) int: obstacle rows in use
    # candidates
    lat_lane: np.ndarray  # (MAX_LAT,) int
    lat_off: np.ndarray  # (MAX_LAT,) offset from the lane's line [m]
    lat_len: np.ndarray  # (MAX_LAT,) length of the move [m]
    lat_coef: np.ndarray  # (MAX_LAT, LAT_COLS) quintic d(u), u = s - s0; then the return (LAT_BACK...)
    lat_cost: np.ndarray  # (MAX_LAT,)
    lat_n: np.ndarray  # (1,) int
    lon_kind: np.ndarray  # (MAX_LON,) int LON_*
    lon_target: np.ndarray  # (MAX_LON,) target speed [m/s] or stop point [m] or lane
    lon_s: np.ndarray  # (MAX_LON, K+1) the way the car drives [m] (along the path where it runs along it)
    lon_v: np.ndarray  # (MAX_LON, K+1) [m/s]
    lon_a: np.ndarray  # (MAX_LON, K+1) [m/s^2]
    lon_ok: np.ndarray  # (MAX_LON,) int: within the vehicle's limits
    lon_cost: np.ndarray  # (MAX_LON,)
    lon_goal: np.ndarray  # (MAX_LON,) the goal's miss cost [s] each profile pays for sure
    lon_bend: np.ndarray  # (MAX_LON,) the steering rate the route's bends ask at each profile's speeds
    lon_vend: np.ndarray  # (MAX_LON,) the speed [m/s] each profile is bound for (0: a stop)
    lon_n: np.ndarray  # (1,) int
    # the choice
    order: np.ndarray  # (MAX_LAT * MAX_LON,) int work space
    keys: np.ndarray  # (MAX_LAT * MAX_LON,) work space
    result: np.ndarray  # (N_RESULT,)
    plan_s: np.ndarray  # (K+1,) the chosen maneuver: arc length [m]
    plan_v: np.ndarray  # (K+1,) the car's speed [m/s]
    plan_a: np.ndarray  # (K+1,) acceleration [m/s^2]
    plan_d: np.ndarray  # (K+1,) lateral offset [m]
    plan_lanes: np.ndarray  # (L,) int: lanes the body overlaps over the controller's horizon
    path: np.ndarray  # (K+1, 4) work space: the way a pair drives (arc length, offset, slope, d'')
    relation: np.ndarray  # (O, K+1) int REL_*

    def struct(self):
        return to_struct(self, _build_planner_work)


def new_work(K: int, grid_s: np.ndarray, n_lanes: int) -> dict:
    """The allocations of a :class:`PlannerWork` for ``K`` steps, the grid ``grid_s`` (G,) and
    ``n_lanes`` lanes, as keyword arrays (the road's and settings' values to be filled in)."""
    G = len(grid_s)
    L = n_lanes
    ds = float(grid_s[1] - grid_s[0]) if G > 1 else 1.0
    f = np.zeros
    return dict(
        grid=np.array([grid_s[0], ds, G, 1.0 / ds], float),
        g_kappa=f(G),
        g_heading=f(G),
        g_vref=f(G),
        g_bend=f(G),
        g_tref=f(G),
        lane_left=f((L, G)),
        lane_right=f((L, G)),
        lane_line=f((L, G)),
        lane_kind=np.zeros(L, np.int64),
        same_left=f(G),
        same_right=f(G),
        all_left=f(G),
        all_right=f(G),
        edge_win=f((4, G)),
        par=f(N_PAR),
        lat_lengths_s=f(1),
        speed_s=f(1),
        dt=f(1),
        discs=f(1),
        ego=f(13),
        goal=f(12),
        ob_s=f((MAX_OBS, K + 1)),
        ob_e=f((MAX_OBS, K + 1)),
        ob_hl=f((MAX_OBS, K + 1)),
        ob_hw=f((MAX_OBS, K + 1)),
        ob_or=f((MAX_OBS, K + 1, 4)),
        ob_n=np.zeros(1, np.int64),
        lat_lane=np.zeros(MAX_LAT, np.int64),
        lat_off=f(MAX_LAT),
        lat_len=f(MAX_LAT),
        lat_coef=f((MAX_LAT, LAT_COLS)),
        lat_cost=f(MAX_LAT),
        lat_n=np.zeros(1, np.int64),
        lon_kind=np.zeros(MAX_LON, np.int64),
        lon_target=f(MAX_LON),
        lon_s=f((MAX_LON, K + 1)),
        lon_v=f((MAX_LON, K + 1)),
        lon_a=f((MAX_LON, K + 1)),
        lon_ok=np.zeros(MAX_LON, np.int64),
        lon_cost=f(MAX_LON),
        lon_goal=f(MAX_LON),
        lon_bend=f(MAX_LON),
        lon_vend=f(MAX_LON),
        lon_n=np.zeros(1, np.int64),
        order=np.zeros(MAX_LAT * MAX_LON, np.int64),
        keys=f(MAX_LAT * MAX_LON),
        result=f(N_RESULT),
        plan_s=f(K + 1),
        plan_v=f(K + 1),
        plan_a=f(K + 1),
        plan_d=f(K + 1),
        plan_lanes=np.zeros(L, np.int64),
        path=f((K + 1, 4)),
        relation=np.zeros((MAX_OBS, K + 1), np.int64),
    )


def road_windows(arrays: dict) -> None:
    """Fill ``edge_win``: each of ``same_left``, ``same_right``, ``all_left``, ``all_right`` at its
    tightest (the left edges' least, the right edges' greatest) over the grid points within the
    body's reach (plus a grid step either way) of each point: what the body's corners can meet of
    the edges, interpolated as the checks interpolate them (``checks._clear_of_edges`` skips the
    corners' own lookups where the body keeps clear of these). The reach, from ``par``: no corner
    lies farther along the path from the reference point than the hypotenuse of the half width
    and the farther of the front and the rear."""
    par = arrays["par"]
    reach_m = math.hypot(max(abs(par[P_CO] + par[P_HL]), abs(par[P_CO] - par[P_HL])), par[P_HW])
    ds = float(arrays["grid"][1])
    if arrays["same_left"].shape[0] == 0:
        return
    W = int(math.ceil(reach_m / ds)) + 1
    out = arrays["edge_win"]
    for r, (name, tight) in enumerate(
        (("same_left", np.min), ("same_right", np.max), ("all_left", np.min), ("all_right", np.max))
    ):
        tab = arrays[name]
        # sliding window over the padded table (the ends repeat: beyond them the checks hold the end value)
        padded = np.concatenate((np.full(W, tab[0]), tab, np.full(W, tab[-1])))
        out[r] = tight(np.lib.stride_tricks.sliding_window_view(padded, 2 * W + 1), axis=1)


_PlannerWorkType, _PlannerWorkStruct = define_struct(PlannerWork, __name__)


@njit(cache=True)
def _build_planner_work(values):
    return _PlannerWorkStruct(*values)
