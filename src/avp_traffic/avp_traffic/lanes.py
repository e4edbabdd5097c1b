"""Lane graph, driving paths and a path tracker for eq. (1) — the road network the training traffic drives on.

**Lane graph.** Nodes are the end points of the road centre lines C_j and their crossings (T and X
junctions, corners), merged within 0.3 m. Each piece of a centre line between two nodes gives two directed
lanes, offset to the right of the driving direction by w_j / 4 (the right-hand half of the aisle, as
ParkSim's 1.75 m on a 7 m aisle and the start pose of the 8 maneuvers, :mod:`avp_scenario.maneuvers`). The
entrance is joined to its nearest node by one more pair of lanes (in and out) that continue outside the lot.

**Turns.** From lane L1 into lane L2 at a node (no U-turns, |turn angle| <= 100 deg): the two lane lines
meet at X; the path leaves L1 at the tangent point X - T d1, follows a circular arc of radius R (3.6 m for
right turns, 5.0 m for left turns; R_min = 3.22 m) and joins L2 at X + T d2, T = R tan(|phi| / 2).

**Paths** are chains of straights and arcs, evaluated exactly (:class:`Path`).

**Tracker** (:func:`follow`): the controls of eq. (1) that drive a path forward and stop exactly at its end,
the same scheme as the maneuver tracker of :mod:`avp_scenario.maneuvers`: each step the largest speed that
the speed limits allow (cruise speed, lateral acceleration in arcs, acceleration / deceleration limits,
braking to stop exactly at the end in whole steps), and the heading set one step ahead to the reference
heading at the middle of the next step minus atan(e_lat / 1 m) (e_lat: lateral error of the next
position), |omega| <= |v| / R_min. The states are eq. (1) rolled out from the start with these controls
(:func:`rollout`), i.e. what the simulator replays.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

from avp_world.geometry import wrap_angle
from avp_world.kinematics import brake_speed
from avp_world.lot import LotMap
from avp_world.vehicle import VehicleSpec

R_RIGHT = 3.6  # m, radius of right turns
R_LEFT = 5.0  # m, radius of left turns
MAX_TURN = math.radians(100.0)  # sharper turns at a node are not allowed
A_LAT = 1.2  # m/s^2, lateral acceleration that sets the speed in arcs
A_ACC = 1.2  # m/s^2
A_DEC = 1.5  # m/s^2
L_CORR = 1.0  # m, distance over which a lateral error is steered away
_NODE_MERGE = 0.3  # m


# --------------------------------------------------------------------------------------------- paths


@dataclass(frozen=True)
class Path:
    """A chain of straights (curvature 0) and circular arcs from ``start`` (x, y, theta).

    ``prims``: per primitive (start x, y, unwrapped heading, start arc length, length, curvature, speed cap).
    """

    start: tuple[float, float, float]
    prims: tuple[tuple[float, float, float, float, float, float, float], ...]

    @property
    def length(self) -> float:
        if not self.prims:
            return 0.0
        p = self.prims[-1]
        return p[3] + p[4]

    @staticmethod
    def build(start, pieces: list[tuple[float, float, float]]) -> Path:
        """``pieces``: (length, curvature, speed cap); zero-length pieces are dropped."""
        x, y, th = (float(v) for v in start)
        s = 0.0
        prims = []
        for length, kappa, cap in pieces:
            if length <= 1e-9:
                continue
            prims.append((x, y, th, s, float(length), float(kappa), float(cap)))
            x, y, th = _advance(x, y, th, float(length), float(kappa))
            s += length
        return Path((float(start[0]), float(start[1]), float(start[2])), tuple(prims))

    def pose(self, s: float) -> tuple[float, float, float]:
        """Pose at arc length s (clamped to the path); heading unwrapped."""
        if not self.prims:
            return self.start
        i = self._index(s)
        x, y, th, s0, length, kappa, _ = self.prims[i]
        return _advance(x, y, th, min(max(s - s0, 0.0), length), kappa)

    def end_pose(self) -> tuple[float, float, float]:
        return self.pose(self.length)

    def _index(self, s: float) -> int:
        for i, p in enumerate(self.prims):
            if s < p[3] + p[4]:
                return i
        return len(self.prims) - 1

    def project(self, px: float, py: float, hint: int) -> tuple[int, float, float]:
        """(primitive, arc length, lateral offset to the left) of the point, searched from primitive ``hint``."""
        i = hint
        n = len(self.prims)
        for _ in range(2 * n + 2):
            x, y, th, s0, length, kappa, _ = self.prims[i]
            if kappa == 0.0:
                c, sn = math.cos(th), math.sin(th)
                t = (px - x) * c + (py - y) * sn
                lat = -(px - x) * sn + (py - y) * c
            else:
                r = 1.0 / kappa
                cx, cy = x - r * math.sin(th), y + r * math.cos(th)
                ang = math.atan2(py - cy, px - cx)
                # heading at the projection: ang + pi/2 for a left arc (kappa > 0), ang - pi/2 for a right arc
                th_p = ang + math.copysign(math.pi / 2.0, kappa)
                t = wrap_angle(th_p - th) / kappa
                dist = math.hypot(px - cx, py - cy)
                lat = math.copysign(1.0, kappa) * (abs(r) - dist)
            if t > length and i + 1 < n:
                i += 1
                continue
            if t < 0.0 and i > 0:
                i -= 1
                continue
            return i, s0 + t, lat
        return i, s0 + t, lat

    def cap_at(self, s: float) -> float:
        """The allowed speed at s: each primitive's cap, and braking in time for the next ones (A_DEC)."""
        i = self._index(s)
        v = self.prims[i][6]
        for p in self.prims[i + 1:]:
            gap = p[3] - s
            if gap * 2.0 * A_DEC > 50.0:
                break
            v = min(v, math.sqrt(p[6] ** 2 + 2.0 * A_DEC * max(gap, 0.0)))
        return v


