"""Geometric paths of the ego: chains of circular arcs and straights driven forward or in reverse (§V-D).

A :class:`Path` is a start pose and segments ``(kappa, ell)``: ``ell`` is the signed arc length (negative =
reverse) and ``kappa`` the curvature with respect to the signed arc length, so the heading changes by
``kappa * ell`` along the segment (the convention of :mod:`avp_world.reeds_shepp`: an ``L`` segment has
kappa = +1/R, ``R`` has -1/R, ``S`` has 0). Motion primitives of Hybrid A* and Reeds-Shepp shots are both
such chains, and every pose along them is exact (closed form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from avp_world.geometry import wrap_angle as wrap  # noqa: F401 - re-exported for the planner modules

_EPS_K = 1e-12


def arc_poses(x: float, y: float, th: float, kappa: float, s: np.ndarray) -> np.ndarray:
    """Poses (..., 3) after signed arc lengths ``s`` along an arc of curvature ``kappa`` from (x, y, th).

    Headings are *not* wrapped (continuous along the arc).
    """
    s = np.asarray(s, dtype=float)
    out = np.empty(s.shape + (3,))
    if abs(kappa) < _EPS_K:
        out[..., 0] = x + s * math.cos(th)
        out[..., 1] = y + s * math.sin(th)
        out[..., 2] = th
    else:
        th1 = th + kappa * s
        out[..., 0] = x + (np.sin(th1) - math.sin(th)) / kappa
        out[..., 1] = y - (np.cos(th1) - math.cos(th)) / kappa
        out[..., 2] = th1
    return out


def arc_end(pose: tuple[float, float, float], kappa: float, ell: float) -> tuple[float, float, float]:
    """Scalar :func:`arc_poses`: the pose after one segment (heading not wrapped)."""
    x, y, th = pose
    if abs(kappa) < _EPS_K:
        return (x + ell * math.cos(th), y + ell * math.sin(th), th)
    th1 = th + kappa * ell
    return (x + (math.sin(th1) - math.sin(th)) / kappa, y - (math.cos(th1) - math.cos(th)) / kappa, th1)


def sample_xycs(
    start: tuple[float, float, float], segments: tuple[tuple[float, float], ...], step: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fast sampling of a chain (all segments in one vectorised pass): x, y, cos θ, sin θ, cumulative arc.

    Same samples as :meth:`Path.sample` (every segment split into ceil(|ell| / step) equal pieces).
    """
    starts = [start]
    for k, ell in segments:
        starts.append(arc_end(starts[-1], k, ell))
    ks = np.array([k for k, _ in segments], dtype=float)
    ells = np.array([ell for _, ell in segments], dtype=float)
    n = np.maximum(1, np.ceil(np.abs(ells) / step - 1e-9).astype(np.int64))
    seg = np.repeat(np.arange(len(segments)), n)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    j = np.arange(len(seg)) - first[seg] + 1
    sl = ells[seg] * j / n[seg]
    p0 = np.array(starts[:-1], dtype=float).reshape(-1, 3)
    x0, y0, t0 = p0[seg, 0], p0[seg, 1], p0[seg, 2]
    k = ks[seg]
    th = t0 + k * sl
    c, s = np.cos(th), np.sin(th)
    straight = np.abs(k) < _EPS_K
    ksafe = np.where(straight, 1.0, k)
    c0, s0 = np.cos(t0), np.sin(t0)
    x = x0 + np.where(straight, sl * c0, (s - s0) / ksafe)
    y = y0 + np.where(straight, sl * s0, -(c - c0) / ksafe)
    arc = np.concatenate([[0.0], np.cumsum(np.abs(ells))])[seg] + np.abs(sl)
    cs, ss = math.cos(start[2]), math.sin(start[2])
    return (np.concatenate([[start[0]], x]), np.concatenate([[start[1]], y]), np.concatenate([[cs], c]),
            np.concatenate([[ss], s]), np.concatenate([[0.0], arc]))


def merge_segments(segments) -> tuple[tuple[float, float], ...]:
    """Drop zero-length segments and merge neighbours of equal curvature and driving direction."""
    out: list[list[float]] = []
    for k, ell in segments:
        if abs(ell) < 1e-9:
            continue
        if out and abs(out[-1][0] - k) < 1e-12 and (out[-1][1] > 0) == (ell > 0):
            out[-1][1] += ell
        else:
            out.append([float(k), float(ell)])
    return tuple((k, ell) for k, ell in out)


