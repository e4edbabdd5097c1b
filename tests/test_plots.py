"""The experiment's charts (matplotlib, Agg): Table I charts with axes fitted to the data, and the sweep plot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from avp_episode.metrics import aggregate, wilson
from avp_report.plots import (
    fitted_limits,
    plot_bars,
    plot_sweep,
    plot_timings,
    rate_limits,
    sweep_series,
)


def png_size(path: Path) -> tuple[int, int]:
    """The PNG's (width, height), after checking that it is one and that it is not blank."""
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        a = np.asarray(im.convert("L"))
    assert a.min() < 100 and a.max() > 200  # something dark drawn on a light background
    return a.shape[1], a.shape[0]


def record(method: str, mode: str, success: bool, seed: int = 0) -> dict:
    return {"method": method, "mode": mode, "seed": seed, "success": success, "collision": not success,
            "status": "success" if success else "collision", "collision_with": "", "steps": 100,
            "spot_stolen": False, "interrupted_steps": 0, "parking_time": 20.0 if success else None,
            "min_ade": 2.0 + 0.1 * seed, "min_fde": 3.0,
            "timings": {"spot_selection_time": 0.005 * (1 + seed % 3), "path_planning_time": 1.0 + 0.1 * seed,
                        "wall_s": 1.0}}


def sweep_row(n: int, success: int, stolen: int = 0, collision: int = 0, mean: float = 0.5,
              sd: float = 1.0) -> dict:
    return {"n": n, "success": success, "stolen": stolen, "collision": collision, "interrupted_mean": mean,
            "interrupted_sd": sd}


# ------------------------------------------------------------------------------------------ axis limits


def test_rate_axis_is_fitted_to_the_data():
    lo, hi = rate_limits([95.0, 97.5, 100.0, 99.0])
    assert 50.0 < lo < 95.0 and 100.0 <= hi < 101.0
    # 90 % and 100 % are far apart on such an axis (on 0-100 % they were a tenth of it apart)
    lo, hi = rate_limits([90.0, 100.0])
    assert (100.0 - 90.0) / (hi - lo) > 0.8
    # low rates: a small axis from (about) 0, not 0-100
    lo, hi = rate_limits([0.0, 2.0, 4.8])
    assert -1.0 < lo <= 0.0 and 4.8 < hi < 10.0
    # the whole range when the data cover it; nothing outside [0, 100] beyond a 2 % margin
    lo, hi = rate_limits([0.0, 100.0])
    assert -2.1 <= lo <= 0.0 and 100.0 <= hi <= 102.1


def test_fitted_limits_edge_cases():
    assert fitted_limits([]) == (0.0, 1.0)
    assert fitted_limits([None, math.nan], lower=0.0, upper=100.0) == (0.0, 100.0)
    lo, hi = fitted_limits([3.0, 3.0], min_span=1.0)  # degenerate range: centred, min_span wide plus padding
    assert lo < 3.0 < hi and hi - lo == pytest.approx(1.16)
    lo, hi = fitted_limits([0.0, 10.0], lower=0.0)
    assert lo == pytest.approx(-0.2) and hi == pytest.approx(10.8)


def test_success_chart_axis_uses_wilson_bounds():
    """The summary chart's limits: below the lowest lower Wilson bound, so every interval is visible."""
    recs = [record("bezier", "reactive", True, s) for s in range(40)]
    recs += [record("nawaz", "reactive", s != 0, s) for s in range(40)]
    stats = aggregate(recs)
    lowest = min(s["success"]["ci95"][0] for s in stats.values())
    assert lowest == pytest.approx(100 * wilson(39, 40)[0])
    lo, hi = rate_limits([x for s in stats.values() for x in (s["success"]["percent"], *s["success"]["ci95"])])
    assert 50.0 < lo < lowest and hi >= 100.0


# ------------------------------------------------------------------------------------------ Table I charts


def test_table_charts_are_valid_pngs(tmp_path):
    recs = [record(m, mode, (s + i) % 7 != 0, s) for i, m in enumerate(("bezier", "nawaz", "my_method"))
            for mode in ("reactive", "non_reactive") for s in range(10)]
    stats = aggregate(recs)
    methods = ["bezier", "nawaz", "my_method"]
    labels = {"bezier": "Explicit, future (Bézier curves, ours)", "nawaz": "Nawaz et al.", "my_method": "mine"}
    out = tmp_path / "plots"
    for p in (plot_bars(out / "success.png", "Success", methods, labels, stats, "success", rate=True),
              plot_bars(out / "min_ade.png", "minADE", methods, labels, stats, "min_ade", rate=False),
              plot_timings(out / "timings.png", methods, labels, recs)):
        assert p.parent == out and p.stat().st_size > 5000
        w, h = png_size(p)
        assert 800 <= w <= 2000 and 400 <= h <= 1200


