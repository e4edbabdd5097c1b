"""The tracker core (avp_tracking.core) on scripted detections, and the sensing model + tracker on simulated
episodes, scored against the simulator's truth with py-motmetrics (an independent scorer)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from avp_tracking.core.tracker import Tracker, TrackerConfig
from avp_world.detections import SensedFrame, VehicleDetection

DT = 0.1


def _det(x, y, th, speed=float("nan"), sigma=0.1, existence=0.9) -> VehicleDetection:
    return VehicleDetection(pose=np.array([x, y, th]), length=4.5, width=1.9,
                            covariance=np.diag([sigma ** 2, sigma ** 2, 0.05 ** 2]), existence=existence,
                            speed=speed, speed_variance=0.26 ** 2)


def _frame(step: int, vehicles=()) -> SensedFrame:
    return SensedFrame(step=step, dt=DT, ego_pose=np.zeros(3), ego_covariance=np.eye(3) * 1e-4, ego_length=4.5,
                       ego_width=1.9, ego_speed=0.0, vacant_spot_ids=np.zeros(0, np.int64),
                       occupied_spot_ids=np.zeros(0, np.int64), vehicles=tuple(vehicles))


def _ids_near(tracks, xy, r=1.5) -> list[int]:
    return [t.id for t in tracks if math.hypot(t.x[0] - xy[0], t.x[1] - xy[1]) < r]


def test_a_car_occluded_for_one_second_keeps_its_track_id():
    """A car driving at 2 m/s, unseen for 1 s (10 steps), is coasted on its motion model and picked up again under
    the same id."""
    rng = np.random.default_rng(0)
    tr = Tracker(TrackerConfig(max_coast=1.5))
    ids = set()
    for k in range(60):
        x = 2.0 * DT * k
        dets = [] if 20 <= k < 30 else [_det(x + rng.normal(0, 0.1), rng.normal(0, 0.1), 0.0, 2.0)]
        out = tr.update(_frame(k, dets))
        if k >= 5:
            near = _ids_near(out, (x, 0.0))
            assert len(near) == 1, (k, [(t.id, t.x[:2]) for t in out])
            ids.add(near[0])
    assert len(ids) == 1


def test_a_track_unseen_longer_than_max_coast_ends():
    tr = Tracker(TrackerConfig(max_coast=0.5))
    for k in range(10):
        tr.update(_frame(k, [_det(0.0, 0.0, 0.0)]))
    for k in range(10, 17):
        out = tr.update(_frame(k))
    assert out == [] and tr.tracks == []


def test_an_unseen_track_brakes_to_a_stop_with_coast_deceleration():
    """A car driving at 2 m/s goes unseen: by default its track coasts on at 2 m/s; with coast_deceleration 4 m/s^2
    it stops after 0.5 s, about 0.5 m beyond where it was last seen (v^2 / 2a), and stands there."""
    ends = {}
    for decel in (0.0, 4.0):
        tr = Tracker(TrackerConfig(max_coast=1.5, coast_deceleration=decel))
        for k in range(20):
            tr.update(_frame(k, [_det(2.0 * DT * k, 0.0, 0.0, 2.0, sigma=0.02)]))
        last = float(tr.tracks[0].x[0])
        for k in range(20, 30):
            out = tr.update(_frame(k))
        assert len(out) == 1
        ends[decel] = (float(out[0].x[0]) - last, float(out[0].x[3]))
    assert abs(ends[0.0][0] - 2.0) < 0.2 and abs(ends[0.0][1] - 2.0) < 0.2
    assert abs(ends[4.0][0] - 0.5) < 0.15 and ends[4.0][1] == 0.0


def test_a_one_step_false_positive_never_becomes_a_confirmed_track():
    """A box seen once (clutter) is tentative and dies at its first miss; one seen n_init times is confirmed."""
    tr = Tracker(TrackerConfig(n_init=3))
    seen_ids = set()
    for k in range(30):
        dets = [_det(10.0, 5.0, 1.0)] if k == 4 else []
        dets.append(_det(0.0, 0.0, 0.0))  # a parked car, always there
        out = tr.update(_frame(k, dets))
        seen_ids |= {t.id for t in out}
        assert not _ids_near(out, (10.0, 5.0)), f"step {k}: the false positive was given to the ego"
    assert len(seen_ids) == 1
    assert all(t.hits >= 3 for t in tr.tracks) and len(tr.tracks) == 1


def test_two_cars_passing_close_keep_their_ids():
    """Two cars in opposite directions on lanes 2.2 m apart pass each other at 2 m/s, with 0.15 m noise: after the
    pass each id still follows its own car."""
    rng = np.random.default_rng(3)
    tr = Tracker()
    first: dict[str, int] = {}
    for k in range(80):
        a = (-8.0 + 2.0 * DT * k, 0.0)
        b = (8.0 - 2.0 * DT * k, 2.2)
        dets = [_det(a[0] + rng.normal(0, 0.15), a[1] + rng.normal(0, 0.15), 0.0, 2.0 + rng.normal(0, 0.2), 0.15),
                _det(b[0] + rng.normal(0, 0.15), b[1] + rng.normal(0, 0.15), math.pi, 2.0 + rng.normal(0, 0.2),
                     0.15)]
        out = tr.update(_frame(k, dets))
        if k >= 5:
            ia, ib = _ids_near(out, a, 1.0), _ids_near(out, b, 1.0)
            assert len(ia) == 1 and len(ib) == 1, k
            first.setdefault("a", ia[0])
            first.setdefault("b", ib[0])
            assert (ia[0], ib[0]) == (first["a"], first["b"]), f"ids swapped at step {k}"


def test_a_track_born_from_a_flipped_box_is_turned_around_and_a_rare_flip_changes_nothing():
    tr = Tracker(TrackerConfig(flip_votes=3.0))
    for k in range(30):  # born at heading pi (the box's other end); every later box says 0
        th = math.pi if k == 0 else 0.0
        flip = k == 20  # one flipped box on a good track
        out = tr.update(_frame(k, [_det(1.0 * DT * k, 0.0, math.pi if flip else th, 1.0 * (-1 if flip else 1))]))
        if k >= 6 and out:
            assert abs(math.remainder(out[0].x[2], 2 * math.pi)) < 0.3, (k, out[0].x[2])
            assert out[0].x[3] > 0.5, (k, out[0].x[3])  # driving forward at about 1 m/s
    hist = out[0].history_array()
    assert np.all(np.abs(np.remainder(hist[:, 2] + math.pi, 2 * math.pi) - math.pi) < 0.5)  # history turned too


def test_a_reversing_car_is_tracked_with_a_negative_speed_and_its_heading_kept():
    """A car backing out of a spot (heading +y, moving -y at 1 m/s) and turning: v < 0, heading not flipped."""
    tr = Tracker()
    th, x, y = math.pi / 2, 0.0, 0.0
    for k in range(40):
        om = 0.4 if k >= 20 else 0.0
        x, y, th = x - 1.0 * math.cos(th) * DT, y - 1.0 * math.sin(th) * DT, th + om * DT
        out = tr.update(_frame(k, [_det(x, y, th, -1.0)]))
    t = out[0]
    assert t.x[3] < -0.7
    assert abs(math.remainder(t.x[2] - th, 2 * math.pi)) < 0.2
    assert abs(t.x[4] - 0.4) < 0.2  # the yaw rate, reversing while turning


def test_tracks_are_deterministic():
    rng = np.random.default_rng(1)
    frames = [_frame(k, [_det(rng.normal(0, 5), rng.normal(0, 5), rng.uniform(-3, 3)) for _ in range(6)])
              for k in range(20)]
    runs = []
    for _ in range(2):
        tr = Tracker()
        runs.append([[(t.id, *t.x) for t in tr.update(f)] for f in frames])
    assert runs[0] == runs[1]


# ------------------------------------------------------------------------------------------ on the simulator

def _episode(paper_lot, model: str, seed: int = 1, steps: int = 150, family: str = "paper", lot=None):
    """(observations through the sensing model and tracker, the world's truth at each step) of a scripted-ego
    episode (the ego drives its scripted stand-in)."""
    from avp_episode.run_config import RunConfig, sim_values
    from avp_episode.sensing import sensed_observer
    from avp_planner.scripted_driver import ScriptedDriver
    from avp_sim.core.factory import make_world

    lot = lot or paper_lot
    p = sim_values(RunConfig(sim_overrides={"sensing.model": model, "scenario.family": family}))
    world = make_world(lot, p, seed, True)
    observe = sensed_observer(world, p, seed)
    driver = ScriptedDriver(lot)
    out = []
    for _ in range(steps):
        if world.done:
            break
        obs = observe() if observe else world.observe()
        truth = {int(i): world.states[j].copy() for j, i in enumerate(world.vehicle_ids)
                 if world.last_scan.seen_vehicles[j]}
        out.append((obs, truth, world.states.copy(), world.vehicle_ids.copy()))
        world.step(*driver.command(obs))
    return out


def _motmetrics(frames) -> dict:
    """MOTA, IDF1 and id switches of the tracks against the vehicles the rays touched, 1 m match (py-motmetrics;
    our own distance matrix, as its norm2squared_matrix uses np.asfarray, gone in NumPy 2)."""
    import motmetrics as mm

    acc = mm.MOTAccumulator(auto_id=True)
    for obs, truth, _, _ in frames:
        gt_ids = sorted(truth)
        hyp = [v for v in obs.vehicles]
        d = np.full((len(gt_ids), len(hyp)), np.nan)
        for i, g in enumerate(gt_ids):
            for j, v in enumerate(hyp):
                e = math.hypot(*(truth[g][:2] - v.history[-1][:2]))
                if e < 1.0:
                    d[i, j] = e * e
        acc.update(gt_ids, [int(v.id) for v in hyp], d)
    summary = mm.metrics.create().compute(acc, metrics=["mota", "idf1", "num_switches"], name="episode")
    return {k: float(summary[k].iloc[0]) for k in ("mota", "idf1", "num_switches")}


def test_noisy_sensing_gives_no_simulator_id_and_no_exact_history(paper_lot):
    """With realistic sensing the ego's vehicles carry the tracker's ids (no vehicle's simulator id appears, since
    the tracker numbers from 1 and the paper lot's ids do too only by chance: checked against the truth of each
    track) and histories that are estimates, not the simulator's poses; the ego's pose is an estimate too."""
    frames = _episode(paper_lot, "realistic")
    assert any(f[0].vehicles for f in frames)
    from avp_episode.sensing import truth_ids

    exact_poses = 0
    n = 0
    for obs, _truth, states, _ids in frames:
        for v in obs.vehicles:
            n += 1
            exact_poses += any(np.allclose(v.history[-1], s, atol=1e-9) for s in states)
    assert n > 0 and exact_poses == 0
    frames_exact = _episode(paper_lot, "exact", steps=len(frames))
    assert all(not np.allclose(a[0].ego_pose, b[0].ego_pose) for a, b in zip(frames, frames_exact, strict=False))
    _ = truth_ids  # (the scoring map exists; the ego never calls it: tests/test_architecture.py)


@pytest.mark.parametrize("model", ["exact", "realistic", "harsh"])
def test_tracking_quality_on_the_paper_lot(paper_lot, model):
    """Scored by py-motmetrics against the truth: exact sensing gives perfect tracks; realistic and harsh give
    usable ones (floors well below what bench/bench_tracking.py measures, docs/perception.md)."""
    frames = _episode(paper_lot, model, steps=200)
    m = _motmetrics(frames)
    floor = {"exact": (0.99, 0.99), "realistic": (0.6, 0.7), "harsh": (0.3, 0.5)}[model]
    assert m["mota"] >= floor[0] and m["idf1"] >= floor[1], m


def test_same_seed_same_noisy_episode(paper_lot):
    a, b = (_episode(paper_lot, "realistic", seed=4, steps=80) for _ in range(2))
    for (oa, *_), (ob, *_) in zip(a, b, strict=True):
        assert np.array_equal(oa.ego_pose, ob.ego_pose)
        assert [(v.id, v.history.tobytes()) for v in oa.vehicles] == [(v.id, v.history.tobytes()) for v in ob.vehicles]
        assert np.array_equal(oa.vacant_spot_ids, ob.vacant_spot_ids)
    c = _episode(paper_lot, "realistic", seed=5, steps=80)
    assert any(not np.array_equal(x[0].ego_pose, y[0].ego_pose) for x, y in zip(a, c, strict=False))


def test_exact_sensing_episodes_never_touch_the_sensing_path(paper_lot, monkeypatch):
    """With sensing.model exact an in-process episode observes with world.observe as before: no sensor, no tracker,
    no relabelling of its predictions (a bound method compared with `is` once relabelled every exact episode)."""
    import avp_episode.episodes as episodes
    from avp_episode.run_config import RunConfig, run_profile, sim_values

    def boom(*a, **k):
        raise AssertionError("the sensing path ran under exact sensing")

    monkeypatch.setattr(episodes, "relabel_predictions", boom, raising=False)
    import avp_episode.sensing as sensing

    monkeypatch.setattr(sensing, "relabel_predictions", boom)
    monkeypatch.setattr(sensing, "truth_ids", boom)
    cfg = RunConfig(t_final=3.0)
    sim = sim_values(cfg)
    rec = episodes.run_episode_inproc(paper_lot, sim, run_profile("oracle", cfg), 1, True, cfg)
    assert rec["steps"] > 0


def test_a_parked_car_is_given_a_held_pose_until_it_moves():
    """A parked car detected with 0.1 m noise: once stationary its given pose changes only when the estimate has
    left it by more than stationary_hold (a few times at most in 10 s, each time near the truth); when it drives
    off, the hold ends at once and the given pose follows the estimate again. stationary_hold 0: every step's
    estimate."""
    rng = np.random.default_rng(5)
    for hold in (0.1, 0.0):
        tr = Tracker(TrackerConfig(stationary_hold=hold))
        given = []
        for k in range(100):
            tr.update(_frame(k, [_det(3.0 + rng.normal(0, 0.1), 1.0 + rng.normal(0, 0.1), 0.5)]))
            (t,) = tr.tracks_given or (None,)
            if t is not None and k >= 30:
                given.append(tuple(t.history_array()[-1]))
                assert math.hypot(t.pose[0] - 3.0, t.pose[1] - 1.0) < 0.25
        if hold:
            assert len(set(given)) <= 5, len(set(given))
        else:
            assert len(set(given)) == len(given)
    tr = Tracker(TrackerConfig(stationary_hold=0.1))
    for k in range(40):
        tr.update(_frame(k, [_det(3.0, 1.0, 0.0)]))
    assert tr.tracks[0].held is not None
    moved = False
    for k in range(40, 60):
        x = 3.0 + 1.5 * DT * (k - 39)
        tr.update(_frame(k, [_det(x, 1.0, 0.0, speed=1.5)]))
        t = tr.tracks[0]
        moved |= t.held is None
        if t.held is None:
            assert np.array_equal(t.pose, t.x[:3])
    assert moved and tr.tracks[0].held is None and tr.tracks[0].pose[0] > 4.5


def test_spot_readings_are_filtered_by_their_evidence():
    """A vacant spot at the sensing region's edge misread once as occupied stays vacant; a spot that really turns
    occupied is followed within a few readings; near the ego one reading turns it in two steps; misread_far 0 passes
    every reading through."""
    from avp_tracking.core.spots import SpotFilter

    xy = np.array([[11.0, 0.0], [1.0, 0.0]])
    f = SpotFilter([7, 8], xy, misread_far=0.05, reach=11.5)
    for _ in range(20):
        vac, occ = f.update((0.0, 0.0), [7, 8], [])
    vac, occ = f.update((0.0, 0.0), [8], [7])  # one misread far away
    assert occ.tolist() == [] and vac.tolist() == [7, 8]
    turned = [f.update((0.0, 0.0), [8], [7])[1].tolist() for _ in range(4)]
    assert turned[-1] == [7] and turned[0] == []  # it takes more than one further reading, fewer than five
    near = [f.update((0.0, 0.0), [], [8])[1].tolist() for _ in range(2)]
    assert near == [[], [8]]
    raw = SpotFilter([7, 8], xy, misread_far=0.0, reach=11.5)
    vac, occ = raw.update((0.0, 0.0), [8], [7])
    assert vac.tolist() == [8] and occ.tolist() == [7]


def _hold_run(radius: float, ego_xy=(0.0, 4.0), rays=None, unseen=40, hold_max=10.0):
    """A car drives at 1 m/s for 2 s, 4 m from the ego, then is never seen again; the tracks given each unseen
    step."""
    tr = Tracker(TrackerConfig(max_coast=0.5, near_hold_radius=radius, near_hold_max=hold_max))
    for k in range(20):
        tr.update(_frame(k, [_det(0.1 * k - 1.0, 0.0, 0.0, 1.0, sigma=0.02)]))
    out = []
    for k in range(20, 20 + unseen):
        f = _frame(k)
        f = SensedFrame(**{**f.__dict__, "ego_pose": np.array([*ego_xy, 0.0])})
        if rays is not None:
            f = SensedFrame(**{**f.__dict__, "ray_angle_min": 0.0, "ray_angle_increment": 2 * math.pi / len(rays),
                               "ray_ranges": np.asarray(rays, np.float32)})
        out.append(tr.update(f))
    return out


def test_a_dropped_track_near_the_ego_is_kept_standing_with_near_hold():
    """Off (the default), the unseen car's track is dropped after max_coast (0.5 s); with near_hold_radius 6 m it is
    kept, standing (speed 0) where it was when dropped, for near_hold_max (2 s) more, then dropped; 10 m away it is
    dropped as without the hold."""
    off = _hold_run(0.0)
    assert len(off[4]) == 1 and off[6] == []
    held = _hold_run(6.0, hold_max=2.0)
    assert all(len(o) == 1 for o in held[:25])
    xs = [float(o[0].x[0]) for o in held[6:25]]
    assert max(xs) - min(xs) < 1e-9 and held[10][0].speed == 0.0
    assert held[6][0].id == held[0][0].id
    assert held[27] == [] and held[-1] == []
    far = _hold_run(6.0, ego_xy=(0.0, 10.0))
    assert far[6] == []


def test_a_held_track_goes_when_a_ray_passes_through_it():
    """With rays from the ego (at (0, 4)) that all reach 20 m, free space where the held track stands: it is
    dropped at max_coast as without the hold; rays that stop 1 m short of it (something there) keep it."""
    free = _hold_run(6.0, rays=np.full(360, 20.0))
    assert free[6] == []
    blocked = _hold_run(6.0, rays=np.full(360, 2.5))
    assert len(blocked[10]) == 1


def test_box_sigmas_grows_a_coasted_tracks_box_with_its_covariance(paper_lot):
    """A moving car's track as the ego's observation gives it: with box_sigmas 0 (the default) its box is the
    detections'; with 2, longer and wider by 4 position sigmas, and the more the longer it coasts unseen; a parked
    (stationary) car's box is never grown."""
    from avp_tracking.core.perceive import TrackingPerception

    def boxes(sigmas: float, speed: float):
        p = TrackingPerception(paper_lot, Tracker(TrackerConfig(max_coast=1.5, box_sigmas=sigmas)))
        out = []
        for k in range(40):
            dets = [_det(speed * DT * k, -30.0, 0.0, speed, sigma=0.1)] if k < 30 else []
            obs = p.observe(_frame(k, dets))
            out.append((obs.vehicles[0].length, obs.vehicles[0].width) if obs.vehicles else None)
        return out

    plain, grown = boxes(0.0, 2.0), boxes(2.0, 2.0)
    assert abs(plain[29][0] - 4.5) < 1e-6 and abs(plain[35][0] - 4.5) < 1e-6
    assert grown[29][0] > plain[29][0] + 0.1 and grown[29][1] > plain[29][1] + 0.1
    assert grown[35][0] > grown[29][0] + 0.2  # coasting: the covariance, and the box, grow
    parked = boxes(2.0, 0.0)
    assert abs(parked[29][0] - 4.5) < 1e-6


def test_pedestrian_velocity_filter_keeps_a_standing_pedestrian_still(paper_lot):
    """A standing pedestrian detected with 0.15 m noise: the velocity the ego reads from the two positions it is
    given (§V-C) is above the planner's still speed (0.3 m/s) in most steps with `difference` (each correction jump
    reads as motion), in few with `filter`; a pedestrian walking at 1 m/s reads about 1 m/s with either."""
    from avp_motion.planner_types import STILL_SPEED
    from avp_tracking.core.perceive import TrackingPerception
    from avp_world.detections import PedestrianDetection

    def speeds(mode: str, walk: float) -> np.ndarray:
        rng = np.random.default_rng(0)
        p = TrackingPerception(paper_lot, Tracker(TrackerConfig(pedestrian_velocity=mode)))
        out = []
        for k in range(300):
            xy = np.array([walk * DT * k, -30.0])
            det = PedestrianDetection(position=xy + rng.normal(0, 0.15, 2), radius=0.3,
                                      covariance=np.diag([0.15 ** 2, 0.15 ** 2]), existence=0.9)
            f = _frame(k)
            obs = p.observe(SensedFrame(**{**f.__dict__, "pedestrians": (det,)}))
            if k > 30:
                ped = obs.pedestrians[0]
                out.append(np.hypot(*(ped.position - ped.previous_position)) / DT)
        return np.array(out)

    assert (speeds("difference", 0.0) > STILL_SPEED).mean() > 0.5
    assert (speeds("filter", 0.0) > STILL_SPEED).mean() < 0.15
    for mode in ("difference", "filter"):
        assert abs(np.median(speeds(mode, 1.0)) - 1.0) < 0.25


def _car_history_run(smoothing: str, speed_at, steps: int = 120, sigma: float = 0.1, seed: int = 0):
    """A car along x with speed ``speed_at(k)``, detected every step with ``sigma`` noise; per step after 40, the
    history given to the ego and the true positions of its steps."""
    from avp_tracking.core.perceive import TrackingPerception
    from avp_world.lot import load_bundled_lot

    rng = np.random.default_rng(seed)
    p = TrackingPerception(load_bundled_lot(), Tracker(TrackerConfig(history_smoothing=smoothing)))
    x, truth, out = 0.0, [], []
    for k in range(steps):
        v = speed_at(k)
        x += v * DT
        truth.append(x)
        det = _det(x + rng.normal(0, sigma), -30.0 + rng.normal(0, sigma), 0.0, v + rng.normal(0, 0.26), sigma)
        obs = p.observe(_frame(k, [det]))
        if k >= 40:
            out.append((obs.vehicles[0].history, np.array(truth[-len(obs.vehicles[0].history):])))
    return out


def test_history_smoothing_rts_reads_a_steady_car_steady_and_a_braking_one_braking():
    """The speed read from a history's last two poses (as the planner reads it): a car at a steady 2 m/s reads as
    braking (0.3 m/s slower than 0.5 s before) in many steps without smoothing and in few with the RTS smoother, whose
    revised poses also lie nearer the truth; a car that really brakes (2 m/s to 0 at 2 m/s^2) still reads as braking
    while it does."""

    def braking_share(runs) -> float:
        reads = []
        for h, _ in runs:
            s = np.hypot(*(h[-1, :2] - h[-2, :2])) / DT
            before = np.hypot(*(h[-7, :2] - h[-8, :2])) / DT
            reads.append(s >= 0.3 and before - s > 0.3)
        return float(np.mean(reads))

    def error(runs) -> float:
        return float(np.sqrt(np.mean([np.mean((h[-10:-1, 0] - t[-10:-1]) ** 2) for h, t in runs])))

    plain, smooth = (_car_history_run(m, lambda k: 2.0, steps=240) for m in ("none", "rts"))
    assert braking_share(plain) > 0.12 and braking_share(smooth) < 0.08  # seeds 0-4: 0.16-0.25, 0-0.06
    assert error(smooth) < 0.85 * error(plain)  # the poses before the last (the last is the filter's own)
    brakes = _car_history_run("rts", lambda k: 2.0 if k < 60 else max(0.0, 2.0 - 0.2 * (k - 60)), steps=75)
    assert braking_share(brakes[22:30]) > 0.5  # steps 62-69: slowing from 1.6 to 0.2 m/s


def test_static_until_moved_keeps_a_newly_seen_parked_car_static_and_releases_a_leaving_one(paper_lot):
    """A parked car in spot 14 first detected with a noisy speed (1 m/s, then 0): without `static_until_moved` its
    young track is given as a moving car (the intent CNN would read it), with 1 m it is static from the start. A car
    that drives out of the spot at 1 m/s is given as moving once it has moved 1 m, and not before."""
    from avp_tracking.core.perceive import TrackingPerception

    spot = paper_lot.spot_poses[paper_lot.spot_index(14)]
    heading = np.array([math.cos(spot[2]), math.sin(spot[2])])

    def flags(until: float, drive: float) -> list[tuple[bool, float]]:
        p = TrackingPerception(paper_lot, Tracker(TrackerConfig(static_until_moved=until)))
        out = []
        for k in range(40):
            moved = max(0.0, drive * DT * (k - 10))  # a leaving car starts at step 10
            x, y = spot[:2] - heading * moved
            speed = (1.0 if k < 5 else 0.0) if drive == 0 else (-drive if k >= 10 else 0.0)
            obs = p.observe(_frame(k, [_det(x, y, spot[2], speed, sigma=0.05)]))
            if obs.vehicles:
                out.append((obs.vehicles[0].is_static, moved))
        return out

    paper_flags = flags(0.0, 0.0)
    assert not all(s for s, _ in paper_flags[:5])  # the noisy start reads as a mover
    assert all(s for s, _ in flags(1.0, 0.0))
    leaving = flags(1.0, 1.0)
    assert all(s for s, m in leaving if m < 0.8)
    assert any(not s for s, m in leaving if m > 1.3) and not leaving[-1][0]


def test_the_oracle_is_told_the_truth_in_the_frame_and_ids_of_what_it_sees(paper_lot):
    """Under noisy sensing the oracle's told futures are moved into the pose estimate's frame and named by the tracks
    that follow the agents (avp_episode.oracle.seen_through): each track's told future starts where the track is, an
    agent no track follows keeps a negative id, and the reacting set is named the same way."""
    from avp_episode.oracle import ground_truth, seen_through
    from avp_episode.run_config import RunConfig, sim_values
    from avp_episode.sensing import sensed_observer
    from avp_planner.scripted_driver import ScriptedDriver
    from avp_sim.core.factory import make_world

    p = sim_values(RunConfig(sim_overrides={"sensing.model": "realistic"}))
    world = make_world(paper_lot, p, 3, True)
    observe, driver = sensed_observer(world, p, 3), ScriptedDriver(paper_lot)
    matched = unmatched = 0
    for _ in range(60):
        obs = observe()
        truth = ground_truth(world, 4.0)
        seen = seen_through(truth, world, obs)
        assert len(seen.trajectories) == len(truth.trajectories) and seen.target_spots == truth.target_spots
        tracks = {v.id: v for v in obs.vehicles}
        for told, p_true in zip(seen.trajectories, truth.trajectories, strict=True):
            if told.agent_id in tracks:
                matched += 1
                first = np.asarray(p_true.poses[0][:2])  # a step on from the agent: within a metre of its track
                near = np.asarray(tracks[told.agent_id].history[-1][:2])
                assert np.hypot(*(told.poses[0][:2] - near)) < 1.5
                assert not np.allclose(told.poses[0][:2], first)  # moved into the estimate's frame
            else:
                unmatched += 1
                assert told.agent_id == -1 - p_true.agent_id
        assert {k for k in seen.reacting if not k[0]} <= {(False, i) for i in tracks} | {
            (False, -1 - i) for i in world.vehicle_ids}
        world.step(*driver.command(obs))
    assert matched >= 5 and unmatched > 0
