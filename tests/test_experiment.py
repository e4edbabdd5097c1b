"""The Table I runner: profiles, metrics on hand-built cases, resumability, determinism, the summary
table, and in-process vs live-DDS-graph equality."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from avp_episode.metrics import comparable, prediction_errors, wilson
from avp_episode.profiles import (
    TABLE_ORDER,
    ProfileError,
    available_names,
    load_profile,
    methods_dir,
    planner_profile_yaml,
    planner_settings,
)
from avp_experiment.runner import RESULTS_FILE, add_arguments, main, read_results, record_key, run_experiment
from avp_world.types import PredictedTrajectory

T_FINAL = 6.0  # short episodes: the runner's logic, not the method's success, is under test here


def argv(out: Path, *extra: str) -> list[str]:
    return ["--scenarios", "2", "--seed-base", "1", "--t-final", str(T_FINAL), "--no-progress", "--out", str(out),
            *extra]


def run(out: Path, *extra: str) -> int:
    """The command's exit status."""
    return main(argv(out, *extra))


def ran(out: Path, *extra: str) -> int:
    """How many episodes the command ran."""
    p = argparse.ArgumentParser()
    add_arguments(p)
    return run_experiment(p.parse_args(argv(out, *extra)))["ran"]


def records(out: Path) -> dict:
    return {record_key(r): comparable(r) for r in read_results(out / RESULTS_FILE)}


# ------------------------------------------------------------------------------------------ profiles


def test_every_table_row_has_a_profile():
    assert available_names() == list(TABLE_ORDER)
    profiles = {n: load_profile(n) for n in TABLE_ORDER}
    assert [n for n, p in profiles.items() if not p.available] == []
    assert profiles["implicit"].ego_intent and profiles["implicit"].beliefs == "observation"
    assert profiles["nawaz"].beliefs == "nawaz" and profiles["nawaz"].predictor == "constant_velocity"
    assert {profiles[n].predictor for n in ("bezier", "constant_velocity", "hybrid_astar", "learned")} == {
        "bezier", "constant_velocity", "hybrid_astar", "learned"}
    # the planner block is a planner profile; the runner lifts the wall-clock caps
    text = planner_profile_yaml(profiles["bezier"])
    assert yaml.safe_load(text)["/**"]["ros__parameters"] == {"use_beliefs": True, "use_predictions": True}
    settings, use_b, use_p = planner_settings(profiles["bezier"], deterministic=True)
    assert use_b and use_p and settings.search.time_cap >= 100 and settings.decision.decision_time_cap >= 100


def unavailable_learned(tmp_path: Path) -> Path:
    """A copy of the learned profile marked unavailable (the runner lists it with the paper's numbers only)."""
    data = yaml.safe_load((methods_dir() / "learned.yaml").read_text())
    data.update(available=False, unavailable_reason="switched off for this test")
    path = tmp_path / "learned.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_profiles_map_onto_the_four_node_graph(tmp_path):
    """One mapping (method_node_params) puts a profile on the same 4 nodes as the default graph: written out here
    for the implicit and Nawaz rows; the Bézier row changes nothing the node defaults do not already say."""
    from avp_bringup.graph import default_graph, method_graph
    from avp_episode.profiles import BELIEF_SOURCES, method_node_params
    from avp_perception.core.pipeline import BELIEF_SOURCES as NODE_SOURCES

    assert BELIEF_SOURCES == NODE_SOURCES
    assert method_node_params(load_profile("implicit")) == {
        "avp_belief": {"belief_source": "observation", "ego_intent": True},
        "avp_prediction": {"method": "constant_velocity"},
        "avp_planner": {"use_beliefs": True, "use_predictions": True, "use_ego_intention": True}}
    p = method_node_params(load_profile("nawaz"), deterministic=True, intent_weights="w.pt", intent_seed=3)
    assert p["avp_belief"] == {"belief_source": "nawaz", "ego_intent": False, "intent.weights": "w.pt",
                               "intent.seed": 3}
    assert p["avp_prediction"] == {"method": "constant_velocity", "hybrid_astar.time_cap": 60.0}
    assert p["avp_planner"]["use_ego_intention"] is False and p["avp_planner"]["search.time_cap"] >= 100
    base = default_graph("planner")
    for name in ("bezier", "constant_velocity", "hybrid_astar", "implicit", "nawaz"):
        nodes = method_graph(name, sim_extra={"seed": 5})
        assert [(n.name, n.package, n.executable) for n in nodes] == [(n.name, n.package, n.executable) for n in base]
        assert nodes[0].extra_params["seed"] == 5
    # the bezier profile = the shipped parameter files of the default graph
    from avp_common.params import load_yaml_params
    from avp_perception.params import BELIEF_PARAMS, PREDICTION_PARAMS
    from avp_planner.planner_node import PLANNER_PARAMS

    for spec, specs in zip(method_graph("bezier")[1:], (BELIEF_PARAMS, PREDICTION_PARAMS, PLANNER_PARAMS), strict=True):
        values = load_yaml_params(spec.default_params(), spec.name, specs)
        default_extra = next(n for n in base if n.name == spec.name).extra_params
        assert all(values[k] == v or default_extra.get(k) == v for k, v in spec.extra_params.items()), spec.name
    assert method_node_params(load_profile("learned"))["avp_prediction"] == {"method": "learned"}
    with pytest.raises(ProfileError, match="not available"):
        method_graph(unavailable_learned(tmp_path))