def test_table_charts_without_data(tmp_path):
    """A method with no episodes (only the paper's numbers) and no timings at all still draws."""
    p = plot_bars(tmp_path / "s.png", "Success", ["learned"], {}, {}, "success", rate=True)
    png_size(p)
    p = plot_timings(tmp_path / "t.png", ["learned"], {}, [])
    png_size(p)


def test_write_summary_draws_the_three_charts(tmp_path):
    """summary.py's call sites: OUT/plots/{success,min_ade,timings}.png, without running any episode."""
    from avp_report.summary import write_summary

    recs = [record(m, mode, s != 1, s) for m in ("nawaz", "implicit") for mode in ("reactive", "non_reactive")
            for s in range(3)]
    write_summary(tmp_path, recs, {"learned": "not run"}, {"t_final": 6.0, "ade_horizon": 4.0, "intent": "-"})
    for name in ("success.png", "min_ade.png", "timings.png"):
        assert png_size(tmp_path / "plots" / name) == (1000, 560)


# ------------------------------------------------------------------------------------------ sweeps


def test_sweep_series_bands():
    v, lo, hi = sweep_series([sweep_row(10, 9), sweep_row(0, 0)], "success")
    assert v[0] == pytest.approx(90.0) and (lo[0], hi[0]) == pytest.approx(tuple(100 * x for x in wilson(9, 10)))
    assert math.isnan(v[1]) and math.isnan(lo[1]) and math.isnan(hi[1])
    v, lo, hi = sweep_series([sweep_row(16, 16, mean=2.0, sd=4.0)], "interrupted")
    assert v[0] == 2.0 and hi[0] - v[0] == pytest.approx(1.959964 * 4.0 / 4.0, abs=1e-5)
    _, lo, _ = sweep_series([sweep_row(4, 4, mean=0.5, sd=2.0)], "interrupted")
    assert lo[0] == 0.0  # the band of a count does not go below 0


def test_sweep_two_methods_three_values(tmp_path):
    rows = {"bezier": [sweep_row(20, 20), sweep_row(20, 19, 1), sweep_row(20, 15, 3, 2, mean=3.0)],
            "nawaz": [sweep_row(20, 18, 1, 1), sweep_row(20, 16, 2, 2), sweep_row(20, 10, 5, 5, mean=6.0, sd=9.0)]}
    p = plot_sweep(tmp_path / "sweep" / "agents.png", "n_agents", [5, 10, 20], rows, title="Agents")
    assert p == tmp_path / "sweep" / "agents.png" and p.stat().st_size > 10000
    w, h = png_size(p)
    assert 800 <= w <= 2000 and 600 <= h <= 1500


def test_sweep_categorical_and_empty_values(tmp_path):
    rows = {"bezier": [sweep_row(5, 5), sweep_row(0, 0, mean=None, sd=None), sweep_row(5, 4)],
            "nawaz": [sweep_row(0, 0), sweep_row(0, 0), sweep_row(0, 0)]}  # a method with no episodes at all
    p = plot_sweep(tmp_path / "speed.png", "agent_speed", ["slow", None, "fast"], rows)
    png_size(p)
    p = plot_sweep(tmp_path / "log.png", "gain", [0.01, 0.1, 10.0], {"bezier": rows["bezier"]})
    png_size(p)


def test_sweep_rejects_mismatched_rows(tmp_path):
    with pytest.raises(ValueError, match="2 rows for 3 values"):
        plot_sweep(tmp_path / "x.png", "k", [1, 2, 3], {"bezier": [sweep_row(1, 1), sweep_row(1, 1)]})
    assert not (tmp_path / "x.png").exists()


def test_all_successful_methods_plot(tmp_path):
    """k = n = 94: the upper Wilson bound comes out as 99.99999999999999 %, a hair below the rate — the chart must draw
    (`avp experiment --summary-only` failed with "'yerr' must not contain negative values" on such a run)."""
    recs = [record(m, mode, True, s) for m in ("bezier", "oracle") for mode in ("reactive", "non_reactive")
            for s in range(94)]
    stats = aggregate(recs)
    p = plot_bars(tmp_path / "success.png", "Success", ["bezier", "oracle"], {}, stats, "success", rate=True)
    assert p.stat().st_size > 5000