@dataclass(frozen=True)
class Path:
    """start (3,) and segments ((kappa, signed length), ...); see the module docstring."""

    start: tuple[float, float, float]
    segments: tuple[tuple[float, float], ...]
    stops: tuple[float, ...] = ()  # arc lengths where the ego stops (a piece ends) besides the cusps (wait_anywhere)

    @property
    def length(self) -> float:
        return float(sum(abs(ell) for _, ell in self.segments))

    @property
    def reverse_length(self) -> float:
        return float(sum(-ell for _, ell in self.segments if ell < 0))

    @property
    def n_switches(self) -> int:
        """Changes of driving direction (cusps)."""
        signs = [ell > 0 for _, ell in self.segments]
        return sum(1 for a, b in zip(signs, signs[1:], strict=False) if a != b)

    @property
    def max_abs_curvature(self) -> float:
        return max((abs(k) for k, _ in self.segments), default=0.0)

    def segment_starts(self) -> list[tuple[float, float, float]]:
        poses = [tuple(float(v) for v in self.start)]
        for k, ell in self.segments:
            poses.append(arc_end(poses[-1], k, ell))
        return poses

    def end(self) -> np.ndarray:
        p = self.segment_starts()[-1]
        return np.array([p[0], p[1], float(wrap(p[2]))])

    def sample(self, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Samples every <= ``step`` metres; segment joints are samples.

        Returns:
            poses (K, 3) (heading wrapped), directions (K,) int (+1/-1, the direction of the segment that
            ends at the sample; the first sample takes the first segment's), arc (K,) cumulative absolute arc
            length, kappa (K,) curvature of the segment ending at the sample.
        """
        starts = self.segment_starts()
        poses = [np.array([starts[0]])]
        dirs = [np.array([1 if not self.segments or self.segments[0][1] > 0 else -1])]
        arcs = [np.zeros(1)]
        kap = [np.array([self.segments[0][0] if self.segments else 0.0])]
        acc = 0.0
        for (k, ell), p0 in zip(self.segments, starts, strict=False):
            n = max(1, math.ceil(abs(ell) / step - 1e-9))
            s = ell * np.arange(1, n + 1) / n
            poses.append(arc_poses(p0[0], p0[1], p0[2], k, s))
            dirs.append(np.full(n, 1 if ell > 0 else -1))
            arcs.append(acc + np.abs(s))
            kap.append(np.full(n, k))
            acc += abs(ell)
        out = np.concatenate(poses)
        out[:, 2] = wrap(out[:, 2])
        return out, np.concatenate(dirs).astype(int), np.concatenate(arcs), np.concatenate(kap)

    def poses_at(self, arc: np.ndarray) -> np.ndarray:
        """Poses (N, 3) at cumulative absolute arc lengths ``arc`` (clipped to [0, length]); heading wrapped."""
        arc = np.clip(np.asarray(arc, dtype=float), 0.0, self.length)
        out = np.empty(arc.shape + (3,))
        if not self.segments:
            out[:] = self.start
            return out
        bounds = np.concatenate([[0.0], np.cumsum([abs(ell) for _, ell in self.segments])])
        idx = np.clip(np.searchsorted(bounds, arc, side="right") - 1, 0, len(self.segments) - 1)
        starts = self.segment_starts()
        for j in np.unique(idx):
            m = idx == j
            k, ell = self.segments[j]
            sgn = 1.0 if ell > 0 else -1.0
            p0 = starts[j]
            out[m] = arc_poses(p0[0], p0[1], p0[2], k, sgn * (arc[m] - bounds[j]))
        out[..., 2] = wrap(out[..., 2])
        return out

    def pieces(self) -> list[Path]:
        """Split at the cusps (and at ``stops``) into pieces of one driving direction each."""
        out: list[Path] = []
        segments, cut = self._split_at_stops()
        starts = Path(self.start, segments).segment_starts()
        cur: list[tuple[float, float]] = []
        cur_start = starts[0]
        for i, ((k, ell), p0) in enumerate(zip(segments, starts, strict=False)):
            if cur and ((cur[-1][1] > 0) != (ell > 0) or i in cut):
                out.append(Path(cur_start, tuple(cur)))
                cur, cur_start = [], p0
            cur.append((k, ell))
        if cur:
            out.append(Path(cur_start, tuple(cur)))
        return out

    def _split_at_stops(self) -> tuple[tuple[tuple[float, float], ...], set[int]]:
        """The segments with a joint at each stop strictly inside the path, and the indices of the segments that
        start at a stop."""
        stops = sorted(s for s in self.stops if 1e-6 < s < self.length - 1e-6)
        if not stops:
            return self.segments, set()
        out: list[tuple[float, float]] = []
        cut: set[int] = set()
        acc = 0.0
        for k, ell in self.segments:
            a = abs(ell)
            sgn = 1.0 if ell > 0 else -1.0
            done = 0.0
            for s in stops:
                if acc + done + 1e-6 < s < acc + a - 1e-6:
                    out.append((k, sgn * (s - acc - done)))
                    done = s - acc
                    cut.add(len(out))
                elif abs(s - acc) <= 1e-6 and out:
                    cut.add(len(out))
            out.append((k, sgn * (a - done)))
            acc += a
        return tuple(out), cut