def _advance(x: float, y: float, th: float, ds: float, kappa: float) -> tuple[float, float, float]:
    if abs(kappa) < 1e-12:
        return x + ds * math.cos(th), y + ds * math.sin(th), th
    th2 = th + kappa * ds
    r = 1.0 / kappa
    return x + r * (math.sin(th2) - math.sin(th)), y - r * (math.cos(th2) - math.cos(th)), th2


def rollout(state0, controls: np.ndarray, dt: float) -> np.ndarray:
    """Eq. (1) along ``controls`` (T, 2) from ``state0``: (T + 1, 3) states, the same arithmetic as
    :func:`avp_world.kinematics.step_vehicle` in scalar Python (several times faster for one car)."""
    x, y, th = (float(v) for v in state0)
    out = [(x, y, th)]
    two_pi = 2.0 * math.pi
    for v, om in np.asarray(controls, dtype=float).reshape(-1, 2).tolist():
        x, y, th = x + v * math.cos(th) * dt, y + v * math.sin(th) * dt, (th + om * dt + math.pi) % two_pi - math.pi
        out.append((x, y, th))
    return np.array(out, dtype=float)


def follow(path: Path, state0, dt: float, vehicle: VehicleSpec = VehicleSpec()) -> tuple[np.ndarray, np.ndarray]:
    """Controls (T, 2) driving eq. (1) from ``state0`` along ``path`` to a stop at its end (module docstring),
    and the states (T + 1, 3) = ``rollout(state0, controls, dt)``."""
    kmax = (1.0 / vehicle.min_turning_radius) * (1.0 - 1e-9)
    dv_acc, dv_dec = A_ACC * dt, A_DEC * dt * (1.0 - 1e-12)
    x, y, th = (float(v) for v in state0)
    length = path.length
    controls: list[tuple[float, float]] = []
    if length <= 1e-6:
        return np.zeros((0, 2)), np.asarray(state0, dtype=float).reshape(1, 3)
    hint = 0
    speed = 0.0

    def target_speed(sigma: float, prev: float) -> float:
        rem = length - sigma
        v = min(path.cap_at(min(max(sigma, 0.0), length)), prev + dv_acc, brake_speed(rem, dt, dv_dec))
        return max(v, 0.0)

    for _ in range(200000):
        hint, sigma, _ = path.project(x, y, hint)
        rem = length - sigma
        if rem < 0.005 and speed <= dv_dec:
            break
        v = target_speed(sigma, speed)
        if v <= 1e-9:
            break
        speed = v
        nx, ny = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
        hint2, sigma2, e_lat = path.project(nx, ny, hint)
        mid = min(max(sigma2 + 0.5 * target_speed(sigma2, v) * dt, 0.0), length)
        th_ref = path.pose(mid)[2]
        target = th_ref - math.atan(e_lat / L_CORR)
        omega = wrap_angle(target - th) / dt
        lim = v * kmax
        omega = min(max(omega, -lim), lim)
        controls.append((v, omega))
        x, y, th = nx, ny, wrap_angle(th + omega * dt)
    else:  # pragma: no cover
        raise RuntimeError("path tracking did not finish")
    controls.append((0.0, 0.0))
    u = np.array(controls, dtype=float).reshape(-1, 2)
    return u, rollout(state0, u, dt)


