"""The learned predictor's data seen through noisy sensing and the tracker (avp_trajectory_training.data,
``sensing=``; the open-loop table of docs/results/sensing/README.md): a sample is a track, its future the car's.

The observer drives the same tour whatever it senses (its holds read the world, not the observation), so the world
and every car's future are the same with and without noise: a (step, car) sampled both ways must have the same
future and goal, and a different (tracked) history."""

from __future__ import annotations

import numpy as np
import pytest

from avp_trajectory_training.data import generate
from avp_trajectory_training.noisy_eval import table


@pytest.fixture(scope="module")
def both():
    return (generate("paper", 1, workers=1, progress=False),
            generate("paper", 1, workers=1, progress=False, sensing="realistic"))


def test_a_tracked_sample_has_the_future_of_the_car_its_track_follows(both):
    exact, noisy = both
    assert len(exact) > 5 and len(noisy) > 5
    assert noisy.history.shape[1:] == exact.history.shape[1:]  # a young track's history padded to the full t_hist
    at = {(int(s), int(v)): i for i, (s, v) in enumerate(zip(exact.step, exact.vehicle, strict=True))}
    pairs = [(at[(int(s), int(v))], j) for j, (s, v) in enumerate(zip(noisy.step, noisy.vehicle, strict=True))
             if (int(s), int(v)) in at]
    assert len(pairs) >= 0.5 * len(noisy)  # most tracks follow a car the exact observer samples at that step
    for i, j in pairs:
        np.testing.assert_array_equal(noisy.future[j], exact.future[i])
        np.testing.assert_array_equal(noisy.goal[j], exact.goal[i])
    moved = [np.abs(noisy.history[j][-1, :2] - exact.history[i][-1, :2]).max() for i, j in pairs]
    assert 0.0 < float(np.median(moved)) < 1.0  # the tracked pose: near the true one, never equal to it


def test_the_table_names_every_predictor_and_sensing_row():
    row = {"sensing": "realistic", "set": "paper", "episodes": 1, "group": "all", "n": 3,
           **{k: [1.0, 2.0] for k in ("oracle_learned", "oracle_bezier", "intent_learned", "intent_bezier", "cv")}}
    text = table([row, {**row, "sensing": "exact", "intent_bezier": None}])
    assert text.count("1.00 / 2.00") == 9 and "–" in text and "| realistic |" in text


def test_train_sensing_mixes_the_training_splits_and_keys_the_cache(both, tmp_path):
    """``--train-sensing exact,realistic``: the training and validation splits are the same episodes seen both ways,
    concatenated; the test sets stay exact; the cache is keyed by the presets, so exact-only data is not reused."""
    import argparse

    from avp_training.run import cached_split, sensing_list
    from avp_trajectory_training.data import TrajDataSpec, TrajSamples

    calls = []

    def generate_from_fixture(name, n, spec, workers=1, progress=False, sensing="exact"):
        calls.append((name, sensing))
        return both[0] if sensing == "exact" else both[1]

    args = argparse.Namespace(reuse_data=True, workers=1, quiet=True, train_sensing=sensing_list("exact,realistic"))
    spec, log = TrajDataSpec(), (lambda msg: None)
    s, _ = cached_split("t", "train", 1, spec, args, tmp_path, generate_from_fixture, TrajSamples.load, log)
    assert calls == [("train", "exact"), ("train", "realistic")]
    assert len(s) == len(both[0]) + len(both[1])
    np.testing.assert_array_equal(s.history[len(both[0]):], both[1].history)
    calls.clear()
    again, _ = cached_split("t", "train", 1, spec, args, tmp_path, generate_from_fixture, TrajSamples.load, log)
    assert calls == [] and len(again) == len(s)  # same presets: read back
    exact_only = argparse.Namespace(**{**vars(args), "train_sensing": sensing_list("exact")})
    cached_split("t", "train", 1, spec, exact_only, tmp_path, generate_from_fixture, TrajSamples.load, log)
    cached_split("t", "test", 1, spec, args, tmp_path, generate_from_fixture, TrajSamples.load, log)
    assert calls == [("train", "exact"), ("test", "exact")]
    with pytest.raises(argparse.ArgumentTypeError, match="foggy"):
        sensing_list("exact,foggy")
    assert sensing_list("realistic, exact,realistic") == ("realistic", "exact")
