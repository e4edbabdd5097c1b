"""``avp experiment --tracker-param`` and a sensing suite row's ``tracker:`` list: the tracker's settings reach the
episodes' tracker, are part of a run's identity, and are refused where no tracker runs."""

import argparse
import json

import pytest

from avp_episode.run_config import RunConfig, sim_values, tracker_values
from avp_episode.sensing import sensed_observer
from avp_experiment.headline import cell_argv, load_suite
from avp_experiment.runner import _cell_args, parse_tracker_params, run_experiment
from avp_sim.core.factory import make_world
from avp_tracking.params import default_tracker_values


def test_a_rows_tracker_list_becomes_tracker_params_of_its_cells():
    suite = load_suite("sensing")
    row = next(r for r in suite["rows"] if r["id"] == "bezier_coast")
    col = next(c for c in suite["columns"] if c["id"] == "busy_realistic")
    args = _cell_args(cell_argv(col, row, False))
    assert args.tracker_param == ["tracking.coast_deceleration=4.0"]
    assert parse_tracker_params(args.tracker_param) == {"tracking.coast_deceleration": 4.0}


def test_the_override_reaches_the_episodes_tracker_and_nothing_else_changes(paper_lot):
    cfg = RunConfig(sim_overrides={"sensing.model": "realistic"},
                    tracker_overrides={"tracking.coast_deceleration": 4.0})
    values = tracker_values(cfg)
    assert values == {**default_tracker_values(), "tracking.coast_deceleration": 4.0}
    world = make_world(paper_lot, sim_values(cfg), 3, False)
    observe = sensed_observer(world, sim_values(cfg), 3, values)
    assert observe.tracker.cfg.coast_deceleration == 4.0
    shipped = sensed_observer(world, sim_values(cfg), 3, tracker_values(RunConfig()))
    assert shipped.tracker.cfg.coast_deceleration == default_tracker_values()["tracking.coast_deceleration"]


@pytest.mark.parametrize("item, match", [
    ("tracking.nope=1", r"--tracker-param 'tracking.nope=1': expected KEY=VALUE with KEY an avp_tracker parameter"),
    ("tracking.coast_deceleration=-1", r"--tracker-param 'tracking.coast_deceleration=-1'"),
    ("sync=latest", r"KEY an avp_tracker parameter"),  # the node's own parameters are not the tracker's
])
def test_bad_items_are_refused_by_name(item, match):
    with pytest.raises(ValueError, match=match):
        parse_tracker_params([item])


def _args(tmp_path, **kw) -> argparse.Namespace:
    base = _cell_args(["--protocol", "paper", "--scenarios", "1", "--mode", "non-reactive", "--methods", "bezier",
                       "--workers", "0", "--no-progress", "--out", str(tmp_path / "out")])
    for k, v in kw.items():
        setattr(base, k, v)
    return base


def test_refused_with_exact_sensing_and_noisy_sensing_over_dds_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match=r"--tracker-param: the tracker runs with noisy sensing only"):
        run_experiment(_args(tmp_path, tracker_param=["tracking.coast_deceleration=4"]))
    with pytest.raises(ValueError, match=r"sensing.model realistic: --transport inproc only"):
        run_experiment(_args(tmp_path, tracker_param=["tracking.coast_deceleration=4"], transport="ros",
                             sim_param=["sensing.model=realistic"]))
    assert not (tmp_path / "out").exists()


def test_a_folder_run_with_tracker_overrides_is_not_resumed_without_them(tmp_path):
    """The overrides are part of the run's identity (run.json); a folder written before they existed reads as none."""

    from avp_episode.profiles import load_profile
    from avp_experiment.results import RUN_FILE, check_run_file, run_identity

    noisy = {"sensing.model": "realistic"}
    with_coast = run_identity(RunConfig(sim_overrides=noisy, tracker_overrides={"tracking.coast_deceleration": 4.0}),
                              [load_profile("bezier")])
    check_run_file(tmp_path, with_coast)
    shipped = run_identity(RunConfig(sim_overrides=noisy), [load_profile("bezier")])
    with pytest.raises(ValueError, match="tracker_overrides"):
        check_run_file(tmp_path, shipped)
    old = json.loads((tmp_path / RUN_FILE).read_text())
    del old["config"]["tracker_overrides"], old["resolved"]  # as written before either existed
    (tmp_path / RUN_FILE).write_text(json.dumps(old))
    check_run_file(tmp_path, shipped)


