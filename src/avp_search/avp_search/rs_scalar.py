"""Scalar (one pose pair) Reeds-Shepp shortest path, for the analytic expansion of Hybrid A* (§V-D).

:func:`avp_world.reeds_shepp.reeds_shepp_batch` evaluates the 44 formula instances of Reeds & Shepp (1990)
vectorised over many pose pairs; for a single pair its numpy overhead dominates (~2.5 ms). This module
evaluates the same 44 instances (same base formulas 8.1-8.11, same symmetries, same order, same tie
breaking) with the ``math`` module in ~0.1 ms. The tests check it against the vectorised version.

Segment lengths are signed metres (negative = reverse); ``L`` turns left (curvature +1/R with respect to
the signed arc length), ``R`` right (-1/R), ``S`` is straight.
"""

from __future__ import annotations

import math

from avp_world.reeds_shepp import formula_instances

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_ZERO = 1e-10


def _mod2pi(a: float) -> float:
    v = math.fmod(a, _TWO_PI)
    if v < -_PI:
        v += _TWO_PI
    if v > _PI:
        v -= _TWO_PI
    return v


def _lsl(x, y, phi):
    sp, cp = math.sin(phi), math.cos(phi)
    ax, ay = x - sp, y - 1.0 + cp
    u, t = math.hypot(ax, ay), math.atan2(ay, ax)
    v = _mod2pi(phi - t)
    if t >= -_ZERO and v >= -_ZERO:
        return (t, u, v)
    return None


def _lsr(x, y, phi):
    sp, cp = math.sin(phi), math.cos(phi)
    ax, ay = x + sp, y - 1.0 - cp
    rho2 = ax * ax + ay * ay
    if rho2 < 4.0:
        return None
    t1 = math.atan2(ay, ax)
    u = math.sqrt(rho2 - 4.0)
    t = _mod2pi(t1 + math.atan2(2.0, u))
    v = _mod2pi(t - phi)
    if t >= -_ZERO and v >= -_ZERO:
        return (t, u, v)
    return None


def _lrl(x, y, phi):
    sp, cp = math.sin(phi), math.cos(phi)
    ax, ay = x - sp, y - 1.0 + cp
    rho = math.hypot(ax, ay)
    if rho > 4.0:
        return None
    theta = math.atan2(ay, ax)
    u = -2.0 * math.asin(min(max(0.25 * rho, -1.0), 1.0))
    t = _mod2pi(theta + 0.5 * u + _PI)
    v = _mod2pi(phi - t + u)
    if t >= -_ZERO and u <= _ZERO:
        return (t, u, v)
    return None


def _tau_omega(u, v, xi, eta, phi):
    delta = _mod2pi(u - v)
    a = math.sin(u) - math.sin(delta)
    b = math.cos(u) - math.cos(delta) - 1.0
    t1 = math.atan2(eta * a - xi * b, xi * a + eta * b)
    t2 = 2.0 * (math.cos(delta) - math.cos(v) - math.cos(u)) + 3.0
    tau = _mod2pi(t1 + _PI) if t2 < 0.0 else _mod2pi(t1)
    omega = _mod2pi(tau - u + v - phi)
    return tau, omega


def _lrlr_a(x, y, phi):
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho = 0.25 * (2.0 + math.hypot(xi, eta))
    if rho > 1.0:
        return None
    u = math.acos(min(max(rho, -1.0), 1.0))
    t, v = _tau_omega(u, -u, xi, eta, phi)
    if t >= -_ZERO and v <= _ZERO:
        return (t, u, -u, v)
    return None


def _lrlr_b(x, y, phi):
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho = (20.0 - xi * xi - eta * eta) / 16.0
    if rho < 0.0 or rho > 1.0:
        return None
    u = -math.acos(rho)
    if u < -_HALF_PI:
        return None
    t, v = _tau_omega(u, u, xi, eta, phi)
    if t >= -_ZERO and v >= -_ZERO:
        return (t, u, u, v)
    return None


def _lrsl(x, y, phi):
    ax, ay = x - math.sin(phi), y - 1.0 + math.cos(phi)
    rho2 = ax * ax + ay * ay
    if rho2 < 4.0:
        return None
    theta = math.atan2(ay, ax)
    r = math.sqrt(rho2 - 4.0)
    u = 2.0 - r
    t = _mod2pi(theta + math.atan2(r, -2.0))
    v = _mod2pi(phi - _HALF_PI - t)
    if t >= -_ZERO and u <= _ZERO and v <= _ZERO:
        return (t, -_HALF_PI, u, v)
    return None