@pytest.mark.parametrize("mutate,needle", [
    (lambda d: d["perception"].update(beliefs="oracle"), "'perception.beliefs'"),
    (lambda d: d["planner"].update(no_such_key=1), "'planner.no_such_key'"),
    (lambda d: d["planner"].update(use_beliefs="yes"), "'use_beliefs'"),
    (lambda d: d.pop("available"), "'available': missing"),
    (lambda d: d.update(colour="red"), "'colour': unknown key"),
    (lambda d: d["planner"].update(use_ego_intention=True), "'planner.use_ego_intention': follows"),
])
def test_bad_profile_names_file_and_field(tmp_path, mutate, needle):
    data = yaml.safe_load(Path(load_profile("bezier").source).read_text())
    mutate(data)
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ProfileError) as exc:
        load_profile(str(bad))
    assert needle in str(exc.value) and str(bad) in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ProfileError, match="unknown method 'nope'"):
        load_profile("nope")


# ------------------------------------------------------------------------------------------ metrics


def test_min_ade_and_min_fde_by_hand():
    """One vehicle moving +x at 1 m per step; H = 4 steps. Mode A is 1 m off everywhere (ADE 1, FDE 1), mode B
    exact but 3 m off at the end (ADE 0.75, FDE 3): minADE = 0.75 (B), minFDE = 1 (A), each minimised alone."""
    dt = 0.1
    gt = np.zeros((10, 2, 3))  # steps 0..9, two vehicles (column 1 parked)
    gt[:, 0, 0] = np.arange(10.0)
    gt[:, 1] = (50.0, 50.0, 0.0)
    truth = np.column_stack([np.arange(1.0, 5.0), np.zeros(4), np.zeros(4)])  # steps 1..4 seen from step 0
    a = truth + [0.0, 1.0, 0.0]
    b = truth.copy()
    b[-1, 1] = 3.0
    preds = {0: [PredictedTrajectory(7, a, dt), PredictedTrajectory(7, b, dt)],
             6: [PredictedTrajectory(7, a, dt)]}  # step 6 + 4 > 9: the log does not cover it, skipped
    ade, fde = prediction_errors(preds, gt, np.array([7, 8]), dt, horizon=4 * dt)
    assert ade.tolist() == pytest.approx([0.75]) and fde.tolist() == pytest.approx([1.0])
    # a longer prediction is cut at H; a pedestrian or an unknown id is ignored
    longer = np.vstack([truth, [[9.0, 9.0, 0.0]]])
    ped = PredictedTrajectory(7, truth, dt, is_pedestrian=True, radius=0.3)
    ade, fde = prediction_errors({0: [PredictedTrajectory(7, longer, dt), ped, PredictedTrajectory(99, a, dt)]},
                                 gt, np.array([7, 8]), dt, horizon=4 * dt)
    assert ade.tolist() == [0.0] and fde.tolist() == [0.0]


