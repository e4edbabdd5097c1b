"""Training of the intent CNN (``avp_training``): lots, traffic, samples, loss, weights.

Oracles: the reference sheet's DLP map facts typed in by hand, the World's own eq. (1) replay and spot
classification (§III-A) for where the traffic cars end, geometry computed here from the lot (distances and
cosines of the features), a loss computed by hand, and the nearest-spot baseline for the shipped weights.
"""

from __future__ import annotations

import functools
import json
import math
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
import torch

from avp_predictors.intent_model import N_FEATURES, IntentPredictor, default_weights_path
from avp_sensing.observation import classify_world
from avp_traffic.lanes import Path, follow
from avp_traffic.traffic import PARK, WANDER, TrafficGenerator, TrafficParams
from avp_training.dataset import (
    DataSpec,
    Samples,
    generate_split,
    label_index,
    paper_episode,
    traffic_episode,
)
from avp_training.lots import load_dlp_lot, random_lot
from avp_training.train import (
    TrainConfig,
    baseline_scores,
    build_model,
    evaluate,
    grouped_loss,
    make_batch,
    topk_hits,
)
from avp_world.geometry import polygon_contains_points, rect_corners, rects_overlap
from avp_world.kinematics import rollout_vehicle
from avp_world.lot import load_bundled_lot
from avp_world.lot_scenario import spot_aisles

SHORT = DataSpec(t_final=20.0)
EPISODE_SEED = 10  # a short episode with samples (31 of them labelled with a spot) on a random lot


@functools.cache
def episode(seed: int) -> Samples:
    """Samples of one short training-distribution episode (cached: several tests read the same one)."""
    return traffic_episode(seed, SHORT)

# shipped weights vs the nearest-spot-ahead baseline on freshly generated held-out episodes (seeds that neither
# training, validation nor the model card's test sets use): required top-1 margin
MARGIN = 0.15


# ------------------------------------------------------------------------------------------------ lots


def test_dlp_lot_follows_the_reference_sheet():
    lot = load_dlp_lot()
    assert lot.n_spots == 21 + 4 * 25 * 2 - 25  # A (21 of 42) + B, D, F (2 x 25) + H (25)
    widths = np.round(lot.spot_dims[:, 1], 3)
    depths = np.round(lot.spot_dims[:, 0], 3)
    # sheet §3.4: A 2.616 x 5.22; B/D/F/H 2.753 wide, 5.50 / 5.655 / 5.585 / 5.53 deep
    assert sorted(set(widths.tolist())) == [2.616, 2.753]
    assert sorted(set(depths.tolist())) == [5.22, 5.5, 5.53, 5.585, 5.655]
    assert (widths == 2.616).sum() == 21 and (depths == 5.655).sum() == 50
    # aisles between the rows: 7.11, 7.16, 7.25, 7.03 m; every spot borders one, at the gap between its rows
    aisle = spot_aisles(lot)
    assert (aisle >= 0).all()
    gaps = {64.955: 7.11, 46.82: 7.16, 28.305: 7.25, 9.995: 7.03}
    for k, j in enumerate(aisle):
        road = lot.roads[j]
        assert road.start[1] == road.end[1] and road.width == gaps[road.start[1]]
        # the spot faces away from its aisle and touches it
        dy = lot.spot_poses[k, 1] - road.start[1]
        assert math.copysign(1.0, dy) == round(math.sin(lot.spot_poses[k, 2]))
        assert abs(abs(dy) - (road.width / 2 + lot.spot_dims[k, 0] / 2)) < 1e-6


