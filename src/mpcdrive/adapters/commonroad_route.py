"""Routes through a CommonRoad lanelet network and their reference polylines.

* **Values.** CommonRoad states may hold intervals (``Interval``, ``AngleInterval``) or shapes
  (an uncertain position) where a number is usual: :func:`scalar` reads an interval as its middle,
  :func:`point` a shape as its centre.
* **Start.** Every lanelet holding the initial position whose direction there is within 90 deg
  of the initial heading, plus -- when the start lies within :data:`FORK_M` of such a lanelet's
  beginning -- the other successors of its predecessors (the car stands at a fork: which branch it
  takes is the route's choice); the nearest lanelet when none holds the position.
* **Goal.** The goal's lanelets, else the lanelets overlapping its position shapes; none for a
  goal without a position (time, speed or orientation only).
* **Search.** Dijkstra over successors (cost: the lanelet's length) and same-direction
  neighbours (cost :data:`LANE_CHANGE_COST_M`) from every start lanelet to any goal lanelet.
* **Lane forward.** Without goal lanelets, and past the goal when the car must drive on through
  it, the route follows the lane: a lanelet's only successor, else the intersection's straight
  successor, else the successor whose neighbours continue the lanelet's neighbours; it stops at a
  dead end or where the network leaves the choice open (no invented turns).
* **Lanes beside.** The same-direction lanelets beside the route (repeatedly), and those through
  which such a lane runs on into the route's lanes where the map gives it no neighbour (a zipper
  merge, :data:`REJOIN_LANELETS`).
* **Road ends.** The mapped road begins at the route's first lanelet when neither it nor a
  same-direction lanelet beside it has a predecessor, and ends at its last likewise without
  successors (:func:`mapped_road_ends`): a body beyond them is off the road.
* **Centreline.** The lanelets' centre polylines joined (a lane change blends from one centre
  line to the other over the last :data:`LANE_CHANGE_M` of the lanelet it leaves, or before the
  goal when that lies beside it), resampled
  every metre, smoothed with a Gaussian of :data:`SMOOTH_SIGMA_M` along the arc length (lanelet
  vertices jitter by centimetres, which would be curvature spikes of the spline through them) and
  cut at the route's end: no extension past it.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

FORK_M = 5.0
LANE_CHANGE_COST_M = 20.0
LANE_CHANGE_M = 40.0
SMOOTH_SIGMA_M = 1.5
RESAMPLE_M = 1.0


# -- values ---------------------------------------------------------------------------------------
def scalar(v) -> float | None:
    """A CommonRoad state value as a number: an interval's middle, else the value; None stays."""
    if v is None:
        return None
    if hasattr(v, "start") and hasattr(v, "end"):
        return 0.5 * (float(v.start) + float(v.end))
    return float(v)


def bounds(v) -> tuple[float, float] | None:
    """(low, high) of an interval-valued field, (v, v) of a number, None when absent."""
    if v is None:
        return None
    if hasattr(v, "start") and hasattr(v, "end"):
        return float(v.start), float(v.end)
    return float(v), float(v)


def point(p) -> np.ndarray:
    """A CommonRoad position as (2,) [m]: a shape's centre (an uncertain position), else the point."""
    if hasattr(p, "center"):
        return np.asarray(p.center, float)
    return np.asarray(p, float).reshape(2)


def angle_diff(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi] [rad]."""
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


# -- lanelets -------------------------------------------------------------------------------------
def heading_at(lanelet, p: np.ndarray) -> float:
    """Direction [rad] of the lanelet's centre line at the vertex nearest ``p``."""
    cv = lanelet.center_vertices
    i = min(int(np.argmin(np.hypot(*(cv - p).T))), len(cv) - 2)
    d = cv[i + 1] - cv[i]
    return math.atan2(d[1], d[0])


def _arc_to(lanelet, p: np.ndarray) -> float:
    """Arc length [m] of the centre vertex nearest ``p`` from the lanelet's start."""
    cv = lanelet.center_vertices
    return float(lanelet.distance[int(np.argmin(np.hypot(*(cv - p).T)))])


