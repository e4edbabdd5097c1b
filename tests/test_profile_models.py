"""A method profile that names its own models (``perception.intent_weights``, a ``prediction:`` block): the sensing
suite's rows `bezier_intent_tracked` and `learned_tracked` run the models trained on tracked histories this way
(docs/results/sensing/README.md). The profile is read, checked, applied in process and in the node graph alike, and
folds the weights into the results folder's identity; the shipped profiles keep theirs."""

from __future__ import annotations

from pathlib import Path

import pytest

from avp_episode.profiles import ProfileError, load_profile, method_node_params, profile_from_dict

ROOT = Path(__file__).resolve().parents[1]
METHODS = ROOT / "src/avp_experiment/config/suites/methods"


def _profile(**extra) -> dict:
    data = {"name": "x", "available": True, "perception": {"beliefs": "intent", "predictor": "learned",
                                                           "ego_intent": False}}
    for k, v in extra.items():
        if k == "intent_weights":
            data["perception"]["intent_weights"] = v
        else:
            data[k] = v
    return data


def test_a_profile_names_prediction_parameters_and_intent_weights_checked_by_field():
    p = profile_from_dict(_profile(prediction={"learned": {"weights": "t.pt"}, "mu": 0.4}, intent_weights="i.pt"),
                          "f.yaml")
    assert p.prediction == {"learned.weights": "t.pt", "mu": 0.4} and p.intent_weights == "i.pt"
    with pytest.raises(ProfileError, match=r"f.yaml: field 'prediction.method': not an avp_prediction parameter"):
        profile_from_dict(_profile(prediction={"method": "bezier"}), "f.yaml")  # that is perception.predictor
    with pytest.raises(ProfileError, match=r"f.yaml: field 'prediction.nope'"):
        profile_from_dict(_profile(prediction={"nope": 1}), "f.yaml")
    with pytest.raises(ProfileError, match=r"field 'perception.intent_weights': expected str"):
        profile_from_dict(_profile(intent_weights=3), "f.yaml")
    assert load_profile("learned").prediction == {} and load_profile("bezier").intent_weights == ""


def test_the_suites_profiles_load_the_tracked_models_in_process_and_in_the_graph():
    from avp_episode.ego import MethodEgo
    from avp_world.lot import load_bundled_lot

    lot = load_bundled_lot()
    intent = load_profile(METHODS / "bezier_intent_tracked.yaml")
    learned = load_profile(METHODS / "learned_tracked.yaml")
    assert "intent_cnn_tracked.pt" in MethodEgo(lot, intent).intent_info
    ego = MethodEgo(lot, learned, intent_weights="")
    assert "intent_cnn.pt (shipped)" in ego.intent_info  # the run's intent weights: only the predictor's change
    assert ego.predictor.config.learned.weights == "trajectory_transformer_tracked.pt"
    # the node graph: the same models through the nodes' parameters; the method's own weights over the run's
    assert method_node_params(intent, intent_weights="other.pt")["avp_belief"]["intent.weights"] == \
        "intent_cnn_tracked.pt"
    assert method_node_params(learned)["avp_prediction"] == {"method": "learned",
                                                             "learned.weights": "trajectory_transformer_tracked.pt"}
    assert "intent.weights" not in method_node_params(learned)["avp_belief"]


def test_the_weights_a_profile_names_are_part_of_its_digest_and_the_shipped_digests_stand():
    import hashlib

    from avp_experiment.results import profile_digest
    from avp_predictors.learned_prediction import default_weights_path

    learned = load_profile("learned")  # as before profiles named weights: its file and the shipped weights
    h = hashlib.sha256(Path(learned.source).read_bytes())
    h.update(default_weights_path().read_bytes())
    assert profile_digest(learned) == h.hexdigest()[:16]
    bezier = load_profile("bezier")
    assert profile_digest(bezier) == hashlib.sha256(Path(bezier.source).read_bytes()).hexdigest()[:16]
    tracked = load_profile(METHODS / "learned_tracked.yaml")
    assert profile_digest(tracked) != profile_digest(load_profile("learned"))
    other = profile_from_dict(_profile(intent_weights="no_such_weights.pt"), str(METHODS / "learned_tracked.yaml"))
    with pytest.raises(ValueError, match="perception.intent_weights"):
        profile_digest(other)


def test_a_suite_row_names_a_profile_file_under_the_suites_methods():
    from avp_experiment.headline import cell_argv, load_suite

    suite = load_suite("sensing")
    col = next(c for c in suite["columns"] if c["id"] == "contested_realistic")
    row = next(r for r in suite["rows"] if r["id"] == "learned_tracked")
    argv = cell_argv(col, row, quick=True)
    path = Path(argv[argv.index("--methods") + 1])
    assert path.is_file() and path.name == "learned_tracked.yaml" and load_profile(path).name == "learned_tracked"