def test_random_lots_are_valid_seeded_and_varied():
    seen = set()
    for seed in range(25):
        lot = random_lot(seed)
        again = random_lot(seed)
        np.testing.assert_array_equal(lot.spot_poses, again.spot_poses)
        aisle = spot_aisles(lot)
        assert (aisle >= 0).all(), seed
        for k, j in enumerate(aisle):  # the spot centre lies on the far side of its road, facing away from it
            r = lot.roads[j]
            a, b = np.array(r.start), np.array(r.end)
            d = (b - a) / np.hypot(*(b - a))
            rel = lot.spot_poses[k, :2] - a
            away = rel - (rel @ d) * d
            heading = np.array([math.cos(lot.spot_poses[k, 2]), math.sin(lot.spot_poses[k, 2])])
            assert away @ heading > 0
        seen.add((lot.n_spots, len(lot.roads), round(float(lot.spot_dims[0, 1]), 2)))
    assert len(seen) > 10


# ----------------------------------------------------------------------------------------- tracking


def test_tracker_drives_the_path_and_stops_at_its_end():
    path = Path.build((1.0, 2.0, 0.3), [(6.0, 0.0, 3.0), (math.pi / 2 * 3.6, -1 / 3.6, 2.0), (10.0, 0.0, 3.0),
                                        (math.pi / 3 * 5.0, 1 / 5.0, 2.5), (4.0, 0.0, 3.0)])
    u, x = follow(path, np.array([1.0, 2.0, 0.3]), 0.1)
    np.testing.assert_allclose(x, rollout_vehicle(np.array([1.0, 2.0, 0.3]), u, 0.1), atol=1e-9)  # eq. (1)
    hint, worst = 0, 0.0
    for p in x:
        hint, _, lat = path.project(p[0], p[1], hint)
        worst = max(worst, abs(lat))
    assert worst < 0.02
    end = path.end_pose()
    assert math.hypot(x[-1, 0] - end[0], x[-1, 1] - end[1]) < 0.01
    assert abs(math.remainder(x[-1, 2] - end[2], 2 * math.pi)) < math.radians(1.0)
    assert u[-1, 0] == 0.0 and (np.abs(u[:, 0]) <= 3.0 + 1e-9).all()
    assert (np.abs(u[:, 1]) <= np.abs(u[:, 0]) / 3.2176 + 1e-9).all()  # |omega| <= |v| / R_min


# ------------------------------------------------------------------------------------------ traffic


def test_traffic_cars_end_in_their_labelled_spots_without_colliding():
    lot = random_lot(3)
    gen = TrafficGenerator(lot)
    tr = gen.generate(5)
    again = gen.generate(5)
    assert tr.labels == again.labels
    for a, b in zip(tr.scenario.vehicles, again.scenario.vehicles, strict=True):
        np.testing.assert_array_equal(a.controls, b.controls)
    assert sum(k == PARK for k in tr.kinds.values()) >= 3
    # replay every plan with the World's kinematics (eq. (1), avp_world.kinematics), to its end
    agents = [v for v in tr.scenario.vehicles if v.id in tr.labels]
    n = max(len(v.controls) for v in agents)
    u = np.zeros((n, len(agents), 2))
    for j, v in enumerate(agents):
        u[:len(v.controls), j] = v.controls
    states = rollout_vehicle(np.array([v.initial_state for v in agents]), u, tr.scenario.dt)  # (n + 1, A, 3)
    ii, jj = np.triu_indices(len(agents), 1)
    for k in range(0, n + 1, 2):
        corners = rect_corners(states[k], 4.6, 1.85)
        inside = polygon_contains_points(lot.boundary, states[k, :, :2])  # outside, cars wait / leave unseen
        both = inside[ii] & inside[jj]
        assert not rects_overlap(corners[ii[both]], corners[jj[both]]).any(), k
    _, vehicle_spot = classify_world(lot, rect_corners(states[-1], 4.6, 1.85))  # V ⊆ S (§III-A)
    finished = 0
    for j, v in enumerate(agents):
        moving = np.nonzero(np.abs(u[:, j]).max(axis=1) > 0)[0]
        done = len(moving) and moving[-1] < n - 10  # the plan ended before the episode did
        finished += bool(done)
        if tr.kinds[v.id] == PARK:
            assert tr.labels[v.id] >= 0
            if done:
                assert lot.spot_ids[vehicle_spot[j]] == tr.labels[v.id]
        else:
            assert tr.labels[v.id] == -1 and vehicle_spot[j] == -1
            if done:
                assert not polygon_contains_points(lot.boundary, states[-1, j, :2])  # it left the lot
    assert finished >= 3


