"""The experiment's PNG charts, drawn with matplotlib's object-oriented API on an Agg canvas (no pyplot, no
global backend state, no display needed).

* :func:`plot_bars` — one value per method and mode: rates (%) as points with 95 % Wilson intervals on an axis
  fitted to the data (not 0-based, so 90 % and 100 % look different), or mean ± std as bars from 0;
  the paper's Table I values as black diamonds;
* :func:`plot_timings` — box plots (5-25-50-75-95 %) of the per-episode mean spot-selection and path-planning
  times per method, log scale;
* :func:`plot_sweep` — success / spots stolen / collision rates and interrupted timesteps against the value
  of one knob, one line per method, with 95 % bands.

Axis limits come from the pure function :func:`fitted_limits`.
"""

from __future__ import annotations

import math
import numbers
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from avp_episode.metrics import Z95, wilson
from avp_report.paper import TABLE_I

MODES = (("non_reactive", "non-reactive"), ("reactive", "reactive"))
MODE_COLORS = {"non_reactive": "#2878c8", "reactive": "#e68c3c"}
TIMING_COLORS = {"spot_selection_time": "#5aaa5a", "path_planning_time": "#c85a46"}
PAPER_STYLE = {"marker": "D", "color": "black", "markersize": 6, "linestyle": "none", "zorder": 4}
SWEEP_PANELS = (("success", "Success (%)"), ("stolen", "Spots stolen (%)"), ("collision", "Collisions (%)"),
                ("interrupted", "Interrupted timesteps"))
DPI = 100


def fitted_limits(values: Iterable[float | None], lower: float | None = None, upper: float | None = None,
                  pad: float = 0.08, min_span: float = 1.0) -> tuple[float, float]:
    """Axis limits fitted to ``values`` (None / NaN ignored): their range, at least ``min_span`` wide, widened by
    ``pad`` of the span on both sides, then clamped to ``[lower, upper]`` less a 2 % margin (so that a point on
    the bound is not cut in half). With no finite value: ``(lower or 0, upper or 1)``.

    E.g. rates with Wilson bounds in 95–100 % and ``lower=0, upper=100`` give about (94.6, 100.1).
    """
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    if not v:
        lo0 = 0.0 if lower is None else float(lower)
        return lo0, (lo0 + 1.0 if upper is None else float(upper))
    lo, hi = min(v), max(v)
    span = max(hi - lo, min_span)
    if hi - lo < min_span:  # centre a degenerate range
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * span, mid + 0.5 * span
    lo, hi = lo - pad * span, hi + pad * span
    if lower is not None:
        lo = max(lo, lower - 0.02 * span)
    if upper is not None:
        hi = min(hi, upper + 0.02 * span)
    return lo, hi


def rate_limits(percents: Iterable[float | None]) -> tuple[float, float]:
    """:func:`fitted_limits` for rates in % (interval bounds included in ``percents``): within [0, 100]."""
    return fitted_limits(percents, lower=0.0, upper=100.0, min_span=5.0)


def _wrap(label: str, width: int = 16) -> str:
    return "\n".join(textwrap.wrap(label, width)[:3]) or label


def _save(fig: Figure, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=DPI)
    return path


def _method_axis(ax: Axes, methods: Sequence[str], labels: Mapping[str, str]) -> None:
    ax.set_xticks(range(len(methods)), [_wrap(labels.get(m, m)) for m in methods], fontsize=9)
    ax.set_xlim(-0.6, len(methods) - 0.4)
    ax.grid(axis="y", color="0.88")
    ax.set_axisbelow(True)


def _bar_values(methods: Sequence[str], stats: Mapping, key: str, rate: bool) -> tuple[list, list]:
    """[(method index, mode, value, low, high)] of ours and [(method index, mode, value)] of the paper's."""
    ours, paper = [], []
    for i, m in enumerate(methods):
        for mode, _ in MODES:
            s = (stats.get((m, mode)) or {}).get(key)
            if rate and s and s.get("percent") is not None:
                ours.append((i, mode, s["percent"], s["ci95"][0], s["ci95"][1]))
            elif not rate and s and s.get("mean") is not None:
                ours.append((i, mode, s["mean"], max(s["mean"] - s["std"], 0.0), s["mean"] + s["std"]))
            p = TABLE_I.get(mode, {}).get(m, {}).get(key)
            if p is not None:
                paper.append((i, mode, float(p if rate else p[0])))
    return ours, paper