def start_lanelets(net, p0: np.ndarray, yaw0: float) -> list[int]:
    """Lanelets the route may start on (see the module docstring); ValueError when none is near."""
    holding = [lid for lst in net.find_lanelet_by_position([p0]) for lid in lst]
    along = [lid for lid in holding if angle_diff(heading_at(net.find_lanelet_by_id(lid), p0), yaw0) < math.pi / 2]
    if not along:
        near = []
        for ll in net.lanelets:
            d = float(np.min(np.hypot(*(ll.center_vertices - p0).T)))
            if d < 3.0 and angle_diff(heading_at(ll, p0), yaw0) < math.pi / 2:
                near.append((d, ll.lanelet_id))
        if not near:
            raise ValueError(
                f"initial position ({p0[0]:.2f}, {p0[1]:.2f}) m is on no lanelet driving in the initial heading"
            )
        along = [min(near)[1]]
    out = list(along)
    for lid in along:
        ll = net.find_lanelet_by_id(lid)
        if _arc_to(ll, p0) < FORK_M:
            for pre in ll.predecessor:
                out += [s for s in net.find_lanelet_by_id(pre).successor if s not in out]
    # the lanelets holding the start best aligned first (ties in the search go to them)
    return sorted(out, key=lambda i: (i not in along, angle_diff(heading_at(net.find_lanelet_by_id(i), p0), yaw0)))


def goal_shapes(goal_state) -> list:
    """The shapes of a goal state's position (a ShapeGroup's members), [] without a position."""
    pos = getattr(goal_state, "position", None)
    if pos is None:
        return []
    return list(getattr(pos, "shapes", None) or [pos])


def goal_lanelets(net, pp) -> set[int]:
    """The goal's lanelets, else those overlapping its position shapes (empty: no position)."""
    ids: set[int] = set()
    if pp.goal.lanelets_of_goal_position:
        for v in pp.goal.lanelets_of_goal_position.values():
            ids.update(v)
        return ids
    for st in pp.goal.state_list:
        for shape in goal_shapes(st):
            ids.update(net.find_lanelet_by_shape(shape))
    return ids


def _edges(net, lid: int):
    ll = net.find_lanelet_by_id(lid)
    for s in ll.successor:
        yield s, float(ll.distance[-1])
    if ll.adj_left is not None and ll.adj_left_same_direction:
        yield ll.adj_left, LANE_CHANGE_COST_M
    if ll.adj_right is not None and ll.adj_right_same_direction:
        yield ll.adj_right, LANE_CHANGE_COST_M


def find_route(net, starts, goals: set[int]) -> list[int] | None:
    """Cheapest lanelet sequence from any of ``starts`` to any of ``goals`` (Dijkstra over
    successors and same-direction neighbours), or None when no goal lanelet is reachable."""
    best: dict[int, float] = {}
    prev: dict[int, int | None] = {}
    heap = []
    for k, s in enumerate(starts):
        heapq.heappush(heap, (0.0, k, s, None))
    counter = len(heap)
    while heap:
        cost, _, lid, parent = heapq.heappop(heap)
        if lid in best:
            continue
        best[lid] = cost
        prev[lid] = parent
        if lid in goals:
            route = [lid]
            while prev[route[-1]] is not None:
                route.append(prev[route[-1]])
            return route[::-1]
        for n, c in _edges(net, lid):
            if n not in best:
                counter += 1
                heapq.heappush(heap, (cost + c, counter, n, lid))
    return None


def _straight_successors(net, lid: int) -> set[int]:
    out: set[int] = set()
    for inter in getattr(net, "intersections", []) or []:
        for inc in inter.incomings:
            if lid in inc.incoming_lanelets:
                out |= set(inc.successors_straight)
    return out


