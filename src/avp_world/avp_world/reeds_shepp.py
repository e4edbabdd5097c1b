"""Shortest Reeds-Shepp paths for the car of eq. (1) with a turning radius R (Reeds & Shepp 1990).

The car of the paper's eq. (1), s_{t+dt} = s_t + [v cos(theta), v sin(theta), omega] dt with
|omega| <= |v| / R, drives forward and backward on circles of radius >= R and on straight lines. Reeds and
Shepp showed that a shortest path between two poses is one of 48 words made of at most five arcs (C = L
or R, radius exactly R) and straight pieces (S), with at most two cusps (``|``), in the families

    CSC, CCC (C|C|C, C|CC, CC|C), CCCC (CC|CC, C|CC|C), CCSC (C|C_{pi/2}SC and its reverse CS C_{pi/2}|C),
    CCSCC (C|C_{pi/2}SC_{pi/2}|C),

and that every word is obtained from a few base formulas (their §8: 8.1 LSL, 8.2 LSR, 8.3 L|R|L,
8.7 LR|LR, 8.8 L|RL|R, 8.9 L|R_{pi/2}SL, 8.10 L|R_{pi/2}SR, 8.11 L|R_{pi/2}SL_{pi/2}|R) through three
symmetries of the goal pose (x, y, phi) given in the start frame with R = 1:

* timeflip  (x, y, phi) -> (-x, y, -phi): the same word driven in the other direction (lengths negated);
* reflect   (x, y, phi) -> (x, -y, -phi): L and R swapped;
* backwards (x, y, phi) -> (x cos phi + y sin phi, x sin phi - y cos phi, phi): the word read in reverse.

This module evaluates the 44 formula instances (8 CSC, 8 CCC, 8 CCCC, 16 CCSC, 4 CCSCC; the CCC and
CCSC instances each cover two or more of the 48 words through the sign of their free segments)
vectorised over many pose pairs, and keeps the shortest valid one. Segment lengths are signed arc
lengths in metres: positive = forward (v > 0), negative = reverse. For an ``L`` segment of signed length
l the heading changes by +l/R, for ``R`` by -l/R (so the curvature with respect to the signed arc
length is +1/R for L, -1/R for R, 0 for S, whatever the driving direction).

Written from the formulas in J. A. Reeds, L. A. Shepp, "Optimal paths for a car that goes both forwards
and backwards", Pacific J. Math. 145(2), 1990; checked against OMPL's ``ReedsSheppStateSpace`` in the
tests.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

_PI = math.pi
_HALF_PI = 0.5 * math.pi
_ZERO = 1e-10  # sign tolerance of the validity tests (normalised units, R = 1)

__all__ = [
    "RSBatch",
    "RSPath",
    "WORDS",
    "reeds_shepp_batch",
    "reeds_shepp_length",
    "reeds_shepp_lengths",
    "reeds_shepp_path",
    "sample_path",
    "segment_end",
]


# ------------------------------------------------------------------------------------------ helpers


def _mod2pi(a: np.ndarray) -> np.ndarray:
    """Wrap to (-pi, pi]."""
    v = np.fmod(a, 2.0 * _PI)
    v = np.where(v < -_PI, v + 2.0 * _PI, v)
    return np.where(v > _PI, v - 2.0 * _PI, v)


def _polar(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.hypot(x, y), np.arctan2(y, x)


def _tau_omega(u, v, xi, eta, phi):
    """The two free arcs (tau, omega) of the CCCC words 8.7/8.8 for given middle arcs u, v."""
    delta = _mod2pi(u - v)
    a = np.sin(u) - np.sin(delta)
    b = np.cos(u) - np.cos(delta) - 1.0
    t1 = np.arctan2(eta * a - xi * b, xi * a + eta * b)
    t2 = 2.0 * (np.cos(delta) - np.cos(v) - np.cos(u)) + 3.0
    tau = np.where(t2 < 0.0, _mod2pi(t1 + _PI), _mod2pi(t1))
    omega = _mod2pi(tau - u + v - phi)
    return tau, omega


# ------------------------------------------------------------- base formulas (R = 1, start at origin)
# Each takes arrays (x, y, phi) of the goal in the start frame and returns (valid, [segment lengths]).
# Invalid entries may hold NaN or junk; they are masked out by ``valid``.


def _lsl(x, y, phi):
    """8.1  L+ S+ L+."""
    u, t = _polar(x - np.sin(phi), y - 1.0 + np.cos(phi))
    v = _mod2pi(phi - t)
    return (t >= -_ZERO) & (v >= -_ZERO), [t, u, v]


def _lsr(x, y, phi):
    """8.2  L+ S+ R+."""
    rho, t1 = _polar(x + np.sin(phi), y - 1.0 - np.cos(phi))
    ok = rho * rho >= 4.0
    u = np.sqrt(np.maximum(rho * rho - 4.0, 0.0))
    t = _mod2pi(t1 + np.arctan2(2.0, u))
    v = _mod2pi(t - phi)
    return ok & (t >= -_ZERO) & (v >= -_ZERO), [t, u, v]


def _lrl(x, y, phi):
    """8.3  L+ R- L (C|C|C or C|CC)."""
    rho, theta = _polar(x - np.sin(phi), y - 1.0 + np.cos(phi))
    ok = rho <= 4.0
    u = -2.0 * np.arcsin(np.clip(0.25 * rho, -1.0, 1.0))
    t = _mod2pi(theta + 0.5 * u + _PI)
    v = _mod2pi(phi - t + u)
    return ok & (t >= -_ZERO) & (u <= _ZERO), [t, u, v]


def _lrlr_a(x, y, phi):
    """8.7  L+ R+u L-u R- (CC|CC)."""
    xi = x + np.sin(phi)
    eta = y - 1.0 - np.cos(phi)
    rho = 0.25 * (2.0 + np.hypot(xi, eta))
    ok = rho <= 1.0
    u = np.arccos(np.clip(rho, -1.0, 1.0))
    t, v = _tau_omega(u, -u, xi, eta, phi)
    return ok & (t >= -_ZERO) & (v <= _ZERO), [t, u, -u, v]


def _lrlr_b(x, y, phi):
    """8.8  L+ R-u L-u R+ (C|CC|C)."""
    xi = x + np.sin(phi)
    eta = y - 1.0 - np.cos(phi)
    rho = (20.0 - xi * xi - eta * eta) / 16.0
    ok = (rho >= 0.0) & (rho <= 1.0)
    u = -np.arccos(np.clip(rho, -1.0, 1.0))
    ok &= u >= -_HALF_PI
    t, v = _tau_omega(u, u, xi, eta, phi)
    return ok & (t >= -_ZERO) & (v >= -_ZERO), [t, u, u, v]


def _lrsl(x, y, phi):
    """8.9  L+ R-pi/2 S- L- (C|C_{pi/2}SC)."""
    rho, theta = _polar(x - np.sin(phi), y - 1.0 + np.cos(phi))
    ok = rho >= 2.0
    r = np.sqrt(np.maximum(rho * rho - 4.0, 0.0))
    u = 2.0 - r
    t = _mod2pi(theta + np.arctan2(r, -2.0))
    v = _mod2pi(phi - _HALF_PI - t)
    return ok & (t >= -_ZERO) & (u <= _ZERO) & (v <= _ZERO), [t, np.full_like(t, -_HALF_PI), u, v]


def _lrsr(x, y, phi):
    """8.10  L+ R-pi/2 S- R- (C|C_{pi/2}SC)."""
    rho, theta = _polar(x + np.sin(phi), y - 1.0 - np.cos(phi))
    ok = rho >= 2.0
    t = _mod2pi(theta + _HALF_PI)
    u = 2.0 - rho
    v = _mod2pi(t + _HALF_PI - phi)
    return ok & (t >= -_ZERO) & (u <= _ZERO) & (v <= _ZERO), [t, np.full_like(t, -_HALF_PI), u, v]


def _lrslr(x, y, phi):
    """8.11  L+ R-pi/2 S- L-pi/2 R+ (C|C_{pi/2}SC_{pi/2}|C)."""
    rho, _ = _polar(x + np.sin(phi), y - 1.0 - np.cos(phi))
    xi = x + np.sin(phi)
    eta = y - 1.0 - np.cos(phi)
    ok = rho >= 2.0
    u = 4.0 - np.sqrt(np.maximum(rho * rho - 4.0, 0.0))
    ok &= u <= _ZERO
    t = _mod2pi(np.arctan2((4.0 - u) * xi - 2.0 * eta, -2.0 * xi + (u - 4.0) * eta))
    v = _mod2pi(t - phi)
    hp = np.full_like(t, -_HALF_PI)
    return ok & (t >= -_ZERO) & (v >= -_ZERO), [t, hp, u, hp, v]


_Formula = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, list[np.ndarray]]]

#: (base word, also evaluate the backwards word) of the base formulas 8.1-8.11, in evaluation order
BASE_WORDS: tuple[tuple[str, bool], ...] = (("LSL", False), ("LSR", False), ("LRL", True), ("LRLR", False),
                                           ("LRLR", False), ("LRSL", True), ("LRSR", True), ("LRSLR", False))
_FORMULAS: tuple[_Formula, ...] = (_lsl, _lsr, _lrl, _lrlr_a, _lrlr_b, _lrsl, _lrsr, _lrslr)

_SWAP = str.maketrans("LR", "RL")


def formula_instances(formulas: tuple) -> tuple[tuple, ...]:
    """All 44 formula instances (formula, word, backwards, timeflip, reflect) of the 8 base formulas
    ``formulas`` (one per :data:`BASE_WORDS` entry), in the order both this module and the scalar version
    (:mod:`avp_search.rs_scalar`) evaluate them."""
    out = []
    for f, (word, has_back) in zip(formulas, BASE_WORDS, strict=True):
        for back in (False, True) if has_back else (False,):
            for flip in (False, True):
                for refl in (False, True):
                    w = word[::-1] if back else word
                    out.append((f, w.translate(_SWAP) if refl else w, back, flip, refl))
    return tuple(out)


_INSTANCES: tuple[tuple[_Formula, str, bool, bool, bool], ...] = formula_instances(_FORMULAS)
WORDS: tuple[str, ...] = tuple(inst[1] for inst in _INSTANCES)
"""The word (segment kinds) of each formula instance, indexed by :attr:`RSBatch.word_index`."""
MAX_SEGMENTS = 5


def _all_candidates(x: np.ndarray, y: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate every instance for goals (x, y, phi) (N,) in the start frame, R = 1.

    Returns:
        valid (44, N) and signed segment lengths (5, 44, N) (normalised, zero-padded after the word and
        where invalid), laid out instance-major for speed.
    """
    n = x.shape[0]
    valid = np.zeros((len(_INSTANCES), n), dtype=bool)
    segs = np.zeros((MAX_SEGMENTS, len(_INSTANCES), n))
    c, s = np.cos(phi), np.sin(phi)
    xb, yb = x * c + y * s, x * s - y * c
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, (f, _word, back, flip, refl) in enumerate(_INSTANCES):
            bx, by = (xb, yb) if back else (x, y)
            sx = -1.0 if flip else 1.0
            sy = -1.0 if refl else 1.0
            sphi = -1.0 if flip != refl else 1.0
            ok, lens = f(sx * bx, sy * by, sphi * phi)
            if back:
                lens = lens[::-1]
            for ln in lens:
                ok &= np.isfinite(ln)
            valid[k] = ok
            for j, ln in enumerate(lens):
                segs[j, k] = np.where(ok, -ln if flip else ln, 0.0)
    return valid, segs