def test_a_folder_is_not_resumed_after_a_planner_or_tracker_default_changed(tmp_path, monkeypatch):
    """run.json records every resolved planner and tracker value: a changed code default (not only a changed
    profile file or override) is refused by name; a folder written before they were recorded is resumed."""

    from avp_episode.profiles import load_profile
    from avp_experiment.results import RUN_FILE, check_run_file, run_identity

    cfg = RunConfig(sim_overrides={"sensing.model": "realistic"})
    ident = run_identity(cfg, [load_profile("bezier")])
    assert ident["resolved"]["planner"]["bezier"]["collision.localisation_sigmas"] == 2.0
    assert ident["resolved"]["tracker"]["tracking.coast_deceleration"] == 0.0
    check_run_file(tmp_path, ident)
    check_run_file(tmp_path, run_identity(cfg, [load_profile("bezier")]))  # the same values: resumed
    for part, name, key in (("planner", "bezier", "collision.localisation_sigmas"),
                            ("tracker", None, "tracking.coast_deceleration")):
        changed = json.loads(json.dumps(ident))
        values = changed["resolved"][part][name] if name else changed["resolved"][part]
        values[key] = 1.5  # as if the code's default had moved
        with pytest.raises(ValueError, match=key.replace(".", r"\.")):
            check_run_file(tmp_path, changed)
    old = json.loads((tmp_path / RUN_FILE).read_text())
    del old["resolved"]  # a folder written before run.json held the resolved values
    (tmp_path / RUN_FILE).write_text(json.dumps(old))
    assert check_run_file(tmp_path, ident)["resolved"] == ident["resolved"]


def test_a_tracker_parameter_added_since_a_run_reads_as_its_default(tmp_path):
    """A noisy-sensing folder whose run.json lacks a tracker parameter added later (here tracking.box_sigmas) is
    resumed when the new parameter is at its default (off), and refused by name when the command sets it."""
    from avp_episode.profiles import load_profile
    from avp_experiment.results import RUN_FILE, check_run_file, run_identity

    cfg = RunConfig(sim_overrides={"sensing.model": "realistic"})
    check_run_file(tmp_path, run_identity(cfg, [load_profile("bezier")]))
    old = json.loads((tmp_path / RUN_FILE).read_text())
    del old["resolved"]["tracker"]["tracking.box_sigmas"]  # as a folder written before the parameter existed
    (tmp_path / RUN_FILE).write_text(json.dumps(old))
    check_run_file(tmp_path, run_identity(cfg, [load_profile("bezier")]))
    grown = RunConfig(sim_overrides={"sensing.model": "realistic"}, tracker_overrides={"tracking.box_sigmas": 2.0})
    with pytest.raises(ValueError, match=r"tracking\.box_sigmas"):
        check_run_file(tmp_path, run_identity(grown, [load_profile("bezier")]))


def test_a_planner_parameter_added_since_a_run_reads_as_its_shipped_default(tmp_path):
    """A folder whose run.json lacks a planner parameter added later (here collision.localisation_keep_start) is
    resumed when the method runs it at its shipped default, and refused when the command sets it."""
    from avp_episode.profiles import load_profile
    from avp_episode.protocols import apply_planner
    from avp_experiment.results import RUN_FILE, check_run_file, run_identity

    cfg = RunConfig(sim_overrides={"sensing.model": "harsh"})
    check_run_file(tmp_path, run_identity(cfg, [load_profile("bezier")]))
    old = json.loads((tmp_path / RUN_FILE).read_text())
    del old["resolved"]["planner"]["bezier"]["collision.localisation_keep_start"]  # written before it existed
    (tmp_path / RUN_FILE).write_text(json.dumps(old))
    check_run_file(tmp_path, run_identity(cfg, [load_profile("bezier")]))
    (tmp_path / RUN_FILE).write_text(json.dumps(old))
    kept = apply_planner(load_profile("bezier"), {}, {"collision.localisation_keep_start": True})
    with pytest.raises(ValueError, match="bezier"):
        check_run_file(tmp_path, run_identity(cfg, [kept]))