def _continues_neighbours(net, ll, succ_id: int) -> bool:
    """The successor lies beside the successors of the lanelet's own neighbours (the lane goes on
    as part of the same road, not as a branch leaving it)."""
    s = net.find_lanelet_by_id(succ_id)
    for mine, theirs in ((ll.adj_left, s.adj_left), (ll.adj_right, s.adj_right)):
        if mine is not None and theirs is not None and theirs in net.find_lanelet_by_id(mine).successor:
            return True
    return False


def next_in_lane(net, lid: int, visited, choose: bool = False) -> int | None:
    """The successor continuing lanelet ``lid``'s lane, None at a dead end: the only one; else
    the intersection's straight-on successor; else the one beside its neighbours' successors
    (the lane goes on as part of the same road); else, where nothing says which branch the lane
    goes on into, None (an open choice), or with ``choose`` the branch that turns least
    (:func:`_turn_rad`)."""
    ll = net.find_lanelet_by_id(lid)
    succ = [s for s in ll.successor if s not in visited]
    if len(succ) <= 1:
        return succ[0] if succ else None
    straight = [s for s in succ if s in _straight_successors(net, lid)]
    if len(straight) == 1:
        return straight[0]
    cont = [s for s in succ if _continues_neighbours(net, ll, s)]
    if len(cont) == 1:
        return cont[0]
    if not choose:
        return None
    return min(cont or succ, key=lambda s: (_turn_rad(net, ll, s), s))


def _turn_rad(net, ll, succ_id: int) -> float:
    """How far [rad] successor ``succ_id`` turns from lanelet ``ll``'s heading at its end: the
    angle between ``ll``'s last segment and the chord from the successor's start to its end."""
    cv = ll.center_vertices
    h0 = math.atan2(cv[-1, 1] - cv[-2, 1], cv[-1, 0] - cv[-2, 0])
    sv = net.find_lanelet_by_id(succ_id).center_vertices
    h1 = math.atan2(sv[-1, 1] - sv[0, 1], sv[-1, 0] - sv[0, 0])
    return abs(math.remainder(h1 - h0, 2.0 * math.pi))


def lane_forward(net, route: list[int], length_m: float, from_m: float = 0.0, choose: bool = False) -> list[int]:
    """``route`` continued along its last lanelet's lane (:func:`next_in_lane`) until it is
    ``length_m`` long past ``from_m`` (arc length along the route's first lanelet), a dead end or
    an open choice (with ``choose``: the branch that turns least there)."""
    route = list(route)
    total = sum(float(net.find_lanelet_by_id(i).distance[-1]) for i in route) - from_m
    while total < length_m:
        nxt = next_in_lane(net, route[-1], route, choose)
        if nxt is None:
            break
        route.append(nxt)
        total += float(net.find_lanelet_by_id(nxt).distance[-1])
    return route


# -- centre line ----------------------------------------------------------------------------------
def _resample(line: np.ndarray, ds_m: float) -> np.ndarray:
    line = line[np.r_[True, np.hypot(*np.diff(line, axis=0).T) > 1e-6]]
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
    s_new = np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1] / ds_m)) + 1))
    return np.column_stack([np.interp(s_new, s, line[:, 0]), np.interp(s_new, s, line[:, 1])])


def _project_onto(poly: np.ndarray, p: np.ndarray) -> np.ndarray:
    a, b = poly[:-1], poly[1:]
    d = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-12), 0.0, 1.0)
    q = a + t[:, None] * d
    return q[int(np.argmin(np.hypot(*(q - p).T)))]


def smooth(line: np.ndarray, sigma_m: float = SMOOTH_SIGMA_M, ds_m: float = RESAMPLE_M) -> np.ndarray:
    """``line`` resampled every ``ds_m`` and smoothed by a Gaussian of ``sigma_m`` along the arc
    length; the ends stay put (the line is mirrored through them, which keeps a straight end
    straight)."""
    pts = _resample(np.asarray(line, float), ds_m)
    half = int(math.ceil(3 * sigma_m / ds_m))
    if len(pts) < 3 or half < 1:
        return pts
    h = min(half, len(pts) - 1)
    head = 2 * pts[0] - pts[h:0:-1]
    tail = 2 * pts[-1] - pts[-2 : -h - 2 : -1]
    padded = np.vstack([head, pts, tail])
    k = np.arange(-half, half + 1) * ds_m
    w = np.exp(-0.5 * (k / sigma_m) ** 2)
    w /= w.sum()
    out = np.empty_like(pts)
    for c in range(2):
        col = np.pad(padded[:, c], (half - h, half - h), mode="edge")
        out[:, c] = np.convolve(col, w, mode="valid")
    out[0], out[-1] = pts[0], pts[-1]
    return out