def test_motion_counts_by_hand():
    """Reversals and U-turns on hand-made ego paths."""
    from avp_episode.metrics import motion_counts

    straight = np.array([[0.2 * k, 0.0, 0.0] for k in range(50)])
    assert motion_counts(straight) == {"reversals": 0, "u_turns": 0}
    # a three-point turn: forward left 90 deg, back 0 -> (turning on), forward on: heading 0 -> pi
    pts, x, y, th = [], 0.0, 0.0, 0.0
    for v, w, n in ((1.0, 0.9, 20), (-1.0, -0.9, 15), (1.0, 0.9, 30), (1.0, 0.0, 10)):
        for _ in range(n):
            pts.append((x, y, th))
            x, y, th = x + 0.1 * v * math.cos(th), y + 0.1 * v * math.sin(th), th + 0.1 * w * abs(v)
    pts.append((x, y, th))
    turn = np.array(pts)
    assert abs(math.remainder(turn[-1, 2], 2 * math.pi)) > math.radians(150)  # it did turn round
    assert motion_counts(turn) == {"reversals": 2, "u_turns": 1}
    # forward, then reversing 90 deg into a spot: one reversal, no U-turn; standing still in between changes nothing
    park = np.array([[0.2 * k, 0.0, 0.0] for k in range(10)] + [[1.8, 0.0, 0.0]] * 5
                    + [[1.8 - 0.1 * k, -0.1 * k, 0.157 * k] for k in range(1, 11)])
    assert motion_counts(park) == {"reversals": 1, "u_turns": 0}


@pytest.mark.slow
def test_the_demo_seed_no_longer_backs_away_while_a_stopped_car_blocks_the_road_ahead():
    """`make demo`'s scenario (seed 1, bezier, reactive). A car stops in the aisle ahead of the ego; the
    detour round (stopped agents as static obstacles) used to back away at once and explore the long way round
    (6 reversals of direction, parked after 38.9 s). With ``decision.detour_waits_to_turn_back`` the road ahead must
    stay blocked for 3 s first (§V-D-2), the car moves on and the ego parks ahead of it, sooner. Measured with the
    agents' reaction assumed only once seen (``collision.reactive_evidence: lot``, the planner profile ``wary``)."""
    from avp_episode.run_config import RunConfig, run_profile, sim_values
    from avp_experiment.runner import run_episode_inproc
    from avp_sim.core.factory import load_lot_param

    out = {}
    for waits in (False, True):
        cfg = RunConfig(planner_overrides={"decision.detour_waits_to_turn_back": waits,
                                           "collision.reactive_evidence": "lot"})
        sim = sim_values(cfg)
        out[waits] = run_episode_inproc(load_lot_param(sim["lot_file"]), sim, run_profile("bezier", cfg), 1, True,
                                        cfg)
    before, after = out[False], out[True]
    assert before["success"] and before["parking_time"] == pytest.approx(38.9) and before["reversals"] == 6
    assert after["success"] and after["parking_time"] < 30.0 and after["reversals"] == 2  # the parking manoeuvre's


def test_wilson_interval_known_values():
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(1.959964**2 / (10 + 1.959964**2), rel=1e-6)  # 0.2775
    assert wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson(10, 10)[0] == pytest.approx(0.7225, abs=1e-4)
    assert all(math.isnan(x) for x in wilson(0, 0))


# ------------------------------------------------------------------------------------------ the runner