# ----------------------------------------------------------------------------------------- lane graph


@dataclass(frozen=True)
class Lane:
    """Directed lane from node u to node v: the line a + t d, t in [0, length] (a: right of node u by w / 4)."""

    id: int
    u: int
    v: int
    road: int  # -1: the entrance lanes
    width: float
    a: np.ndarray
    d: np.ndarray
    length: float

    @property
    def heading(self) -> float:
        return math.atan2(self.d[1], self.d[0])

    def point(self, t: float) -> np.ndarray:
        return self.a + t * self.d


@dataclass
class Turn:
    """Lane l1 -> lane l2 at their common node: leave l1 at t1, arc of signed angle phi and radius r, join l2
    at t2 (for a straight continuation phi = 0, t1 = l1.length, t2 = 0)."""

    t1: float
    t2: float
    phi: float
    radius: float


@dataclass
class LaneGraph:
    """The lanes of a lot (module docstring). ``entry`` / ``exit`` are the entrance lanes (into / out of the lot)."""

    lot: LotMap
    nodes: np.ndarray
    lanes: list[Lane]
    turns: dict[tuple[int, int], Turn]
    nexts: dict[int, list[int]]
    entry: int
    exit: int
    dead_ends: set[int]
    spot_lanes: dict[int, list[tuple[int, float, str]]] = field(default_factory=dict)  # lane -> (row, t, side)

    @classmethod
    def build(cls, lot: LotMap, spot_road: np.ndarray | None = None) -> LaneGraph:
        from avp_world.lot_scenario import spot_aisles

        roads = lot.roads
        pts: list[np.ndarray] = []
        for r in roads:
            pts += [np.asarray(r.start, float), np.asarray(r.end, float)]
        for i in range(len(roads)):
            for j in range(i + 1, len(roads)):
                x = _segment_intersection(roads[i], roads[j])
                if x is not None:
                    pts.append(x)
        nodes: list[np.ndarray] = []
        for p in pts:
            if not any(np.hypot(*(p - q)) < _NODE_MERGE for q in nodes):
                nodes.append(p)
        node_arr = np.array(nodes)
        lanes: list[Lane] = []

        def add_pair(u: int, v: int, road: int, width: float, pu: np.ndarray, pv: np.ndarray) -> tuple[int, int]:
            ids = []
            for a_, b_, p, q in ((u, v, pu, pv), (v, u, pv, pu)):
                length = float(np.hypot(*(q - p)))
                d = (q - p) / length
                right = np.array([d[1], -d[0]])
                lanes.append(Lane(len(lanes), a_, b_, road, width, p + right * width / 4.0, d, length))
                ids.append(len(lanes) - 1)
            return ids[0], ids[1]

        for j, r in enumerate(roads):
            a, b = np.asarray(r.start, float), np.asarray(r.end, float)
            d = (b - a) / r.length
            t = (node_arr - a) @ d
            off = np.abs((node_arr - a) @ np.array([-d[1], d[0]]))
            on = np.nonzero((off < _NODE_MERGE) & (t > -_NODE_MERGE) & (t < r.length + _NODE_MERGE))[0]
            on = on[np.argsort(t[on])]
            for u, v in zip(on[:-1], on[1:], strict=True):
                add_pair(int(u), int(v), j, r.width, node_arr[u], node_arr[v])
        n_nodes = len(node_arr)
        # entrance: a virtual node joined to the nearest node, continuing the road collinear with it
        ent = np.asarray(lot.entrance, float)
        near = int(np.argmin(np.hypot(*(node_arr - ent).T)))
        d_in = node_arr[near] - ent
        d_in /= np.hypot(*d_in)
        width = max(ln.width for ln in lanes if ln.u == near)
        for ln in lanes:
            if ln.u == near and abs(float(ln.d @ d_in) - 1.0) < 1e-6:
                width = ln.width
        node_arr = np.vstack([node_arr, ent])
        entry, exit_ = add_pair(n_nodes, near, -1, width, ent, node_arr[near])

        degree = np.zeros(len(node_arr), dtype=int)
        for ln in lanes:
            degree[ln.u] += ln.road >= 0
        dead = {int(n) for n in np.nonzero(degree <= 1)[0] if n != n_nodes}
        turns: dict[tuple[int, int], Turn] = {}
        nexts: dict[int, list[int]] = {ln.id: [] for ln in lanes}
        for l1 in lanes:
            for l2 in lanes:
                if l2.u != l1.v or (l2.v == l1.u and l2.road == l1.road):
                    continue
                turn = _turn(l1, l2)
                if turn is not None:
                    turns[(l1.id, l2.id)] = turn
                    nexts[l1.id].append(l2.id)
        g = cls(lot, node_arr, lanes, turns, nexts, entry, exit_, dead)
        g.spot_lanes = _spot_lanes(lot, lanes, spot_aisles(lot) if spot_road is None else spot_road)
        return g

    # ------------------------------------------------------------------ queries
    def lane_at(self, pose, tol: float = 0.3) -> tuple[int, float] | None:
        """(lane, t) of a pose lying on a lane line and heading along it, or None."""
        p = np.asarray(pose[:2], float)
        for ln in self.lanes:
            if ln.road < 0:
                continue
            t = float((p - ln.a) @ ln.d)
            lat = float((p - ln.a) @ np.array([-ln.d[1], ln.d[0]]))
            if abs(lat) < tol and -ln.width / 2 - tol <= t <= ln.length + ln.width / 2 + tol \
                    and abs(wrap_angle(float(pose[2]) - ln.heading)) < 0.1:
                return ln.id, t
        return None

    def shortest(self, lane: int, goal: int) -> list[int]:
        """Lane sequence from ``lane`` to ``goal`` minimising the driven length (Dijkstra over turns)."""
        dist = {lane: 0.0}
        prev: dict[int, int] = {}
        heap = [(0.0, lane)]
        while heap:
            d, u = heapq.heappop(heap)
            if u == goal:
                break
            if d > dist.get(u, math.inf):
                continue
            for v in self.nexts[u]:
                nd = d + self.lanes[v].length
                if nd < dist.get(v, math.inf):
                    dist[v] = nd
                    prev[v] = u
                    heapq.heappush(heap, (nd, v))
        if goal not in dist:
            raise ValueError(f"lane {goal} unreachable from lane {lane}")
        seq = [goal]
        while seq[-1] != lane:
            seq.append(prev[seq[-1]])
        return seq[::-1]

    def route_pieces(self, lanes: list[int], t_start: float, t_end: float, v_cruise: float,
                     caps: dict[int, float] | None = None) -> tuple[tuple[float, float, float], list]:
        """Start pose and (length, curvature, cap) pieces along ``lanes`` from t_start on the first to t_end on the
        last. ``caps``: speed cap per lane (default ``v_cruise``). Raises ValueError where turns overlap."""
        caps = caps or {}
        first = self.lanes[lanes[0]]
        p = first.point(t_start)
        start = (float(p[0]), float(p[1]), first.heading)
        pieces = []
        t = t_start
        for k in range(len(lanes) - 1):
            ln = self.lanes[lanes[k]]
            turn = self.turns[(lanes[k], lanes[k + 1])]
            straight = turn.t1 - t
            if straight < -1e-6 and ln.road >= 0:
                raise ValueError(f"turn from lane {ln.id} starts before the path reaches it ({straight:.2f} m)")
            cap = caps.get(ln.id, v_cruise)
            pieces.append((max(straight, 0.0), 0.0, cap))
            if turn.phi != 0.0:
                k_sign = math.copysign(1.0 / turn.radius, turn.phi)
                pieces.append((abs(turn.phi) * turn.radius, k_sign,
                               min(cap, v_cruise, math.sqrt(A_LAT * turn.radius))))
            t = turn.t2
        last = self.lanes[lanes[-1]]
        if t_end < t - 1e-6:
            raise ValueError(f"path ends at t = {t_end:.2f} before it enters lane {last.id} at t = {t:.2f}")
        pieces.append((max(t_end - t, 0.0), 0.0, caps.get(last.id, v_cruise)))
        return start, pieces


