"""Reeds-Shepp paths (avp_world.reeds_shepp) for the car of eq. (1): OMPL as the length oracle, plus
closed-form checks of every word, the sampled geometry and the basic metric properties."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from avp_world import reeds_shepp as rs
from avp_world.geometry import wrap_angle
from avp_world.kinematics import rollout_vehicle
from avp_world.vehicle import VehicleSpec

R_CAR = VehicleSpec().min_turning_radius


def _random_pairs(n: int, seed: int, span: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lo, hi = [-span, -span, -np.pi], [span, span, np.pi]
    return rng.uniform(lo, hi, (n, 3)), rng.uniform(lo, hi, (n, 3))


def _ompl_distances(starts: np.ndarray, goals: np.ndarray, radius: float) -> np.ndarray:
    ob = pytest.importorskip("ompl.base")
    space = ob.ReedsSheppStateSpace(radius)
    a, b = space.allocState(), space.allocState()
    out = np.empty(len(starts))
    for i, (s, g) in enumerate(zip(starts, goals, strict=True)):
        a.setX(float(s[0]))
        a.setY(float(s[1]))
        a.setYaw(float(s[2]))
        b.setX(float(g[0]))
        b.setY(float(g[1]))
        b.setYaw(float(g[2]))
        out[i] = space.distance(a, b)
    return out


# ---------------------------------------------------------------------------------------------- OMPL


@pytest.mark.parametrize("radius,seed", [(R_CAR, 0), (1.0, 1), (5.0, 2)], ids=["R_car", "R1", "R5"])
def test_lengths_match_ompl_on_10000_random_pairs(radius, seed):
    starts, goals = _random_pairs(10_000, seed)
    expected = _ompl_distances(starts, goals, radius)
    got = rs.reeds_shepp_lengths(starts, goals, radius)
    err = np.abs(got - expected)
    worst = int(np.argmax(err))
    assert err.max() <= 1e-6, (starts[worst], goals[worst], got[worst], expected[worst])
    # the scalar API agrees with the vectorised one
    for i in range(0, 10_000, 997):
        assert rs.reeds_shepp_length(starts[i], goals[i], radius) == pytest.approx(got[i], abs=1e-12)


def test_lengths_match_ompl_on_degenerate_and_axis_aligned_goals():
    vals = [-4.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 4.0]
    goals = np.array(list(itertools.product(vals, vals, np.linspace(-np.pi, np.pi, 9))))
    goals = np.vstack([goals, [[1e-9, 0.0, 0.0], [0.0, 0.0, 1e-9], [0.0, 1e-9, -1e-9], [3.0, 0.0, np.pi]]])
    starts = np.zeros_like(goals)
    expected = _ompl_distances(starts, goals, 1.0)
    got = rs.reeds_shepp_lengths(starts, goals, 1.0)
    assert np.abs(got - expected).max() <= 1e-6


# ---------------------------------------------------------------------------- closed-form consistency


def test_every_valid_word_instance_reaches_its_goal():
    """All 44 formula instances: wherever a word is declared valid, driving it ends at the goal."""
    starts, goals = _random_pairs(3000, 7, span=6.0)
    x, y, phi = rs._relative(starts, goals, 1.0)
    valid, segs = rs._all_candidates(x, y, phi)
    assert len(rs.WORDS) == 44 and valid.shape == (44, 3000)
    assert valid.any(axis=1).all(), "every formula instance is used somewhere"
    for k, word in enumerate(rs.WORDS):
        for i in np.nonzero(valid[k])[0][:60]:
            p = np.zeros(3)
            for kind, ln in zip(word, segs[: len(word), k, i], strict=True):
                p = rs.segment_end(p, kind, ln, 1.0)
            assert np.hypot(p[0] - x[i], p[1] - y[i]) < 1e-8, (word, i)
            assert abs(wrap_angle(p[2] - phi[i])) < 1e-8, (word, i)


def test_segment_end_is_the_limit_of_eq1():
    """An RS segment is what eq. (1) converges to with omega = v * curvature as dt -> 0."""
    start = np.array([1.0, -2.0, 0.7])
    for kind, curv in (("L", 1 / R_CAR), ("R", -1 / R_CAR), ("S", 0.0)):
        for ln in (2.5, -1.5):
            n = 200_000
            v = ln / 1.0  # 1 s of driving
            ctrl = np.tile([v, v * curv], (1, 1))
            # constant controls: roll eq. (1) with tiny steps in one vectorised loop
            dt = 1.0 / n
            state = start.copy()
            th = start[2] + np.arange(n) * v * curv * dt
            state[0] += np.sum(v * np.cos(th) * dt)
            state[1] += np.sum(v * np.sin(th) * dt)
            state[2] = wrap_angle(start[2] + v * curv)
            exact = rs.segment_end(start, kind, ln, R_CAR)
            assert np.allclose(state[:2], exact[:2], atol=1e-4)
            assert abs(wrap_angle(state[2] - exact[2])) < 1e-9
            # and a coarse rollout of eq. (1) stays close too (consistency with avp_world.kinematics)
            coarse = rollout_vehicle(start, np.repeat(ctrl, 100, axis=0), 0.01)[-1]
            assert np.allclose(coarse[:2], exact[:2], atol=0.02)


# ---------------------------------------------------------------------------------- metric properties


def test_basic_metric_properties():
    starts, goals = _random_pairs(2000, 11)
    fwd = rs.reeds_shepp_lengths(starts, goals, R_CAR)
    back = rs.reeds_shepp_lengths(goals, starts, R_CAR)
    assert np.allclose(fwd, back, atol=1e-9)  # RS distance is symmetric
    assert (fwd >= np.hypot(*(goals[:, :2] - starts[:, :2]).T) - 1e-9).all()
    assert rs.reeds_shepp_length(starts[0], starts[0], R_CAR) == pytest.approx(0.0, abs=1e-12)
    # straight ahead / straight back
    assert rs.reeds_shepp_length([0, 0, 0], [5, 0, 0], 2.0) == pytest.approx(5.0)
    assert rs.reeds_shepp_length([0, 0, 0], [-5, 0, 0], 2.0) == pytest.approx(5.0)
    # a quarter turn on the minimal circle
    assert rs.reeds_shepp_length([0, 0, 0], [2, 2, math.pi / 2], 2.0) == pytest.approx(math.pi)
    # scaling: length(R * pose, R) = R * length(pose, 1)
    unit = rs.reeds_shepp_lengths(starts / [R_CAR, R_CAR, 1.0], goals / [R_CAR, R_CAR, 1.0], 1.0)
    assert np.allclose(unit * R_CAR, fwd, atol=1e-9)
    with pytest.raises(ValueError):
        rs.reeds_shepp_length([0, 0, 0], [1, 0, 0], 0.0)


def test_cusp_penalty_trades_length_for_fewer_cusps():
    starts, goals = _random_pairs(2000, 5, span=5.0)
    plain = rs.reeds_shepp_batch(starts, goals, R_CAR)
    pen = rs.reeds_shepp_batch(starts, goals, R_CAR, cusp_penalty=3.0)
    cusps_plain = np.array([plain.path(i).n_cusps for i in range(2000)])
    cusps_pen = np.array([pen.path(i).n_cusps for i in range(2000)])
    assert (pen.length >= plain.length - 1e-9).all()
    assert (pen.length + 3.0 * cusps_pen <= plain.length + 3.0 * cusps_plain + 1e-9).all()
    assert (cusps_pen < cusps_plain).any()


# ------------------------------------------------------------------------------------------- sampling


@pytest.mark.parametrize("step", [0.05, 0.25])
def test_sampled_paths_end_at_goal_with_bounded_steps_and_curvature(step):
    starts, goals = _random_pairs(300, 3, span=8.0)
    batch = rs.reeds_shepp_batch(starts, goals, R_CAR)
    for i, (s, g) in enumerate(zip(starts, goals, strict=True)):
        path = batch.path(i)
        if i % 50 == 0:
            assert path == rs.reeds_shepp_path(s, g, R_CAR)
        assert path.length == pytest.approx(sum(abs(ln) for _, ln in path.segments), abs=1e-9)
        assert all(kind in "LSR" for kind, _ in path.segments)
        poses, dirs = rs.sample_path(s, path, R_CAR, step)
        assert poses.shape == (len(dirs), 3) and set(np.unique(dirs)) <= {-1, 1}
        assert np.allclose(poses[0], [s[0], s[1], wrap_angle(s[2])], atol=1e-12)
        assert np.hypot(*(poses[-1, :2] - g[:2])) <= 1e-6
        assert abs(wrap_angle(poses[-1, 2] - g[2])) <= 1e-6
        chord = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        assert (chord <= step + 1e-9).all()
        assert len(poses) >= path.length / step
        # curvature: a chord c of a curve with radius >= R turns the heading by at most 2 asin(c / 2R)
        dth = np.abs(wrap_angle(np.diff(poses[:, 2])))
        assert (dth <= 2 * np.arcsin(np.minimum(1.0, chord / (2 * R_CAR))) + 1e-9).all()
        # the car moves along its heading, forward where dirs = +1 and backward where dirs = -1
        mid = poses[:-1, 2] + 0.5 * wrap_angle(np.diff(poses[:, 2]))
        heading = np.column_stack([np.cos(mid), np.sin(mid)])
        along = np.einsum("ij,ij->i", np.diff(poses[:, :2], axis=0), heading)
        moving = chord > 1e-9
        assert np.allclose(along[moving], dirs[1:][moving] * chord[moving], atol=1e-9)


def test_sample_path_includes_joints_and_directions():
    path = rs.RSPath(segments=(("L", 1.0), ("S", -0.3), ("R", 2.0)), length=3.3)
    poses, dirs = rs.sample_path([0.0, 0.0, 0.0], path, 2.0, 0.4)
    # 3 + 1 + 5 pieces, joints once, both ends: 10 samples
    assert len(poses) == 10
    assert list(dirs) == [1, 1, 1, 1, -1, 1, 1, 1, 1, 1]
    j1 = rs.segment_end(np.zeros(3), "L", 1.0, 2.0)
    assert np.allclose(poses[3], j1)
    assert np.allclose(poses[4], rs.segment_end(j1, "S", -0.3, 2.0))
    with pytest.raises(ValueError):
        rs.sample_path([0, 0, 0], path, 2.0, 0.0)