# -------------------------------------------------------------------------------------------- API


@dataclass(frozen=True)
class RSPath:
    """A Reeds-Shepp path: ``segments`` = ((kind 'L'|'S'|'R', signed length in metres), ...)."""

    segments: tuple[tuple[str, float], ...]
    length: float

    @property
    def n_cusps(self) -> int:
        """Number of driving-direction reversals."""
        signs = [math.copysign(1.0, ln) for _, ln in self.segments if abs(ln) > 1e-9]
        return sum(1 for a, b in zip(signs, signs[1:], strict=False) if a != b)


@dataclass(frozen=True)
class RSBatch:
    """Shortest paths for N pose pairs.

    length: (N,) metres; word_index: (N,) index into :data:`WORDS`; seg_lengths: (N, 5) signed metres
    (zero-padded after the word's segments).
    """

    length: np.ndarray
    word_index: np.ndarray
    seg_lengths: np.ndarray

    def path(self, i: int) -> RSPath:
        word = WORDS[int(self.word_index[i])]
        lens = self.seg_lengths[i, : len(word)]
        segs = tuple((kind, float(ln)) for kind, ln in zip(word, lens, strict=True) if abs(ln) > 1e-10)
        return RSPath(segments=segs, length=float(self.length[i]))


def _relative(start: np.ndarray, goal: np.ndarray, radius: float) -> tuple[np.ndarray, ...]:
    start = np.atleast_2d(np.asarray(start, dtype=float))
    goal = np.atleast_2d(np.asarray(goal, dtype=float))
    start, goal = np.broadcast_arrays(start, goal)
    dx = goal[:, 0] - start[:, 0]
    dy = goal[:, 1] - start[:, 1]
    c, s = np.cos(start[:, 2]), np.sin(start[:, 2])
    x = (c * dx + s * dy) / radius
    y = (-s * dx + c * dy) / radius
    phi = _mod2pi(goal[:, 2] - start[:, 2])
    return x, y, phi