def _segment_intersection(r1, r2) -> np.ndarray | None:
    a, b = np.asarray(r1.start, float), np.asarray(r1.end, float)
    c, d = np.asarray(r2.start, float), np.asarray(r2.end, float)
    e, f = b - a, d - c
    den = e[0] * f[1] - e[1] * f[0]
    if abs(den) < 1e-12:
        return None
    w = c - a
    t = (w[0] * f[1] - w[1] * f[0]) / den
    s = (w[0] * e[1] - w[1] * e[0]) / den
    tol1, tol2 = _NODE_MERGE / r1.length, _NODE_MERGE / r2.length
    if -tol1 <= t <= 1 + tol1 and -tol2 <= s <= 1 + tol2:
        return a + t * e
    return None


def _turn(l1: Lane, l2: Lane) -> Turn | None:
    phi = wrap_angle(l2.heading - l1.heading)
    if abs(phi) < 1e-3:
        lat = float((l2.a - l1.a) @ np.array([-l1.d[1], l1.d[0]]))
        if abs(lat) > 0.05:
            return None
        return Turn(l1.length, 0.0, 0.0, 0.0)
    if abs(phi) > MAX_TURN:
        return None
    den = l1.d[0] * l2.d[1] - l1.d[1] * l2.d[0]
    w = l2.a - l1.a
    t1x = (w[0] * l2.d[1] - w[1] * l2.d[0]) / den
    t2x = (w[0] * l1.d[1] - w[1] * l1.d[0]) / den
    r = R_LEFT if phi > 0 else R_RIGHT
    tang = r * math.tan(abs(phi) / 2.0)
    return Turn(float(t1x - tang), float(t2x + tang), float(phi), r)


def _spot_lanes(lot: LotMap, lanes: list[Lane], spot_road: np.ndarray) -> dict[int, list[tuple[int, float, str]]]:
    """For each lane, the spots bordering its road whose centre projects within the lane (+- w / 2): (spot row,
    lane coordinate of the spot centre, 'near' if the spot lies on the driver's right else 'far'), by t."""
    out: dict[int, list[tuple[int, float, str]]] = {}
    centres = lot.spot_poses[:, :2]
    for ln in lanes:
        rows = np.nonzero(spot_road == ln.road)[0] if ln.road >= 0 else np.zeros(0, dtype=int)
        items = []
        for k in rows:
            t = float((centres[k] - ln.a) @ ln.d)
            lat = float((centres[k] - ln.a) @ np.array([-ln.d[1], ln.d[0]]))
            if -ln.width / 2.0 <= t <= ln.length + ln.width / 2.0:
                items.append((int(k), t, "near" if lat < 0 else "far"))
        out[ln.id] = sorted(items, key=lambda it: it[1])
    return out