def _lrsr(x, y, phi):
    ax, ay = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho = math.hypot(ax, ay)
    if rho < 2.0:
        return None
    theta = math.atan2(ay, ax)
    t = _mod2pi(theta + _HALF_PI)
    u = 2.0 - rho
    v = _mod2pi(t + _HALF_PI - phi)
    if t >= -_ZERO and u <= _ZERO and v <= _ZERO:
        return (t, -_HALF_PI, u, v)
    return None


def _lrslr(x, y, phi):
    xi = x + math.sin(phi)
    eta = y - 1.0 - math.cos(phi)
    rho2 = xi * xi + eta * eta
    if rho2 < 4.0:
        return None
    u = 4.0 - math.sqrt(rho2 - 4.0)
    if u > _ZERO:
        return None
    t = _mod2pi(math.atan2((4.0 - u) * xi - 2.0 * eta, -2.0 * xi + (u - 4.0) * eta))
    v = _mod2pi(t - phi)
    if t >= -_ZERO and v >= -_ZERO:
        return (t, -_HALF_PI, u, -_HALF_PI, v)
    return None


_FORMULAS = (_lsl, _lsr, _lrl, _lrlr_a, _lrlr_b, _lrsl, _lrsr, _lrslr)  # as avp_world.reeds_shepp.BASE_WORDS
_INSTANCES = formula_instances(_FORMULAS)
CURVATURE_SIGN = {"L": 1.0, "R": -1.0, "S": 0.0}


def _cusps(lens) -> int:
    last = 0.0
    n = 0
    for ln in lens:
        if abs(ln) > 1e-9:
            s = 1.0 if ln > 0 else -1.0
            if last != 0.0 and s != last:
                n += 1
            last = s
    return n


def rs_candidates(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius: float, cusp_penalty: float = 0.0,
    k: int = 3, slack: float = math.inf,
) -> list[tuple[float, tuple[tuple[str, float], ...]]]:
    """Up to ``k`` Reeds-Shepp paths (distinct words) in increasing order of length + ``cusp_penalty`` per cusp,
    keeping only those whose score is within ``slack`` (metres) of the best; same format as :func:`rs_shortest`."""
    found = _evaluate(start, goal, radius, cusp_penalty)
    found.sort(key=lambda e: e[0])
    out = []
    for score, total, word, r in found[:k]:
        if score > found[0][0] + slack:
            break
        out.append((total * radius, tuple((kk, v * radius) for kk, v in zip(word, r, strict=True) if abs(v) > 1e-10)))
    return out


def _evaluate(start, goal, radius, cusp_penalty):
    """All valid instances: [(score, total, word, normalised lengths)] in instance order."""
    sx0, sy0, sth = float(start[0]), float(start[1]), float(start[2])
    dx, dy = float(goal[0]) - sx0, float(goal[1]) - sy0
    c, s = math.cos(sth), math.sin(sth)
    x = (c * dx + s * dy) / radius
    y = (-s * dx + c * dy) / radius
    phi = _mod2pi(float(goal[2]) - sth)
    cphi, sphi_ = math.cos(phi), math.sin(phi)
    xb, yb = x * cphi + y * sphi_, x * sphi_ - y * cphi
    pen = cusp_penalty / radius
    out = []
    for f, word, back, flip, refl in _INSTANCES:
        bx, by = (xb, yb) if back else (x, y)
        if flip:
            bx = -bx
        if refl:
            by = -by
        r = f(bx, by, -phi if flip != refl else phi)
        if r is None:
            continue
        if back:
            r = r[::-1]
        if flip:
            r = tuple(-v for v in r)
        total = 0.0
        for v in r:
            total += abs(v)
        if not math.isfinite(total):
            continue
        out.append((total + pen * _cusps(r) if pen > 0 else total, total, word, r))
    return out


def rs_shortest(
    start: tuple[float, float, float], goal: tuple[float, float, float], radius: float, cusp_penalty: float = 0.0
) -> tuple[float, tuple[tuple[str, float], ...]]:
    """Shortest (or length + ``cusp_penalty`` per cusp minimising) Reeds-Shepp path, turning radius ``radius``.

    Returns:
        (length in metres, ((kind, signed length in metres), ...)) with zero-length segments dropped.
    """
    found = _evaluate(start, goal, radius, cusp_penalty)
    if not found:  # pragma: no cover - a Reeds-Shepp word always exists
        raise RuntimeError("no Reeds-Shepp word found")
    _, total, word, r = min(found, key=lambda e: e[0])  # first minimum in instance order
    segs = tuple((k, v * radius) for k, v in zip(word, r, strict=True) if abs(v) > 1e-10)
    return total * radius, segs
