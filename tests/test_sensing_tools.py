"""tools/idle_causes.py and tools/motion_from_tracks.py, whose figures docs/results/sensing/README.md cites: they run
from a clone on committed records and scripted detections, and their counts agree with the records read directly."""

from __future__ import annotations

import gzip
import json
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import idle_causes  # noqa: E402
import motion_from_tracks  # noqa: E402

BLIND = ROOT / "docs/results/sensing/grid/busy_realistic/blind"


def test_idle_causes_counts_the_committed_records(capsys):
    """The row's outcomes and mean idle steps are those of the records, read here with the standard library; the
    paired line reports no change for a folder against itself."""
    with gzip.open(BLIND / "episodes.jsonl.gz", "rt") as f:
        recs = [json.loads(line) for line in f]
    idle = sum(r["decision_trace"]["steps_by_mode"].get("idle", 0) for r in recs) / len(recs)
    assert idle_causes.main([f"a={BLIND}", f"b={BLIND}:blind"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| a |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == str(len(recs)) and float(cells[4]) == round(idle, 1)
    for status, n in Counter(r["status"] for r in recs).items():
        assert f"{status} {n}" in cells[-1]
    assert "no change" in out
    drive = next(line for line in out.splitlines() if line.startswith("| a |") and line != row)
    cells = [c.strip() for c in drive.strip("|").split("|")]
    assert float(cells[1]) == round(sum(r["reversals"] for r in recs) / len(recs), 2)
    timeouts = [r for r in recs if r["status"] == "timeout"]
    frozen = sum(max(r["decision_trace"]["idle_spells"], key=lambda sp: sp["start_step"])["steps"] >= 100
                 for r in timeouts if r["decision_trace"]["idle_spells"])
    assert int(cells[3]) == len(timeouts) and int(cells[4]) == frozen


def test_idle_causes_splits_the_parking_time_by_spot(capsys):
    """The paired line's parking-time change where both parked in the same spot and in another one, and the share of
    the total from changes over 10 s, are those of the records read directly."""
    grid = ROOT / "docs/results/sensing/grid/paper_realistic"
    recs = {}
    for row in ("bezier", "bezier_steer"):
        with gzip.open(grid / row / "episodes.jsonl.gz", "rt") as f:
            recs[row] = {(r["seed"], r["mode"]): r for r in map(json.loads, f) if r["status"] == "success"}
    a, b = recs["bezier"], recs["bezier_steer"]
    pairs = [(a[k], b[k]) for k in a if k in b]
    same = [y["parking_time"] - x["parking_time"] for x, y in pairs if x["parked_spot_id"] == y["parked_spot_id"]]
    tail = sum(d for x, y in pairs if abs(d := y["parking_time"] - x["parking_time"]) > 10)
    assert idle_causes.main([f"a={grid / 'bezier'}", f"b={grid / 'bezier_steer'}"]) == 0
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("* a -> b"))
    assert f"same spot {len(same)}: {sum(same) / len(same):+.2f} s" in line
    assert f"another {len(pairs) - len(same)}:" in line and f"{tail:+.0f} of the" in line


def test_inloop_errors_pairs_episodes_and_sums_samples(capsys):
    """tools/inloop_errors.py on one folder read as two presets: every episode with a value paired, the samples the
    records' sum, the means the records' and the ratio 1."""
    import inloop_errors

    folder = ROOT / "docs/results/sensing/grid/paper_realistic/bezier"
    with gzip.open(folder / "episodes.jsonl.gz", "rt") as f:
        recs = [r for r in map(json.loads, f) if r["min_ade"] is not None and r["seed"] < 50]
    assert inloop_errors.main([f"exact={folder}", f"realistic={folder}", "--methods", "bezier", "--seeds", "0-49"]) == 0
    row = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("| bezier |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    n, samples = len(recs), sum(r["ade_samples"] for r in recs)
    ade, fde = (sum(r[k] for r in recs) / n for k in ("min_ade", "min_fde"))
    assert cells[1] == str(n) and cells[2] == cells[3] == f"{samples}: {ade:.2f} / {fde:.2f}" and cells[4] == "1.00"


def test_motion_from_tracks_reads_a_standing_pedestrian_still_with_the_filter():
    fast = {m: motion_from_tracks.run("pedestrian", 0.0, 0.15, m, 160, 0)["flagged"] for m in ("difference", "filter")}
    assert fast["difference"] > 0.5 and fast["filter"] < 0.2


def test_plan_drops_reruns_the_recorded_episode_and_counts_drops():
    """tools/plan_drops.py re-runs an episode of the committed busy-lot records: its outcome, steps and reversals are
    the record's (under noise and, for the same seed, with exact sensing against the headline's exact record), and
    under noise it counts plans dropped because the estimate left them."""
    import plan_drops

    folder = ROOT / "docs/results/sensing/grid/busy_realistic/bezier"
    with gzip.open(folder / "episodes.jsonl.gz", "rt") as f:
        rec = next(r for r in map(json.loads, f) if r["seed"] == 112)
    rows, drops, causes = plan_drops.run(folder, [112])
    assert rows[0][:4] == (112, rec["status"], rec["steps"], rec["reversals"]) and rows[0][4] >= 4  # 43 <-> 69
    assert drops["park: ego off the plan"] > 0 and sum(causes.values()) == rows[0][4]
    with gzip.open(ROOT / "docs/results/busy_dlp/default_reaction_assumed/episodes.jsonl.gz", "rt") as f:
        exact = next(r for r in map(json.loads, f) if r["seed"] == 112 and r["method"] == "bezier")
    rows, drops, causes = plan_drops.run(folder, [112], exact=True)
    assert rows == [(112, exact["status"], exact["steps"], exact["reversals"], 0)] and not drops and not causes


def test_plan_drops_reruns_a_contested_episode_in_its_own_mode():
    """`contested` is non-reactive: with ``reactive=False`` the re-run is the record (seed 170, a racing car drives
    into the ego); the reactive episode of the same seed is another (its car brakes and the ego parks)."""
    import plan_drops

    folder = ROOT / "docs/results/sensing/grid/contested_realistic/bezier"
    with gzip.open(folder / "episodes.jsonl.gz", "rt") as f:
        rec = next(r for r in map(json.loads, f) if r["seed"] == 170)
    rows, _, _ = plan_drops.run(folder, [170], reactive=False)
    assert rec["status"] == "collision" and rows[0][:4] == (170, rec["status"], rec["steps"], rec["reversals"])
    rows, _, _ = plan_drops.run(folder, [170], reactive=True)
    assert rows[0][1:3] != (rec["status"], rec["steps"])


def test_the_in_loop_table_is_made_from_the_committed_records(capsys):
    """docs/results/sensing/README.md's in-loop table (constant velocity, Hybrid A*, learned) is what
    tools/inloop_errors.py makes of the committed records, cell for cell."""
    import inloop_errors

    sensing = ROOT / "docs/results/sensing"
    assert inloop_errors.main([f"exact={ROOT / 'docs/results/paper_protocol/paper'}",
                               f"realistic={sensing / 'inloop/realistic'}", f"harsh={sensing / 'inloop/harsh'}",
                               "--methods", "constant_velocity,hybrid_astar,learned", "--seeds", "0-49"]) == 0
    made = {t.split("|")[1].strip(): [c.strip() for c in t.strip("|").split("|")[1:]]
            for t in capsys.readouterr().out.splitlines() if t.startswith("| ") and "---" not in t}
    text = (sensing / "README.md").read_text()
    block = text[text.index("<!-- inloop:begin -->"):text.index("<!-- inloop:end -->")]
    names = {"constant velocity": "constant_velocity", "Hybrid A*": "hybrid_astar", "learned": "learned"}
    rows = {t.split("|")[1].strip(): [c.strip() for c in t.strip("|").split("|")[1:]] for t in block.splitlines()
            if t.startswith("| ") and t.split("|")[1].strip() in names}
    assert len(rows) == 3
    for label, cells in rows.items():
        assert cells == made[names[label]], label