def _count_cusps(segs: np.ndarray) -> np.ndarray:
    """Direction reversals along the first axis of signed lengths (zero-length segments ignored)."""
    s = (np.sign(segs) * (np.abs(segs) > 1e-9)).astype(np.int8)
    for j in range(1, s.shape[0]):  # carry the last direction over zero-length segments
        s[j] = np.where(s[j] == 0, s[j - 1], s[j])
    return np.count_nonzero(s[1:] * s[:-1] < 0, axis=0)


def reeds_shepp_batch(
    starts: np.ndarray, goals: np.ndarray, radius: float, cusp_penalty: float = 0.0
) -> RSBatch:
    """Shortest Reeds-Shepp paths between (N, 3) starts and (N, 3) goals (broadcast), turning radius R.

    With ``cusp_penalty`` > 0 (metres per change of direction) the word minimising
    length + cusp_penalty * cusps among all 44 formula instances is chosen instead (e.g. a forward-only
    CSC path instead of a marginally shorter one with a tiny reversal); ``length`` stays the true length.
    """
    if radius <= 0:
        raise ValueError(f"turning radius must be > 0, got {radius}")
    x, y, phi = _relative(starts, goals, radius)
    valid, segs = _all_candidates(x, y, phi)
    total = np.where(valid, np.abs(segs).sum(0), np.inf)
    score = total + (cusp_penalty / radius) * _count_cusps(segs) if cusp_penalty > 0 else total
    best = np.argmin(score, axis=0)
    cols = np.arange(x.shape[0])
    if not np.isfinite(total[best, cols]).all():  # pragma: no cover - RS theorem: a word always exists
        raise RuntimeError("no Reeds-Shepp word found (numerical failure)")
    return RSBatch(
        length=total[best, cols] * radius,
        word_index=best,
        seg_lengths=segs[:, best, cols].T * radius,
    )