def test_goal_directed_parkers_take_the_shortest_route_prefer_near_spots_and_slow_down():
    """ParkSim's task-based drivers (reference sheet §3.3): the spot is chosen at the entrance, the car drives the
    shortest lane route to it at cruise speed and rolls the last metres slowly; with p_explore = 0 nobody
    wanders. Oracles: the lane graph's own Dijkstra lengths and speeds measured from the states."""
    lot = load_dlp_lot()
    params = TrafficParams(p_explore=0.0, preference_length=(8.0, 8.0))
    gen = TrafficGenerator(lot, params)
    n = lot.n_spots
    rng = np.random.default_rng(7)
    excess, uniform_excess = [], []
    for _ in range(12):
        free_from = np.where(rng.random(n) < 0.7, np.inf, -np.inf)
        for _ in range(params.tries):  # as generate(): a draw whose maneuvers do not fit is tried again
            plan = gen._parker(rng, 0, free_from, np.zeros(n, dtype=bool))
            if plan is not None:
                break
        assert plan is not None and plan.kind == PARK and free_from[plan.spot_row] < 0  # a free spot
        # route length to the chosen spot vs the nearest free spot (by the lane graph's Dijkstra)
        d = {row: min(gen.entry_dist[lane] + t for lane, t, _ in items if lane in gen.entry_dist)
             for row, items in gen.spot_lanes.items() if free_from[row] < 0}
        excess.append(d[plan.spot_row] - min(d.values()))
        uniform_excess.append(np.mean(list(d.values())) - min(d.values()))  # a spot drawn uniformly
        # speeds along the drive: up to cruise speed, then at most slow_speed over the last slow_distance
        x = plan.states[:plan.drive_end + 1]
        v = np.hypot(*np.diff(x[:, :2], axis=0).T) / params.dt
        s_left = np.cumsum(v[::-1] * params.dt)[::-1]  # distance still to drive from each step
        assert v.max() >= params.approach_speed - 1e-6
        assert (v[s_left < params.slow_distance[0] - 0.5] <= params.slow_speed[1] + 0.05).all()
        assert v[-1] < 0.2  # stopped at the maneuver's start
    # L = 8 m: a spot 8 m further along the route is e times less likely: far nearer than a uniform choice
    assert np.mean(excess) < 0.3 * np.mean(uniform_excess), (excess, uniform_excess)
    tr = gen.generate(3)
    assert tr.stats[WANDER] == 0 and tr.stats[PARK] >= 3


# ------------------------------------------------------------------------------------------ samples