def test_resumable_and_summary(tmp_path):
    out = tmp_path / "run"
    cmd = ("--methods", f"nawaz,implicit,{unavailable_learned(tmp_path)}", "--mode", "both", "--workers", "0")
    assert ran(out, *cmd) == 8
    first = records(out)
    assert len(first) == 2 * 2 * 2  # 2 methods x 2 seeds x 2 modes; 'learned' is not available
    # interrupt: the last episode never finished and a line was cut off mid-write
    path = out / RESULTS_FILE
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-1]) + lines[-1][:25])
    assert ran(out, *cmd) == 1  # only the lost episode is run again
    assert records(out) == first
    assert ran(out, *cmd) == 0  # nothing left
    assert len(path.read_text().splitlines()) == 8
    # every invocation that runs episodes is logged (the wall time of a resumed run is their sum)
    runs = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert [r["episodes_run"] for r in runs] == [8, 1] and all(r["wall_s"] >= 0 for r in runs)
    assert runs[0]["options"]["methods"] == cmd[1] and runs[0]["options"]["workers"] == 0 and runs[0]["commit"]
    # the summary: every method x mode (learned with the paper's numbers only)
    md = (out / "summary.md").read_text()
    nr, rr = md.index("Non-Reactive Agents"), md.index("| **Reactive Agents**")
    for label in ("Implicit (ParkPredict+)", "Explicit, future (Nawaz et al.)", "Learned Model (ParkPredict+)"):
        assert nr < md.index(label) < rr and md.index(label, rr) > rr
    assert md.count("| paper | 500 |") == 6 and "| ours | 2 |" in md
    stats = json.loads((out / "summary.json").read_text())["stats"]
    assert set(stats) == {f"{m}/{mode}" for m in ("nawaz", "implicit") for mode in ("reactive", "non_reactive")}
    assert stats["nawaz/reactive"]["episodes"] == 2
    for png in ("success.png", "min_ade.png", "timings.png"):
        assert (out / "plots" / png).stat().st_size > 1000
    # other settings into the same folder are refused
    assert run(out, "--methods", "nawaz", "--workers", "0", "--ade-horizon", "2.0") == 2


def test_summary_lists_every_failed_episode():
    from avp_report.summary import compute_section, failures_section

    def rec(method, seed, mode, status, with_="", wall=1.0):
        return {"method": method, "seed": seed, "mode": mode, "status": status, "success": status == "success",
                "collision_with": with_, "spot_stolen": status == "spot_stolen", "steps": 100,
                "interrupted_steps": 3, "timings": {"wall_s": wall}}

    recs = [rec("bezier", 1, "reactive", "success", wall=2.0),
            rec("nawaz", 7, "non_reactive", "collision", "vehicle:1000"), rec("implicit", 7, "non_reactive", "timeout"),
            rec("nawaz", 3, "reactive", "spot_stolen"),
            rec("bezier", 7, "reactive", "success", wall=4.0)]
    text = "\n".join(failures_section(recs, ["bezier", "implicit", "nawaz"]))
    assert "3 of 5 episodes failed, in 2 (seed, mode) cases over 2 seeds; per method: implicit 1, nawaz 2." in text
    rows = [line for line in text.splitlines() if line.startswith("| 3 ") or line.startswith("| 7 ")]
    assert rows == ["| 3 | reactive | nawaz | spot_stolen | — | 100 | 3 |",
                    "| 7 | non_reactive | implicit | timeout | — | 100 | 3 |",
                    "| 7 | non_reactive | nawaz | collision | vehicle:1000 | 100 | 3 |"]
    assert failures_section(recs[:1], ["bezier"])[-2] == "None."
    assert "Median episode: bezier 3.00 s" in "\n".join(compute_section(recs, ["bezier", "implicit", "nawaz"]))