def reeds_shepp_lengths(starts: np.ndarray, goals: np.ndarray, radius: float) -> np.ndarray:
    """Vectorised :func:`reeds_shepp_length`: (N,) metres for (N, 3) starts and goals."""
    return reeds_shepp_batch(starts, goals, radius).length


def reeds_shepp_length(start: np.ndarray, goal: np.ndarray, radius: float) -> float:
    """Length (m) of the shortest Reeds-Shepp path from ``start`` to ``goal`` (each (x, y, theta))."""
    return float(reeds_shepp_batch(start, goal, radius).length[0])


def reeds_shepp_path(start: np.ndarray, goal: np.ndarray, radius: float) -> RSPath:
    """The shortest Reeds-Shepp path from ``start`` to ``goal`` for turning radius ``radius`` (m)."""
    return reeds_shepp_batch(start, goal, radius).path(0)


def segment_end(pose: np.ndarray, kind: str, length: np.ndarray | float, radius: float) -> np.ndarray:
    """Pose(s) reached from ``pose`` (3,) after a segment of signed ``length`` (scalar or (K,)) metres.

    Exact (closed form); returns (..., 3) with the heading wrapped to [-pi, pi).
    """
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    c0, s0 = math.cos(th), math.sin(th)
    ln = np.asarray(length, dtype=float)
    if kind == "S":
        out = np.stack([x + ln * c0, y + ln * s0, np.full_like(ln, th)], axis=-1)
    elif kind == "L":
        th1 = th + ln / radius
        out = np.stack([x + radius * (np.sin(th1) - s0), y - radius * (np.cos(th1) - c0), th1], axis=-1)
    elif kind == "R":
        th1 = th - ln / radius
        out = np.stack([x - radius * (np.sin(th1) - s0), y + radius * (np.cos(th1) - c0), th1], axis=-1)
    else:
        raise ValueError(f"unknown segment kind {kind!r}")
    out[..., 2] = (out[..., 2] + _PI) % (2.0 * _PI) - _PI
    return out


def sample_path(
    start: np.ndarray, path: RSPath, radius: float, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Poses every <= ``step`` metres of arc along ``path`` driven from ``start``.

    Every segment is split into ceil(|l| / step) equal pieces, so both ends and every segment joint are
    samples (each joint once). ``directions[k]`` is +1 (forward) or -1 (reverse): the direction of the
    segment that *ends* at sample k (the first sample takes the first segment's direction), so at a
    cusp the joint sample still carries the incoming direction.

    Returns:
        poses (K, 3), directions (K,) int.
    """
    if step <= 0:
        raise ValueError(f"step must be > 0, got {step}")
    pose = np.asarray(start, dtype=float).copy()
    pose[2] = (pose[2] + _PI) % (2.0 * _PI) - _PI
    poses = [pose[None, :]]
    dirs = [np.array([1 if not path.segments or path.segments[0][1] >= 0 else -1])]
    for kind, ln in path.segments:
        n = max(1, math.ceil(abs(ln) / step - 1e-9))
        s = ln * np.arange(1, n + 1) / n
        seg = segment_end(pose, kind, s, radius)
        seg[-1] = segment_end(pose, kind, ln, radius)
        poses.append(seg)
        dirs.append(np.full(n, 1 if ln >= 0 else -1))
        pose = seg[-1]
    return np.concatenate(poses), np.concatenate(dirs).astype(int)
