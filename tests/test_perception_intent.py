"""Intent model of §V-A (``avp_predictors.intent_model``) with random weights (no training yet).

Oracles: hand arithmetic (layer sizes, parameter count, features, sigmoid-then-normalise), the plain torch
module (the fused and incremental inference paths must give its logits), and the probability axioms.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from avp_belief_map.belief import BeliefMap
from avp_belief_map.bev import BEVConfig
from avp_perception.core.pipeline import PerceptionCore
from avp_predictors.intent_model import (
    FEATURE_NAMES,
    N_FEATURES,
    PARKPREDICT_FEATURES,
    FusedIntentNet,
    IntentPredictor,
    SmallRegularizedCNN,
    conv_output_size,
    images_to_tensor,
    intent_features,
    load_cnn,
    max_pool_2x2,
    motion_features,
    receptive_field,
    sigmoid_normalise,
)
from avp_scenario.scenario import ScenarioParams, generate_paper_scenario
from avp_sim.core.world import World
from avp_world.lot import load_bundled_lot
from avp_world.types import Observation, ObservedVehicle

LOT = load_bundled_lot("paper_lot")


def snapshots(n_dynamic: int, seed: int = 0, steps=(0, 25, 30)):
    """World observations with the ego parked mid-lot (it then sees the dynamic vehicles)."""
    params = replace(ScenarioParams(), ego_start=(21.5, 20.0, -math.pi / 2), n_dynamic=(n_dynamic, n_dynamic))
    world = World(LOT, generate_paper_scenario(LOT, seed, True, params))
    out = []
    for k in range(max(steps) + 1):
        if k in steps:
            out.append(world.observe())
        world.step(0.0, 0.0)
    return out


def two_vehicle_obs():
    obs = snapshots(2, steps=(30,))[0]
    assert sum(not v.is_static for v in obs.vehicles) == 2
    return obs


def test_layer_sizes_match_parkpredict():
    # 400: 394 -> 197 -> 193 -> 96 -> 94 -> 47 (3 x 47^2 = 6627 as ParkPredict+); 100: 94-47-43-21-19-9
    assert conv_output_size(400) == 47 and conv_output_size(100) == 9 and conv_output_size(80) == 7
    assert receptive_field() == (30, 8)  # 7 + 1 -> 8 (x2) + 4*2 + 2 -> 18 (x4) + 2*4 + 4 -> 30, stride 8
    m = SmallRegularizedCNN(400, n_features=5)  # ParkPredict+'s five features
    n_params = sum(p.numel() for p in m.parameters())
    # conv 1184 + 1608 + 219, BN 16 + 16 + 6, fc1 6632*100 + 100, BN1d 200, fc2 101
    assert n_params == 666650
    assert m.fc[0].in_features == 6632
    with torch.no_grad():
        assert m.eval()(torch.zeros(2, 3, 400, 400), torch.zeros(2, 5)).shape == (2,)
    assert SmallRegularizedCNN(100).fc[0].in_features == 243 + N_FEATURES
    assert N_FEATURES == len(FEATURE_NAMES) == 12 and FEATURE_NAMES[:5] == PARKPREDICT_FEATURES
    with pytest.raises(ValueError):
        conv_output_size(20)


def test_sigmoid_then_normalise_not_softmax():
    p = sigmoid_normalise(np.array([0.0, math.log(3.0)]))  # sigmoids 0.5 and 0.75
    np.testing.assert_allclose(p, [0.4, 0.6])
    assert p.sum() == pytest.approx(1.0)
    q = sigmoid_normalise(np.array([-50.0, 3.0, 1.0, 0.0]))
    assert q.sum() == pytest.approx(1.0) and np.all(q >= 0)


def test_features_by_hand_and_entrance_distance_uses_true_position():
    f = intent_features(np.array([0.0, 0.0, 0.0]), 2.0, np.array([[3.0, 4.0], [-5.0, 0.0]]),
                        np.array([6.0, 8.0]), 0.5)
    # ParkPredict+'s five, the spot's side (sin, + left), then (no history) the speed in every window, no turn
    motion = [2, 2, 2, 2, 0, 0]  # ... and no slow roll seen
    np.testing.assert_allclose(f, [[0, 0, 2, 10, 0.5, 0, *motion], [0.6, 5, 2, 10, 0.5, 0.8, *motion],
                                   [-1, 5, 2, 10, 0.5, 0, *motion]], atol=1e-6)
    assert f.dtype == np.float32
    # heading north at (10, 20): spot due east is perpendicular; entrance distance from the true position
    g = intent_features(np.array([10.0, 20.0, math.pi / 2]), 0.0, np.array([[13.0, 20.0]]), LOT.entrance, 0.0)
    assert g[1, 0] == pytest.approx(0.0, abs=1e-6) and g[1, 1] == pytest.approx(3.0)
    assert g[0, 3] == pytest.approx(math.hypot(10.0 - 21.5, 20.0 - 41.5), rel=1e-6)


def test_motion_features_by_hand():
    """Mean speed per past 1 s window and the heading change over 2 s, from a history built by hand: 4 m/s for
    the first 2 s, then 1 m/s, turning left at 0.125 rad/s."""
    t = np.arange(41) * 0.1
    x = np.concatenate([[0.0], np.cumsum(np.where(t[1:] <= 2.0 + 1e-9, 4.0, 1.0) * 0.1)])
    hist = np.stack([x, np.zeros_like(t), 0.125 * t], axis=1)
    np.testing.assert_allclose(motion_features(hist, 0.1, 1.0), [1.0, 1.0, 4.0, 4.0, 0.25], atol=1e-9)
    # rotated and translated, the same motion gives the same features (they are frame-free)
    c, s = math.cos(2.0), math.sin(2.0)
    moved = np.column_stack([5 + c * hist[:, 0] - s * hist[:, 1], -3 + s * hist[:, 0] + c * hist[:, 1],
                             hist[:, 2] + 2.0])
    np.testing.assert_allclose(motion_features(moved, 0.1, 1.0), motion_features(hist, 0.1, 1.0), atol=1e-9)
    # heading change wraps through +-pi
    wrap = hist.copy()
    wrap[:, 2] = np.remainder(2 * math.pi - 0.3 + 0.125 * t, 2 * math.pi) - math.pi  # crosses +pi at t = 2.4 s
    assert motion_features(wrap, 0.1, 1.0)[-1] == pytest.approx(0.25)
    # 1 s of history: the older windows repeat the last one measured; one pose: the given speed everywhere
    np.testing.assert_allclose(motion_features(hist[-11:], 0.1, 1.0), [1, 1, 1, 1, 0.125], atol=1e-9)
    np.testing.assert_allclose(motion_features(hist[-1:], 0.1, 0.7), [0.7, 0.7, 0.7, 0.7, 0.0])
    # through intent_features: the same motion block in every row
    f = intent_features(hist[-1], 1.0, np.array([[20.0, 3.0]]), np.zeros(2), 0.1, hist, 0.1, 7.5)
    np.testing.assert_allclose(f[:, 6:], np.tile([1.0, 1.0, 4.0, 4.0, 0.25, 7.5], (2, 1)), atol=1e-6)


def test_max_pool_and_fused_net_are_the_same_function():
    x = torch.randn(3, 8, 23, 18)
    assert torch.equal(max_pool_2x2(x), torch.nn.functional.max_pool2d(x, 2))
    torch.manual_seed(1)
    m = SmallRegularizedCNN(100)
    # non-trivial batch-norm statistics so that folding them matters
    with torch.no_grad():
        for mod in m.modules():
            if isinstance(mod, torch.nn.BatchNorm2d | torch.nn.BatchNorm1d):
                mod.running_mean.uniform_(-0.5, 0.5)
                mod.running_var.uniform_(0.5, 2.0)
                mod.weight.uniform_(0.5, 1.5)
                mod.bias.uniform_(-0.2, 0.2)
    m.eval()
    imgs = torch.rand(4, 3, 100, 100)
    feats = torch.rand(4, N_FEATURES)
    with torch.no_grad():
        np.testing.assert_allclose(FusedIntentNet(m)(imgs, feats).numpy(), m(imgs, feats).numpy(), atol=1e-4)


@pytest.mark.parametrize("cfg", [BEVConfig(), BEVConfig(size_px=80, m_per_px=0.5)], ids=["100px", "80px"])
def test_incremental_and_fused_logits_equal_reference(cfg):
    obs = two_vehicle_obs()
    dyn = [v for v in obs.vehicles if not v.is_static]
    bm = BeliefMap.from_lot(LOT)
    bm.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    preds = {m: IntentPredictor(LOT, cfg, seed=3, mode=m) for m in ("reference", "fused", "incremental")}
    _, bevs = preds["reference"].predict_all(obs, dyn, bm, return_bevs=True)
    assert sum(len(b.candidate_spot_ids) for b in bevs) >= 4
    feats = [intent_features(b.pose, b.speed, LOT.spot_poses[b.candidate_idx, :2], LOT.entrance, 0.1) for b in bevs]
    ref = preds["reference"].logits(bevs, feats)
    assert ref.shape == (sum(1 + len(b.candidate_spot_ids) for b in bevs),)
    np.testing.assert_allclose(preds["fused"].logits(bevs, feats), ref, atol=1e-4)
    np.testing.assert_allclose(preds["incremental"].logits(bevs, feats), ref, atol=1e-4)
    # and the marking matters: candidates' logits are not all equal to the unmarked one
    assert np.ptp(ref[: 1 + len(bevs[0].candidate_spot_ids)]) > 1e-6


def test_incremental_logits_with_marks_outside_the_read_region():
    """A candidate marked only in the last rows / cols (beyond the 94 px the pooled stack reads) or at the image
    corner: incremental = reference (the implicit method met such a box on the ego's BEV, seed 156)."""
    from dataclasses import replace

    obs = two_vehicle_obs()
    dyn = [v for v in obs.vehicles if not v.is_static]
    bm = BeliefMap.from_lot(LOT)
    bm.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    preds = {m: IntentPredictor(LOT, BEVConfig(), seed=3, mode=m) for m in ("reference", "incremental")}
    _, bevs = preds["reference"].predict_all(obs, dyn, bm, return_bevs=True)
    b = bevs[0]
    img = b.image
    boxes = np.array([[49, 62, 94, 99], [95, 99, 10, 30], [0, 6, 0, 6], [90, 99, 88, 99]], dtype=np.int64)
    marks = []
    for r0, r1, c0, c1 in boxes:
        m = img.copy()
        m[r0:r1 + 1, c0:c1 + 1] = (200, 0, 200)
        marks.append(m)
    k = len(boxes)
    b = replace(b, candidate_boxes=boxes, candidate_images=np.stack(marks), candidate_spot_ids=np.arange(k),
                candidate_idx=np.arange(k))
    feats = [intent_features(b.pose, b.speed, LOT.spot_poses[b.candidate_idx, :2], LOT.entrance, 0.1)]
    ref = preds["reference"].logits([b], feats)
    np.testing.assert_allclose(preds["incremental"].logits([b], feats), ref, atol=1e-4)
    # marks no output reads change nothing: the same logits as the unmarked image with the same features
    unmarked = replace(b, candidate_images=np.stack([img] * k))
    same = preds["reference"].logits([unmarked], feats)
    assert np.allclose(ref[1:3], same[1:3], atol=1e-6) and np.abs(ref[3:] - same[3:]).max() > 1e-6
    # the case met in the sweep: every candidate of the batch marked outside the read region
    only = replace(b, candidate_boxes=boxes[:1], candidate_images=np.stack(marks[:1]), candidate_spot_ids=np.arange(1),
                   candidate_idx=np.arange(1))
    f1 = [intent_features(b.pose, b.speed, LOT.spot_poses[:1, :2], LOT.entrance, 0.1)]
    np.testing.assert_allclose(preds["incremental"].logits([only], f1), preds["reference"].logits([only], f1),
                               atol=1e-4)


def test_predict_gives_a_distribution_over_candidates_and_exploration():
    for obs in snapshots(1) + snapshots(2, seed=5):
        dyn = [v for v in obs.vehicles if not v.is_static]
        bm = BeliefMap.from_lot(LOT)
        bt = bm.observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
        pred = IntentPredictor(LOT, seed=0)
        for v in dyn:
            it = pred.predict(obs, v, bt)
            assert it.vehicle_id == v.id
            assert len(it.spot_ids) == len(it.spot_probabilities)
            assert set(it.spot_ids.tolist()) <= set(obs.vacant_spot_ids.tolist())  # b~ < beta only there
            total = it.spot_probabilities.sum() + it.none_probability
            assert total == pytest.approx(1.0, abs=1e-9)
            assert np.all(it.spot_probabilities > 0) and it.none_probability > 0
            if len(it.exploration_points):
                assert it.exploration_probabilities.sum() == pytest.approx(it.none_probability)
                assert len(it.exploration_points) <= 3
            # the same as a BeliefMap argument
            it2 = pred.predict(obs, v, bm)
            np.testing.assert_allclose(it2.spot_probabilities, it.spot_probabilities)


def test_seeded_random_weights_are_deterministic_and_do_not_touch_global_rng():
    obs = two_vehicle_obs()
    v = next(v for v in obs.vehicles if not v.is_static)
    bt = BeliefMap.from_lot(LOT).observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    torch.manual_seed(123)
    before = torch.rand(1)
    torch.manual_seed(123)
    a = IntentPredictor(LOT, seed=7).predict(obs, v, bt)
    assert torch.equal(torch.rand(1), before)
    b = IntentPredictor(LOT, seed=7).predict(obs, v, bt)
    c = IntentPredictor(LOT, seed=8).predict(obs, v, bt)
    np.testing.assert_array_equal(a.spot_probabilities, b.spot_probabilities)
    assert not np.allclose(a.spot_probabilities, c.spot_probabilities)


def test_time_in_lot_counts_from_first_history_pose():
    obs0, obs25, _ = snapshots(2)
    v0 = next(v for v in obs0.vehicles if not v.is_static)
    v25 = next(v for v in obs25.vehicles if v.id == v0.id)
    pred = IntentPredictor(LOT)
    span = (len(v0.history) - 1) * obs0.dt
    assert pred.time_in_lot(obs0, v0) == pytest.approx(span / 60.0)
    assert pred.time_in_lot(obs25, v25) == pytest.approx((span + 25 * obs0.dt) / 60.0)
    assert pred.time_in_lot(obs0, v0) == pytest.approx(span / 60.0)  # time went back: new episode


def test_roll_distance_remembers_the_slow_roll_beyond_the_history():
    """slow_roll_distance: on first sight read from the history (back to the last step at or above ROLL_SPEED),
    then grown by each observation's displacement while the car stays slow, 0 once it is fast again, and
    forgotten with the episode (time going back)."""
    dt = 0.1
    # 3 m/s for 2 s, then 1 m/s: a 41-pose (4 s) history ending 2 s into the slow roll (2.0 m rolled)
    speeds = np.where(np.arange(40) < 20, 3.0, 1.0)
    x = np.concatenate([[0.0], np.cumsum(speeds * dt)])

    def seen(step: int, xs: np.ndarray) -> tuple[Observation, ObservedVehicle]:
        hist = np.stack([xs, np.full_like(xs, 5.0), np.zeros_like(xs)], axis=1)
        v = ObservedVehicle(id=7, length=4.6, width=1.85, is_static=False, history=hist)
        obs = Observation(step=step, dt=dt, ego_pose=np.zeros(3), ego_length=4.6, ego_width=1.85, ego_speed=0.0,
                          vacant_spot_ids=np.zeros(0, np.int64), occupied_spot_ids=np.zeros(0, np.int64),
                          vehicles=(v,))
        return obs, v

    pred = IntentPredictor(LOT)
    assert pred.roll_distance(*seen(100, x)) == pytest.approx(2.0)
    assert pred.roll_distance(*seen(100, x)) == pytest.approx(2.0)  # same step: not counted twice
    # 5 s later, still at 1 m/s (the history no longer shows the slow-down): 2 + 5 m
    later = x[-1] + np.arange(-40, 1) * 0.1 + 5.0
    assert pred.roll_distance(*seen(150, later)) == pytest.approx(7.0)
    # fast again: 0
    fast = later[-1] + np.arange(-40, 1) * 0.3 + 3.0
    assert pred.roll_distance(*seen(160, fast)) == 0.0
    # a new episode (time went back), seen first at 3 m/s
    obs, v = seen(10, np.arange(41) * 0.3)
    pred.time_in_lot(obs, v)
    assert pred.roll_distance(obs, v) == 0.0
    # the feature rows carry it in the last column
    obs, v = seen(200, x)
    bt = BeliefMap.from_lot(LOT).observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    fresh = IntentPredictor(LOT)
    _, feats = fresh.inputs(obs, [v], bt)
    assert FEATURE_NAMES[-1] == "slow_roll_distance" and np.allclose(feats[0][:, -1], 2.0)


def test_weights_round_trip(tmp_path):
    obs = two_vehicle_obs()
    v = next(v for v in obs.vehicles if not v.is_static)
    bt = BeliefMap.from_lot(LOT).observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    a = IntentPredictor(LOT, seed=11)
    torch.save(a.model.state_dict(), tmp_path / "w.pt")
    b = IntentPredictor(LOT, seed=12)
    b.load_weights(tmp_path / "w.pt")
    np.testing.assert_allclose(b.predict(obs, v, bt).spot_probabilities, a.predict(obs, v, bt).spot_probabilities)


def test_images_to_tensor_layout():
    img = np.zeros((1, 4, 5, 3), dtype=np.uint8)
    img[0, 1, 2] = (255, 0, 51)  # row 1, col 2
    t = images_to_tensor(img)
    assert t.shape == (1, 3, 4, 5)
    assert t[0, 0, 1, 2] == 1.0 and t[0, 2, 1, 2] == pytest.approx(0.2) and t.sum() == pytest.approx(1.2)


def test_pipeline_step_applies_eq8_with_its_own_intentions():
    obs_list = snapshots(2, steps=tuple(range(0, 40, 3)))
    core = PerceptionCore(LOT, keep_bevs=True)
    prev = np.full(LOT.n_spots, 0.5)
    for obs in obs_list:
        out = core.step(obs)
        vac = np.array([LOT.spot_index(s) for s in obs.vacant_spot_ids], dtype=int)
        occ = np.array([LOT.spot_index(s) for s in obs.occupied_spot_ids], dtype=int)
        # eq. (7) oracle
        exp_tilde = prev.copy()
        exp_tilde[vac], exp_tilde[occ] = 0.0, 1.0
        np.testing.assert_array_equal(out.b_tilde, exp_tilde)
        # eq. (8) oracle from the returned intentions
        exp = exp_tilde.copy()
        for i in vac:
            sid = LOT.spot_ids[i]
            exp[i] = 1.0 - np.prod([1.0 - it.spot_probability(sid) for it in out.intentions])
        np.testing.assert_allclose(out.beliefs, exp, atol=1e-12)
        assert {it.vehicle_id for it in out.intentions} == {v.id for v in obs.vehicles if not v.is_static}
        assert len(out.bevs) == len(out.intentions)
        ids = {t.agent_id for t in out.trajectories}
        assert ids == {it.vehicle_id for it in out.intentions}
        prev = out.beliefs
    # the ego's trail is kept over t_hist
    assert core.ego_history(obs_list[-1]).shape[1] == 3


def test_vehicle_without_candidates_keeps_all_mass_on_none():
    obs = two_vehicle_obs()
    dyn = [v for v in obs.vehicles if not v.is_static]
    b = np.full(LOT.n_spots, 0.9)  # nothing believed vacant
    for mode in ("incremental", "reference"):
        its = IntentPredictor(LOT, mode=mode).predict_all(obs, dyn, b)
        for it in its:
            assert len(it.spot_ids) == 0 and it.none_probability == pytest.approx(1.0)
            assert it.exploration_probabilities.sum() == pytest.approx(1.0)
    assert IntentPredictor(LOT).predict_all(obs, [], b) == []


def test_the_head_lets_shared_features_change_the_ranking():
    """v_hat, d_ent and t_lot are the same in every option of a vehicle: with ParkPredict+'s affine head they add
    one constant to every logit and could never change which option ranks first (module docstring). With the
    head's LeakyReLU the gap between a spot and "none" must depend on the speed."""
    torch.manual_seed(3)
    model = SmallRegularizedCNN(100).eval()
    with torch.no_grad():
        for m in model.modules():  # non-trivial BatchNorm statistics, as after training
            if isinstance(m, torch.nn.BatchNorm1d):
                m.running_mean.uniform_(-1.0, 1.0)
                m.running_var.uniform_(0.5, 2.0)
    images = torch.rand(2, 3, 100, 100)
    gaps = []
    for speed in (0.5, 1.5, 3.0):
        f = torch.tensor([[0.0, 0.0, speed, 20.0, 0.3, 0.0, *[speed] * 4, 0.0, 0.0],
                          [0.9, 6.0, speed, 20.0, 0.3, 0.4, *[speed] * 4, 0.0, 0.0]])
        with torch.no_grad():
            z = model(images, f)
        gaps.append(float(z[1] - z[0]))
    assert max(gaps) - min(gaps) > 1e-3, gaps


def test_weights_carry_their_feature_count(tmp_path):
    """A state dict trained on ParkPredict+'s five features loads as a 5-feature model (it never reads the motion
    columns); one with all of FEATURE_NAMES as a 12-feature one; anything else is one error naming the file."""
    torch.manual_seed(0)
    images = torch.rand(3, 3, 100, 100)
    feats = torch.rand(3, N_FEATURES) * 4
    for n in (5, N_FEATURES):
        m = SmallRegularizedCNN(100, n_features=n).eval()
        torch.save(m.state_dict(), tmp_path / f"w{n}.pt")
        loaded = load_cnn(tmp_path / f"w{n}.pt")
        assert loaded.n_features == n
        pred = IntentPredictor(LOT)
        pred.load_weights(tmp_path / f"w{n}.pt")
        assert pred.model.n_features == n and pred.net.n_features == n
        changed = feats.clone()
        changed[:, 5:] += 1.0  # the side and motion columns
        with torch.no_grad():
            same = torch.allclose(loaded(images, feats), loaded(images, changed))
            np.testing.assert_allclose(pred.net(images, feats).numpy(), loaded(images, feats).numpy(), atol=1e-4)
        assert same == (n == 5)
    torch.save({"conv.0.0.weight": torch.zeros(1)}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="bad.pt"):
        load_cnn(tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="n_features"):
        SmallRegularizedCNN(100, n_features=N_FEATURES + 1)


def test_columns_the_network_does_not_read_are_skipped_not_changed(tmp_path):
    """A 5-feature network's inputs skip the history-based columns (no motion features, no roll tracking) but
    the five it reads are those an all-features network gets."""
    obs = two_vehicle_obs()
    dyn = [v for v in obs.vehicles if not v.is_static]
    bt = BeliefMap.from_lot(LOT).observe(obs.vacant_spot_ids, obs.occupied_spot_ids)
    full = IntentPredictor(LOT)  # all features
    five = IntentPredictor(LOT)
    torch.save(SmallRegularizedCNN(100, n_features=5).state_dict(), tmp_path / "w5.pt")
    five.load_weights(tmp_path / "w5.pt")
    _, f_full = full.inputs(obs, dyn, bt)
    _, f_five = five.inputs(obs, dyn, bt)
    for a, b in zip(f_full, f_five, strict=True):
        np.testing.assert_array_equal(a[:, :5], b[:, :5])
    assert all(np.all(b[:, 11] == 0.0) for b in f_five)  # slow_roll_distance: not tracked for this network


def test_weights_named_in_the_models_folder(tmp_path, monkeypatch):
    """``intent.weights`` takes a path or the name of a file in avp_predictors/models/: the name loads that file
    (here the shipped one, by name), a path wins over a models/ file of the same name, an unknown name is one error
    naming it."""
    from avp_perception.core.pipeline import make_intent_predictor
    from avp_predictors.intent_model import default_weights_path, weights_path

    shipped = default_weights_path()
    if not shipped.is_file():
        pytest.skip("no shipped weights")
    assert weights_path(shipped.name) == shipped and weights_path("") == shipped
    pred, info = make_intent_predictor(LOT, weights=shipped.name)
    assert str(shipped) in info
    ref = IntentPredictor.pretrained(LOT).model.state_dict()
    assert all(torch.equal(a, ref[k]) for k, a in pred.model.state_dict().items())
    torch.save(IntentPredictor(LOT, seed=3).model.state_dict(), tmp_path / shipped.name)
    monkeypatch.chdir(tmp_path)
    assert weights_path(shipped.name) == Path(shipped.name)  # the local file, not the package's
    with pytest.raises(FileNotFoundError, match="no_such_model.pt"):
        IntentPredictor.pretrained(LOT, path="no_such_model.pt")


def test_the_tracked_intent_model_ships_as_an_option():
    """``intent.weights: intent_cnn_tracked.pt`` names the intent CNN trained on tracked histories too
    (docs/results/sensing/README.md): loaded from the package's models/, other weights than the shipped ones; its card
    records the sensing of its training episodes and its exact held-out top-1 (below the shipped model's, hence an
    option)."""
    import json

    from avp_perception.core.pipeline import make_intent_predictor
    from avp_predictors.intent_model import default_weights_path

    name = "intent_cnn_tracked.pt"
    models = default_weights_path().parent
    card = json.loads((models / name).with_suffix(".json").read_text())
    shipped_card = json.loads(default_weights_path().with_suffix(".json").read_text())
    assert card["train_sensing"] == ["exact", "realistic"]
    assert card["metrics"]["test"]["n"] == shipped_card["metrics"]["test"]["n"]
    assert card["metrics"]["test"]["top1"] < shipped_card["metrics"]["test"]["top1"]
    tracked, info = make_intent_predictor(LOT, weights=name)
    assert name in info
    ref = IntentPredictor.pretrained(LOT).model.state_dict()
    assert any(not torch.equal(a, ref[k]) for k, a in tracked.model.state_dict().items())