@pytest.mark.slow
def test_failure_analysis_reruns_failed_episodes(tmp_path):
    """``python -m avp_experiment.failures OUT`` re-runs every failed episode of a run and says whether it
    came out the same, which maneuvers the agents did, and how close they came."""
    from avp_experiment import failures
    from avp_experiment.runner import RunConfig, sim_values
    from avp_scenario.scenario import generate_paper_scenario
    from avp_sim.core.factory import scenario_params
    from avp_world.lot import load_bundled_lot

    out = tmp_path / "run"
    # Nawaz et al., seed 59, non-reactive, stopped at t_f = 5 s: a failure (a timeout) whatever the intent weights
    # (the method never ranks spots with the CNN), in 50 steps. The run's collision at t = 12.5 s with the
    # `wary` profile (docs/results/table1) costs five times the steps, in the searches of its last seconds
    assert main(["--scenarios", "1", "--seed-base", "59", "--methods", "nawaz", "--mode", "non-reactive",
                 "--workers", "0", "--t-final", "5", "--no-progress", "--out", str(out)]) == 0
    path = out / RESULTS_FILE
    (rec,) = read_results(path)
    assert not rec["success"] and rec["status"] == "timeout" and rec["steps"] == 50
    md = tmp_path / "failures.md"
    assert failures.main([str(out), "--markdown", str(md), "--workers", "0"]) == 0  # no pool to start
    text = md.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| 59 |"))
    assert "| yes |" in row
    # a record the re-run does not reproduce is flagged
    path.write_text(json.dumps(dict(rec, steps=rec["steps"] + 1)) + "\n")
    assert failures.main([str(out), "--markdown", str(md), "--workers", "0"]) == 0  # no pool to start
    assert "| NO |" in next(line for line in md.read_text().splitlines() if line.startswith("| 59 |"))
    sc = generate_paper_scenario(load_bundled_lot(), 59, False, scenario_params(sim_values(RunConfig())))
    dyn = [v for v in sc.vehicles if not v.parked]
    for v in dyn:
        assert f"{v.id}: {v.maneuver} → {v.target_spot_id}" in row
        assert f"| {v.maneuver} | 1 | 1 (" in text


def test_an_episode_that_raises_is_reported_and_the_others_recorded(tmp_path, monkeypatch, capsys):
    """One episode's bug must not stop (or silently hang) the sweep: it is named on stderr, left out of the
    results so the same command retries it, the other episodes are recorded and the exit status is 1."""
    import avp_experiment.runner as runner

    real = runner._worker_episode

    def flaky(key):
        if key == ("nawaz", 2, "reactive"):
            raise RuntimeError("kernel size can't be greater than actual input size")
        return real(key)

    monkeypatch.setattr(runner, "_worker_episode", flaky)
    out = tmp_path / "run"
    assert run(out, "--methods", "nawaz", "--mode", "reactive", "--workers", "0") == 1
    err = capsys.readouterr().err
    assert "episode nawaz seed 2 reactive raised RuntimeError: kernel size" in err and "retry" in err
    assert set(records(out)) == {("nawaz", 1, "reactive")}
    monkeypatch.setattr(runner, "_worker_episode", real)
    assert ran(out, "--methods", "nawaz", "--mode", "reactive", "--workers", "0") == 1  # the retry


def test_sim_param_overrides_are_checked_and_part_of_the_run_identity(tmp_path):
    from avp_episode.profiles import load_profile
    from avp_experiment.runner import RunConfig, check_run_file, parse_sim_params, run_identity

    old = parse_sim_params(["scenario.maneuver_max_speed=2.0", "scenario.outer_row_max=9"])
    assert old == {"scenario.maneuver_max_speed": 2.0, "scenario.outer_row_max": 9}
    for bad, needle in (("scenario.maneuver_speed=2", "avp_sim parameter"), ("t_final", "KEY=VALUE"),
                        ("scenario.outer_row_max=1000", "above the maximum"), ("dt=fast", "expected a number")):
        with pytest.raises(ValueError, match=needle):
            parse_sim_params([bad])
    prof = [load_profile("nawaz")]
    check_run_file(tmp_path, run_identity(RunConfig(), prof))
    check_run_file(tmp_path, run_identity(RunConfig(), prof))  # same settings: accepted
    with pytest.raises(ValueError, match=r"scenario\.maneuver_max_speed, scenario\.outer_row_max"):
        check_run_file(tmp_path, run_identity(RunConfig(sim_overrides=old), prof))
    # a parameter added to avp_sim since a folder's run counts as its default there; another value does not
    import json

    run = json.loads((tmp_path / "run.json").read_text())
    del run["sim"]["scenario.passiveness_step"]
    (tmp_path / "run.json").write_text(json.dumps(run))
    check_run_file(tmp_path, run_identity(RunConfig(), prof))
    with pytest.raises(ValueError, match=r"scenario\.passiveness_step"):
        check_run_file(tmp_path, run_identity(RunConfig(sim_overrides={"scenario.passiveness_step": 0.5}), prof))