def test_samples_labels_candidates_and_features_are_consistent():
    s = episode(EPISODE_SEED)
    assert len(s) > 20
    lot = random_lot(EPISODE_SEED) if s.lot[0] == 1 else load_dlp_lot()
    centres = {int(i): lot.spot_poses[k, :2] for k, i in enumerate(lot.spot_ids)}
    for i in range(len(s)):
        c0, c1 = int(s.cand_offsets[i]), int(s.cand_offsets[i + 1])
        ids = s.candidate_spot_ids[c0:c1]
        y, target = int(s.labels[i]), int(s.target_spot[i])
        assert c1 > c0  # instances with no candidate are not samples
        assert y == label_index(ids, target)
        if y > 0:
            assert ids[y - 1] == target
        else:
            assert target not in ids.tolist()
        f = s.features[s.feature_rows(i)]
        assert f.shape == (c1 - c0 + 1, N_FEATURES) and (f[0, :2] == 0).all() and f[0, 5] == 0
        assert (f[:, 6:] == f[0, 6:]).all()  # the motion block is the vehicle's, the same in every row
        # distance / cosine to each candidate from the stored pose and the lot map (not the renderer)
        pose = s.pose[i]
        d = np.array([centres[int(j)] for j in ids]) - pose[:2]
        np.testing.assert_allclose(f[1:, 1], np.hypot(d[:, 0], d[:, 1]), rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(f[1:, 0], d @ [math.cos(pose[2]), math.sin(pose[2])] / np.hypot(d[:, 0], d[:, 1]),
                                   atol=1e-5)
        np.testing.assert_allclose(f[1:, 5], d @ [-math.sin(pose[2]), math.cos(pose[2])] / np.hypot(d[:, 0], d[:, 1]),
                                   atol=1e-5)
        # marked images differ from I_k,0 only inside their boxes, and there they contain the purple mark
        marked = s.candidate_images(i)
        for j, img in enumerate(marked):
            r0, r1, q0, q1 = s.candidate_boxes[c0 + j]
            diff = np.any(img != s.images[i], axis=2)
            assert diff.any() and not diff[:r0].any() and not diff[r1 + 1:].any()
            assert not diff[:, :q0].any() and not diff[:, q1 + 1:].any()
            assert (img[diff] == (128, 0, 128)).all()


def test_datasets_are_deterministic_by_seed():
    a, b = episode(EPISODE_SEED), traffic_episode(EPISODE_SEED, SHORT)
    c = episode(14)
    for name in ("images", "labels", "features", "patch_data", "candidate_spot_ids", "pose"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert len(a) != len(c) or not np.array_equal(a.features, c.features)
    p, q = paper_episode(3_000_001, SHORT), paper_episode(3_000_001, SHORT)
    np.testing.assert_array_equal(p.images, q.images)
    np.testing.assert_array_equal(p.labels, q.labels)


def test_samples_roundtrip_subset_and_concat(tmp_path):
    s = episode(EPISODE_SEED)
    s.save(tmp_path / "s.npz")
    t = Samples.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(s.patch_data, t.patch_data)
    idx = np.array([3, 0, len(s) - 1])
    sub = s.subset(idx)
    for j, i in enumerate(idx):
        np.testing.assert_array_equal(sub.candidate_images(j), s.candidate_images(int(i)))
        np.testing.assert_array_equal(sub.features[sub.feature_rows(j)], s.features[s.feature_rows(int(i))])
    both = Samples.concat([sub, sub])
    np.testing.assert_array_equal(both.candidate_images(4), s.candidate_images(0))


# ----------------------------------------------------------------------------------------- training


def test_grouped_loss_by_hand():
    def sig(v):
        return 1.0 / (1.0 + math.exp(-v))

    z = torch.tensor([0.0, 1.0, -1.0, 2.0, 0.5])
    spans, w, tg = [(0, 3), (3, 5)], [np.array([1.0, 1.0, 2.0]), np.array([1.0, 1.0])], [1, 0]
    by_hand = (-math.log(sig(1.0)) + math.log(sig(0.0) + sig(1.0) + 2 * sig(-1.0))
               - math.log(sig(2.0)) + math.log(sig(2.0) + sig(0.5))) / 2
    assert float(grouped_loss(z, spans, w, tg)) == pytest.approx(by_hand, rel=1e-6)


@pytest.mark.slow
def test_a_few_training_steps_reduce_the_loss():
    s = episode(EPISODE_SEED)
    assert len(s) >= 20
    cfg = replace(TrainConfig(), threads=1, max_candidates=6)
    torch.set_num_threads(1)
    model = build_model(cfg)
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    idx = np.arange(4)  # 31 candidate images: the loss falls to 0.31 of its start in 30 steps (3 s on one core)
    x, f, spans, w, tg = make_batch(s, idx, None, 10**6)

    def loss_eval() -> float:
        model.eval()
        with torch.no_grad():
            return float(grouped_loss(model(x, f), spans, w, tg))

    before = loss_eval()
    model.train()
    for _ in range(30):  # (batch-norm running statistics need a few dozen steps to follow the weights)
        opt.zero_grad()
        grouped_loss(model(x, f), spans, w, tg).backward()
        opt.step()
    assert loss_eval() < 0.8 * before


# ---------------------------------------------------------------------------------- shipped weights


# Until `avp train-intent` has produced avp_predictors/models/intent_cnn.pt, the two tests of the
# shipped weights cannot run; they run as soon as the file exists.
_NO_WEIGHTS = pytest.mark.skipif(not default_weights_path().is_file(), reason="no shipped intent weights yet")


@pytest.mark.slow
@_NO_WEIGHTS
def test_shipped_weights_beat_the_nearest_spot_baseline_on_fresh_held_out_episodes():
    path = default_weights_path()
    assert path.is_file(), "run `avp train-intent` to make the shipped weights"
    assert path.stat().st_size <= 10 * 2**20
    card = json.loads(path.with_suffix(".json").read_text())
    assert card["metrics"]["test"]["top1"] > card["metrics"]["test"]["nearest_ahead"]["top1"]
    pred = IntentPredictor.pretrained(load_bundled_lot())
    fresh = generate_split("test", 0, DataSpec(), seeds=range(2_500_000, 2_500_006), progress=False)
    assert len(fresh) > 200
    torch.set_num_threads(1)
    result = evaluate(pred.model, fresh, with_baselines=True)
    assert result["top1"] >= result["nearest_ahead"]["top1"] + MARGIN, result
    assert result["top1"] >= result["nearest"]["top1"] + MARGIN, result
    # the shipped weights give the same logits through every inference path
    sample = fresh.subset(np.arange(5))
    z = [evaluate_logits(pred, sample, mode) for mode in ("incremental", "reference")]
    np.testing.assert_allclose(z[0], z[1], atol=1e-4)


def evaluate_logits(pred: IntentPredictor, s: Samples, mode: str) -> np.ndarray:
    from avp_training.train import vehicle_bevs

    other = IntentPredictor(None, pred.bev_config, model=pred.model, mode=mode)
    return other.logits(vehicle_bevs(s, range(len(s))), [s.features[s.feature_rows(i)] for i in range(len(s))])


def test_nearest_spot_baseline_by_hand():
    # three candidates: ahead at 8 m, ahead at 5 m, behind at 2 m; label = the 5 m one (option 2)
    s = episode(EPISODE_SEED).subset(np.array([0]))
    s = replace(s, cand_offsets=np.array([0, 3]),
                features=np.pad(np.array([[0, 0, 1, 10, 0], [0.9, 8, 1, 10, 0], [0.5, 5, 1, 10, 0],
                                          [-0.7, 2, 1, 10, 0]], np.float32), ((0, 0), (0, N_FEATURES - 5))),
                labels=np.array([2]))
    ahead, nearest = baseline_scores(s, True)[0], baseline_scores(s, False)[0]
    assert np.argmax(ahead) == 2 and np.argmax(nearest) == 3
    assert list(np.argsort(-ahead, kind="stable")) == [2, 1, 0, 3]  # ahead by distance, none, behind
    assert topk_hits([ahead], s.labels, 1)[0] and not topk_hits([nearest], s.labels, 1)[0]


def test_training_never_sees_test_or_paper_episodes():
    from avp_training.dataset import episode_seeds

    train, val, test, paper = (set(episode_seeds(k, 5000)) for k in ("train", "val", "test", "paper"))
    assert not (train & val) and not (train & test) and not (val & test) and not (paper & (train | val | test))
    assert 2_500_000 not in test  # the fresh held-out seeds of the weights test lie beyond every split's range
    # the paper's lot is never a training lot
    assert all(traffic_episode_lot(seed) != "paper_lot" for seed in range(50))


def traffic_episode_lot(seed: int) -> str:
    rng = np.random.default_rng([int(seed), 7])
    return "dlp_west" if rng.random() < DataSpec().p_dlp else random_lot(seed).name


@_NO_WEIGHTS
def test_shipped_card_records_data_command_and_accuracy():
    card = json.loads(default_weights_path().with_suffix(".json").read_text())
    for key in ("data", "command", "commit", "metrics", "timings_s", "train_config", "parameters"):
        assert key in card
    assert card["parameters"] == sum(p.numel() for p in build_model(TrainConfig()).parameters())
    assert card["metrics"]["paper"]["n"] > 0 and card["data"]["train"]["samples"] > 1000


def test_error_analysis_by_distance_counts_every_spot_sample():
    """``python -m avp_training.analysis``: the distance bins partition the label-is-spot samples, the
    per-bin hits add up to the overall figures, and the hybrid rule with X = 0 would be the CNN itself."""
    from avp_training.analysis import BINS, error_table
    from avp_training.train import model_logits, topk_hits

    s = episode(EPISODE_SEED)
    torch.set_num_threads(1)
    logits = model_logits(IntentPredictor.pretrained(load_bundled_lot()).model, s)
    t = error_table(s, logits)
    spot = s.labels > 0
    assert spot.any() and sum(r["n"] for r in t["by_distance"]) == int(spot.sum())
    hits = topk_hits(logits, s.labels, 1)
    assert sum(r["cnn"] * r["n"] for r in t["by_distance"]) == pytest.approx(hits[spot].sum())
    assert t["top1"] == pytest.approx(hits.mean()) and [r["from_m"] for r in t["by_distance"]] == sorted(
        r["from_m"] for r in t["by_distance"]) and t["by_distance"][0]["from_m"] >= BINS[0][0]
    assert set(t["hybrid"]) == {2.0, 3.0, 4.0, 5.0, 6.0, 8.0} and all(0.0 <= v <= 1.0 for v in t["hybrid"].values())
    # error budget: the label groups and the speed groups each partition the samples and count the misses
    budget = {r["group"]: r for r in t["error_budget"]}
    misses = int((~hits).sum())
    label_groups = ["label none"] + [g for g in budget if g.startswith("label a spot") and " m away" in g]
    speed_groups = [g for g in budget if "m/s" in g or g.endswith("faster")]
    for names in (label_groups, speed_groups):
        assert sum(budget[g]["n"] for g in names) == len(s) and sum(budget[g]["errors"] for g in names) == misses
    for r in budget.values():
        assert r["top1_if_fixed"] == pytest.approx(t["top1"] + r["errors"] / len(s))


def test_oracle_explains_every_goal_directed_car():
    """``python -m avp_training.oracle``: regenerated from its seed, the episode gives back the plans
    behind the samples; for every goal-directed parker still driving, the observer that knows the driver model
    gives the spot the car really takes a non-zero posterior (its route, roll and stop rules agree with the
    generator), the posteriors are distributions, and the table's groups partition the samples."""
    from avp_training.oracle import GROUPS, OracleEpisode, oracle_table

    seen = Counter()
    for seed in (EPISODE_SEED, 12):
        s = episode(seed)
        ep = OracleEpisode(seed, SHORT)
        for i in range(len(s)):
            plan = ep.plans.get(int(s.vehicle[i]))
            assert plan is not None and plan.kind == {0: "park", 1: "leave", 2: "wander"}[int(s.kind[i])]
            if not plan.goal_options:
                continue
            name, post = ep.posterior(plan, s.pose[i, :2])
            seen[name] += 1
            if name in ("cruising", "rolling"):
                assert sum(post.values()) == pytest.approx(1.0)
                assert post.get(int(s.target_spot[i]), 0.0) > 0.0, (seed, i, name)
    assert seen["cruising"] > 10 and seen["rolling"] > 10 and seen["maneuvering"] > 0
    s = episode(EPISODE_SEED)
    hits = np.zeros(len(s), dtype=bool)
    t = oracle_table(s, hits, SHORT)
    assert set(t["groups"]) == set(GROUPS) and sum(r["n"] for r in t["groups"].values()) == len(s)
    assert t["groups"]["maneuvering"]["oracle"] in (None, 1.0) and t["cnn_top1"] == 0.0