def route_polyline(net, route: list[int], start_xy: np.ndarray, goal_xy: np.ndarray | None = None) -> np.ndarray:
    """The route's centre line (M, 2) [m] from one metre behind ``start_xy``, unsmoothed:
    successors joined end to start; a lane change stays on the lanelet it leaves as long as it
    can and blends to the neighbour over the last :data:`LANE_CHANGE_M` of it -- done
    :data:`LANE_CHANGE_M` / 2 before the point abreast of ``goal_xy`` when the goal lies ahead on
    that stretch, and begun no earlier than the start -- then goes on along the neighbour from
    the point abreast."""
    pieces: list[np.ndarray] = []
    for k, lid in enumerate(route):
        cv = _resample(np.asarray(net.find_lanelet_by_id(lid).center_vertices, float), RESAMPLE_M)
        if k == 0:
            j = int(np.argmin(np.hypot(*(cv - start_xy).T)))
            cv = cv[max(j - 1, 0) :]
        elif lid not in net.find_lanelet_by_id(route[k - 1]).successor:
            prev = pieces.pop()
            s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(prev, axis=0).T))]
            done = s[-1]
            if goal_xy is not None:
                g = float(s[int(np.argmin(np.hypot(*(prev - goal_xy).T)))])
                if g < s[-1] - 1.0:  # the goal is abreast of this lanelet: be across before it
                    done = min(done, g - 0.5 * LANE_CHANGE_M)
            done = max(done, min(LANE_CHANGE_M, s[-1]))
            begin = max(done - LANE_CHANGE_M, 0.0)
            n = int(np.searchsorted(s, done, side="right"))
            w = 0.5 - 0.5 * np.cos(math.pi * np.clip((s[:n] - begin) / max(done - begin, 1e-9), 0.0, 1.0))
            other = np.array([_project_onto(cv, p) for p in prev[:n]])
            pieces.append((1 - w)[:, None] * prev[:n] + w[:, None] * other)
            j = int(np.argmin(np.hypot(*(cv - pieces[-1][-1]).T)))
            cv = cv[min(j + 1, len(cv)) :]
            if len(cv) == 0:
                continue
        pieces.append(cv)
    return np.vstack(pieces)


def route_centerline(
    net, route: list[int], start_xy: np.ndarray, length_m: float | None = None, goal_xy: np.ndarray | None = None
) -> np.ndarray:
    """Smoothed centre polyline (M, 2) [m] of a route from one metre behind the start to the
    route's end, or ``length_m`` past the start when shorter; lane changes done before
    ``goal_xy`` (module docstring)."""
    line = smooth(route_polyline(net, route, start_xy, goal_xy))
    if length_m is not None:
        s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
        line = line[: max(2, int(np.searchsorted(s, length_m + RESAMPLE_M)) + 1)]
    return line


def trim_route(net, route: list[int], line: np.ndarray) -> list[int]:
    """``route`` without the lanelets past the end of ``line`` (a centre line cut short)."""
    from shapely.geometry import Point

    end = Point(*line[-1])
    route = list(route)
    while len(route) > 1 and net.find_lanelet_by_id(route[-1]).polygon.shapely_object.distance(end) > 1e-6:
        route.pop()
    return route


def nearest_arc(line: np.ndarray, shapes) -> tuple[float, float] | None:
    """The arc length [m] along ``line`` closest to the shapes' centres, as a (s, s) stretch;
    None without shapes."""
    if not shapes:
        return None
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
    best = min(
        (float(np.min(np.hypot(*(line - point(sh.center)).T))), int(np.argmin(np.hypot(*(line - point(sh.center)).T))))
        for sh in shapes
    )
    return float(s[best[1]]), float(s[best[1]])