def plot_bars(path: Path, title: str, methods: Sequence[str], labels: Mapping[str, str], stats: Mapping,
              key: str, rate: bool) -> Path:
    """One value per method and mode from ``stats[(method, mode)][key]``: a rate (``{"percent", "ci95"}``, drawn
    as a point with its Wilson interval, axis fitted by :func:`rate_limits`) or a ``{"mean", "std"}`` (a bar from
    0 with ± std whiskers); the paper's values as black diamonds."""
    ours, paper = _bar_values(methods, stats, key, rate)
    fig = Figure(figsize=(10, 5.6), layout="constrained")
    ax = fig.add_subplot()
    off = {"non_reactive": -0.18, "reactive": 0.18}
    for i, mode, v, lo, hi in ours:
        x = i + off[mode]
        if not rate:
            ax.bar(x, v, width=0.34, color=MODE_COLORS[mode], alpha=0.85)
        # clipped at 0: a Wilson bound can miss the rate by 1e-14 (k = n = 94), and matplotlib refuses a negative error
        ax.errorbar(x, v, yerr=[[max(v - lo, 0.0)], [max(hi - v, 0.0)]], fmt="o" if rate else "none",
                    color=MODE_COLORS[mode],
                    ecolor="black" if not rate else MODE_COLORS[mode], markersize=7, capsize=5, elinewidth=1.5)
    for i, mode, v in paper:
        ax.plot([i + off[mode]], [v], **PAPER_STYLE)
    if rate:
        ax.set_ylim(*rate_limits([x for o in ours for x in o[2:]] + [p[2] for p in paper]))
    else:
        ax.set_ylim(*fitted_limits([0.0] + [o[4] for o in ours] + [p[2] for p in paper], lower=0.0))
    _method_axis(ax, methods, labels)
    ax.set_title(title)
    handles = [Patch(color=MODE_COLORS[mode], label=name) for mode, name in MODES]
    handles.append(Line2D([], [], label="paper (Table I)", **PAPER_STYLE))
    ax.legend(handles=handles, loc="best", fontsize=9)
    return _save(fig, path)


def plot_timings(path: Path, methods: Sequence[str], labels: Mapping[str, str],
                 records: Sequence[Mapping]) -> Path:
    """Box plots (whiskers 5 / 95 %, no outliers) of the per-episode mean spot-selection (left) and path-planning
    (right) times per method, both modes pooled; log scale."""
    fig = Figure(figsize=(10, 5.6), layout="constrained")
    ax = fig.add_subplot()
    drawn = False
    for j, key in enumerate(TIMING_COLORS):
        for i, m in enumerate(methods):
            v = [r.get("timings", {}).get(key) for r in records if r["method"] == m]
            v = [float(x) for x in v if x is not None and x > 0]
            if not v:
                continue
            ax.boxplot([v], positions=[i + (j - 0.5) * 0.36], widths=0.3, whis=(5, 95), showfliers=False,
                       patch_artist=True, boxprops={"facecolor": TIMING_COLORS[key]},
                       medianprops={"color": "black", "linewidth": 2}, manage_ticks=False)
            drawn = True
    if drawn:
        ax.set_yscale("log")
    else:
        ax.text(0.5, 0.5, "no timings recorded", transform=ax.transAxes, ha="center", va="center")
    _method_axis(ax, methods, labels)
    ax.set_ylabel("s")
    ax.set_title("Per-episode mean time per step (s), log scale: spot selection | path planning")
    ax.legend(handles=[Patch(color=c, label=k.replace("_time", "").replace("_", " "))
                       for k, c in TIMING_COLORS.items()], loc="best", fontsize=9)
    return _save(fig, path)