@pytest.mark.slow
def test_same_command_twice_gives_identical_episodes(tmp_path):
    """Worker processes (spawn) in both runs, finishing in any order: per-episode results are identical."""
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert run(out, "--methods", "bezier,nawaz", "--mode", "reactive", "--workers", "2") == 0
    ra, rb = records(a), records(b)
    assert len(ra) == 4 and ra == rb


# ------------------------------------------------------------------------------------------ over DDS


pytest.importorskip("rclpy")


def test_inproc_and_ros_transport_give_identical_episodes(tmp_path, ros_env, monkeypatch):
    """Seeds 1 and 2 (dynamic vehicles in view early, so minADE has samples) through the live graph (the 4 nodes —
    simulator, belief, prediction, planner — configured per method, over DDS, reset service per episode) equal the
    in-process episodes bit for bit, Nawaz's occupancy and the implicit ego intention included."""
    for k, v in ros_env.items():
        monkeypatch.setenv(k, v)
    common = ["--t-final", "10", "--methods", "bezier,nawaz,implicit", "--mode", "reactive"]
    assert run(tmp_path / "ros", *common, "--transport", "ros") == 0
    assert run(tmp_path / "inproc", *common, "--transport", "inproc", "--workers", "0") == 0
    ros, inproc = records(tmp_path / "ros"), records(tmp_path / "inproc")
    assert len(ros) == 6 and ros == inproc
    assert all(r["ade_samples"] > 0 for r in ros.values())
    raw = read_results(tmp_path / "ros" / RESULTS_FILE)
    assert {r["transport"] for r in raw} == {"ros"}
    # the perception's share (observation k -> predictions k across the belief and prediction nodes) is counted
    assert all(r["timings"]["perception_time"] > 0 for r in raw)


def test_intent_identity_names_the_weights_without_machine_paths(tmp_path):
    """run.json / summary.md name the intent weights by content hash and 'shipped' (or the path as given), never
    by this machine's absolute path, so results made on two machines compare."""
    import hashlib

    from avp_experiment.runner import RunConfig, intent_identity
    from avp_perception.core.pipeline import shipped_weights_path

    shipped = shipped_weights_path()
    assert intent_identity(RunConfig()) == f"sha256:{hashlib.sha256(shipped.read_bytes()).hexdigest()} (shipped)"
    assert str(shipped.parent) not in intent_identity(RunConfig())
    (tmp_path / "w.pt").write_bytes(b"not really weights")
    given = str(tmp_path / "w.pt")
    assert intent_identity(RunConfig(intent_weights=given)).endswith(f" ({given})")
    with pytest.raises(ValueError, match="no such file"):
        intent_identity(RunConfig(intent_weights=str(tmp_path / "missing.pt")))
    # a name in avp_predictors/models/ (as --intent-weights and the belief node's intent.weights take it): that file
    named = intent_identity(RunConfig(intent_weights=shipped.name))
    assert named == f"sha256:{hashlib.sha256(shipped.read_bytes()).hexdigest()} ({shipped.name})"
    with pytest.raises(ValueError, match="no such file"):
        intent_identity(RunConfig(intent_weights="no_such_model.pt"))


@pytest.mark.slow
def test_a_second_invocation_on_a_folder_being_written_is_refused(tmp_path):
    """Two invocations on one folder would each run the episodes the other runs and record them twice (seen when a
    run was restarted while the interrupted one finished its episodes): the second one is refused."""
    import subprocess
    import sys

    from avp_experiment.results import lock_folder

    held = lock_folder(tmp_path)
    try:
        r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", "blind",
                            "--scenarios", "1", "--no-progress", "--out", str(tmp_path)],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and "another avp experiment is writing this folder" in r.stderr, r.stderr
        assert not (tmp_path / "episodes.jsonl").exists()
    finally:
        held.close()
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "experiment", "--methods", "blind", "--scenarios",
                        "1", "--mode", "non-reactive", "--t-final", "5", "--no-progress", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