def arc_inside(line: np.ndarray, shapes) -> tuple[float, float] | None:
    """(first, last) arc length [m] along ``line`` of the points inside any of ``shapes``, or None."""
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(line, axis=0).T))]
    inside = np.array([any(sh.contains_point(p) for sh in shapes) for p in line])
    if not inside.any():
        return None
    idx = np.flatnonzero(inside)
    return float(s[idx[0]]), float(s[idx[-1]])


# -- the road around the route ------------------------------------------------------------------
#: how far [m] to either side of the centre line the road's edges are looked for, and the step
#: [m] of the search (an edge is placed at the last step inside the drivable lanelets)
EDGE_SEARCH_M = 15.0
EDGE_STEP_M = 0.05


#: how many lanelets a lane beside the route may run through, with no neighbour in the map,
#: before it joins the route's lanes again (a zipper merge: two lanes converging into one)
REJOIN_LANELETS = 2


def _rejoining(net, ids: set[int]) -> set[int]:
    """The lanelets of successor chains, at most :data:`REJOIN_LANELETS` long, that leave a
    lanelet of ``ids`` and lead into one of ``ids`` again."""
    found: set[int] = set()
    for lid in ids:
        stack: list[tuple[int, tuple[int, ...]]] = [(lid, ())]
        while stack:
            cur, chain = stack.pop()
            for nxt in net.find_lanelet_by_id(cur).successor:
                nxt = int(nxt)
                if nxt in ids:
                    found.update(chain)  # (a chain holds no lanelet of ids)
                elif len(chain) < REJOIN_LANELETS and nxt not in chain:
                    stack.append((nxt, (*chain, nxt)))
    return found


def drivable_lanelets(net, route, neighbours: bool = True) -> set[int]:
    """The route's lanelets and, with ``neighbours``, every lanelet beside them in the same
    direction (adjacent left / right, repeatedly: all lanes of a motorway's carriageway) and the
    lanelets through which such a lane runs on into the route's lanes where the map gives them
    no neighbour (:func:`_rejoining`: the two lanes of a zipper merge converge, each its own
    lanelet, into one)."""
    ids = set(int(i) for i in route)
    frontier = list(ids) if neighbours else []
    while frontier:
        ll = net.find_lanelet_by_id(frontier.pop())
        for adj, same in ((ll.adj_left, ll.adj_left_same_direction), (ll.adj_right, ll.adj_right_same_direction)):
            if adj is not None and same and adj not in ids:
                ids.add(int(adj))
                frontier.append(int(adj))
        if not frontier:  # every lane beside found: on through the merges, and beside those
            frontier = sorted(_rejoining(net, ids))
            ids.update(frontier)
    return ids


def route_ends(net, route) -> set[int]:
    """The lanelets the road goes on into past the route's ends: the first lanelet's
    predecessors and the last one's successors. Measured with them, the road's edges at the ends
    of the centre line are the lane's sides; without them a route ending where its lanelet ends
    (DEU_Gar-1_1_T-1) measures, at its last point, the lanelet's slanted closing edge as a side
    a few centimetres away."""
    first, last = net.find_lanelet_by_id(int(route[0])), net.find_lanelet_by_id(int(route[-1]))
    return {int(i) for i in (*first.predecessor, *last.successor)}