# ------------------------------------------------------------------------------------------ sweeps


def _is_number(v: object) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(float(v))


def _float(v: object) -> float:
    return math.nan if v is None else float(v)


def sweep_series(rows: Sequence[Mapping], panel: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(value, low, high) per sweep value of one panel of :func:`plot_sweep`: a rate in % with its 95 % Wilson
    interval, or the interrupted timesteps' mean ± 1.96 sd / sqrt(n) (the band clipped at 0); NaN where ``n``
    is 0."""
    val, lo, hi = [], [], []
    for r in rows:
        n = int(r.get("n") or 0)
        if panel == "interrupted":
            mean, sd = _float(r.get("interrupted_mean")), _float(r.get("interrupted_sd"))
            half = Z95 * sd / math.sqrt(n) if n else math.nan
            val.append(mean if n else math.nan)
            lo.append(max(mean - half, 0.0))
            hi.append(mean + half)
        else:
            k = int(r.get(panel) or 0)
            w_lo, w_hi = wilson(k, n)
            val.append(100.0 * k / n if n else math.nan)
            lo.append(100.0 * w_lo)
            hi.append(100.0 * w_hi)
    return np.array(val, float), np.array(lo, float), np.array(hi, float)


def plot_sweep(path: Path, key: str, values: list, rows: dict[str, list[dict]], title: str = "") -> Path:
    """One PNG of 4 panels (success %, spots stolen %, collisions %, interrupted timesteps) against the value of
    the knob ``key``, one line per method with 95 % bands (Wilson for the rates, mean ± 1.96 sd / sqrt(n) for the
    interrupted timesteps; a value with ``n`` = 0 has no point and no band).

    Args:
        path: the PNG to write (its folder is created).
        key: the knob's name (the x axis' label).
        values: the knob's values; numbers give a numeric x axis (log if they are positive and span a factor
            of 100 or more), anything else a categorical one.
        rows: method -> one dict per value of ``values`` (same order) with ``n``, ``success``, ``stolen``,
            ``collision`` (episode counts), ``interrupted_mean`` and ``interrupted_sd`` (population std).
        title: the figure's title (default: "Sweep over <key>").
    """
    for m, rs in rows.items():
        if len(rs) != len(values):
            raise ValueError(f"method {m!r}: {len(rs)} rows for {len(values)} values of {key!r}")
    numeric = bool(values) and all(_is_number(v) for v in values)
    x = np.array([float(v) for v in values]) if numeric else np.arange(len(values), dtype=float)
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, (panel, ylabel) in zip(axes, SWEEP_PANELS, strict=True):
        fitted: list[float] = []
        for idx, (m, rs) in enumerate(rows.items()):
            v, lo, hi = sweep_series(rs, panel)
            color = f"C{idx % 10}"
            ax.plot(x, v, marker="o", color=color, label=m)
            ok = np.isfinite(lo) & np.isfinite(hi)
            if ok.any():
                ax.fill_between(x, np.where(ok, lo, np.nan), np.where(ok, hi, np.nan), where=ok, color=color,
                                alpha=0.2, linewidth=0)
            fitted += [*v.tolist(), *lo[ok].tolist(), *hi[ok].tolist()]
        if panel == "interrupted":
            ax.set_ylim(*fitted_limits(fitted, lower=0.0, min_span=0.1))
        else:
            ax.set_ylim(*rate_limits(fitted))
        ax.set_ylabel(ylabel)
        ax.grid(color="0.9")
    if numeric and len(x) and x.min() > 0 and x.max() / x.min() >= 100:
        axes[0].set_xscale("log")
    elif numeric and len(x) <= 12:
        axes[0].set_xticks(x, [f"{v:g}" for v in x])
    if not numeric:
        axes[0].set_xticks(x, [str(v) for v in values])
    for ax in axes[2:]:
        ax.set_xlabel(key)
        ax.tick_params(labelbottom=True)
    if rows:
        axes[0].legend(loc="best", fontsize=9)
    fig.suptitle(title or f"Sweep over {key}")
    return _save(fig, path)