def mapped_road_ends(net, route) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Where the mapped road begins and ends around the route: the closing edges (their two
    points each, (2 n, 2) [m]) of the route's first lanelet and the same-direction lanelets beside
    it when none of them has a predecessor, and likewise of its last lanelet and those beside it
    when none has a successor; None where the network goes on (a lanelet beside that continues
    is road to drive on)."""
    out: list[np.ndarray | None] = []
    for lid, attr, k in ((route[0], "predecessor", 0), (route[-1], "successor", -1)):
        here = [net.find_lanelet_by_id(i) for i in sorted(drivable_lanelets(net, [lid], neighbours=True))]
        if any(getattr(ll, attr) for ll in here):
            out.append(None)
        else:
            out.append(np.array([p for ll in here for p in (ll.left_vertices[k], ll.right_vertices[k])], float))
    return out[0], out[1]


def route_edges(net, lanelet_ids, line: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, left, right) (M,) [m] along the polyline ``line`` (M, 2): the arc length of each point
    and the distances from it, along the line's left / right normal, to the edge of the union of
    ``lanelet_ids`` (where the normal leaves it; 0 where the point itself lies outside, filled in
    from the neighbouring points)."""
    import shapely

    polys = [net.find_lanelet_by_id(i).polygon.shapely_object.buffer(0.02) for i in lanelet_ids]
    area = shapely.union_all(polys)
    shapely.prepare(area)
    p = np.asarray(line, float)
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    t = np.gradient(p, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    d = np.arange(0.0, EDGE_SEARCH_M + EDGE_STEP_M / 2, EDGE_STEP_M)
    out = []
    for sign in (1.0, -1.0):
        q = p[:, None, :] + sign * d[None, :, None] * n[:, None, :]
        inside = shapely.contains_xy(area, q[..., 0], q[..., 1])  # (M, D)
        # the last offset of the first run inside, starting at the point itself
        first_out = np.where(inside.all(axis=1), len(d), np.argmin(inside, axis=1))
        width = np.where(inside[:, 0], d[np.maximum(first_out - 1, 0)], np.nan)
        out.append(width)
    left, right = out
    ok = np.isfinite(left) & np.isfinite(right)
    if not ok.any():
        raise ValueError("the route's centre line lies outside its lanelets everywhere")
    left = np.interp(s, s[ok], left[ok])
    right = np.interp(s, s[ok], right[ok])
    return s, left, right


#: the step [m] of the search for lane edges along the normals (the route's own edges take
#: EDGE_STEP_M)
LANE_STEP_M = 0.1
#: two lanelets' stretches along a normal that overlap by more than this [m] are one lane (a
#: lanelet and its successor at their seam, two lanelets side by side in a junction)
LANE_MERGE_M = 0.5
#: a lane missed at this many points of the line in a row (a seam, a small gap between lanelets)
#: goes on; the points are a metre apart
LANE_GAP_POINTS = 5
#: a strip of lane shorter than this many points (metres) is no lane: a junction's corner
MIN_LANE_POINTS = 10


def lane_candidates(net, route) -> dict[int, bool]:
    """The lanelets that may make up the road's lanes: the route's, those it goes on into, every
    lanelet beside them going the same way (repeatedly) and the first lanelet beside those going
    the other way; lanelet id -> goes the other way."""
    base = {int(i) for i in route} | route_ends(net, route)
    same = drivable_lanelets(net, list(base), neighbours=True)
    out = {i: False for i in same}
    for lid in same:
        ll = net.find_lanelet_by_id(lid)
        for adj, is_same in ((ll.adj_left, ll.adj_left_same_direction), (ll.adj_right, ll.adj_right_same_direction)):
            if adj is not None and not is_same and int(adj) not in out:
                out[int(adj)] = True
    return out


def _touching_path(intervals: list[list]) -> list[list]:
    """Of the lanes met along a normal (``[right, left, oncoming]`` offsets, sorted), those that
    touch the one at the path (offset 0; else the nearest) through a chain of lanes no more than
    ``LANE_MERGE_M`` apart."""
    if not intervals:
        return intervals
    at = min(range(len(intervals)), key=lambda k: 0.0 if intervals[k][0] <= 0.0 <= intervals[k][1] else min(
        abs(intervals[k][0]), abs(intervals[k][1])))  # fmt: skip
    lo = hi = at
    while lo > 0 and intervals[lo][0] - intervals[lo - 1][1] <= LANE_MERGE_M:
        lo -= 1
    while hi < len(intervals) - 1 and intervals[hi + 1][0] - intervals[hi][1] <= LANE_MERGE_M:
        hi += 1
    return intervals[lo : hi + 1]


def lane_strips(net, route, line: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """The lanes along the polyline ``line`` (M, 2) as strips: per lane (left, right) (M,) offsets
    [m] from the line (positive left; NaN where the lane is absent) and whether it goes the other
    way. Along each normal, every candidate lanelet (:func:`lane_candidates`) gives the stretch
    where the normal first runs inside it; stretches overlapping by more than ``LANE_MERGE_M``
    are one lane; a lane at one point continues the lane at the point before that overlaps it
    most (a lane that appears starts a strip, one that ends stops it)."""
    import shapely

    cands = lane_candidates(net, route)
    p = np.asarray(line, float)
    M = len(p)
    t = np.gradient(p, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    nrm = np.column_stack([-t[:, 1], t[:, 0]])
    d = np.arange(-EDGE_SEARCH_M, EDGE_SEARCH_M + LANE_STEP_M / 2, LANE_STEP_M)
    q = p[:, None, :] + d[None, :, None] * nrm[:, None, :]
    lo_box, hi_box = q.reshape(-1, 2).min(axis=0), q.reshape(-1, 2).max(axis=0)
    per_point: list[list[tuple[float, float, bool]]] = [[] for _ in range(M)]
    for lid, other in cands.items():
        poly = net.find_lanelet_by_id(lid).polygon.shapely_object.buffer(0.02)  # closes seams
        b = poly.bounds
        if b[2] < lo_box[0] or b[0] > hi_box[0] or b[3] < lo_box[1] or b[1] > hi_box[1]:
            continue
        shapely.prepare(poly)
        inside = shapely.contains_xy(poly, q[..., 0], q[..., 1])  # (M, D)
        for i in np.flatnonzero(inside.any(axis=1)):
            row = inside[i]
            k0 = int(np.argmax(row))
            k1 = k0 + int(np.argmin(row[k0:])) if not row[k0:].all() else len(d)
            per_point[i].append((float(d[k0]), float(d[k1 - 1]), other))
    strips: list[list] = []  # each: [left (M,), right (M,), oncoming, last index]
    for i in range(M):
        # merge one lane's stretches (a lanelet and its successor at their seam)
        merged: list[list] = []
        for r, l_, other in sorted(per_point[i]):
            if merged and merged[-1][2] == other and min(l_, merged[-1][1]) - max(r, merged[-1][0]) > LANE_MERGE_M:
                merged[-1][0] = min(merged[-1][0], r)
                merged[-1][1] = max(merged[-1][1], l_)
            else:
                merged.append([r, l_, other])
        # only the lanes beside the path's own, touching one another: a lanelet across a
        # roundabout's island or a median is another road
        merged = _touching_path(merged)
        used: set[int] = set()
        for r, l_, other in merged:
            best, best_ov = -1, 0.0
            for k, st in enumerate(strips):
                if k in used or st[2] != other or i - st[3] > LANE_GAP_POINTS:
                    continue
                j = st[3]  # the strip's last point (a short gap where no lanelet was met is bridged)
                ov = min(l_, st[0][j]) - max(r, st[1][j])
                if ov > best_ov:
                    best, best_ov = k, ov
            if best < 0:
                strips.append([np.full(M, np.nan), np.full(M, np.nan), other, i])
                best = len(strips) - 1
            st = strips[best]
            st[0][i], st[1][i], st[3] = l_, r, i
            used.add(best)
    out = []
    for lf, rt, other, _ in strips:
        found = np.flatnonzero(np.isfinite(lf))
        if len(found) < MIN_LANE_POINTS:
            continue  # a sliver (a junction's corner): no lane to drive in
        # bridge the short gaps inside the strip
        idx = np.arange(found[0], found[-1] + 1)
        lf[idx] = np.interp(idx, found, lf[found])
        rt[idx] = np.interp(idx, found, rt[found])
        out.append((lf, rt, other))
    return out
