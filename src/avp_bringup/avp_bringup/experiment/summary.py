"""The experiment's summary: a Markdown table laid out like Table I with the paper's numbers beside ours,
``summary.json``, and PNG plots drawn with OpenCV (matplotlib is not a dependency).

Plots (``OUT/plots/``): ``success.png`` (success rate per method and mode, 95 % Wilson intervals),
``min_ade.png`` (minADE mean ± std), ``timings.png`` (distributions of the per-episode mean spot-selection
and path-planning times, log scale); the paper's values are drawn as black diamonds.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np

from avp_bringup.experiment.metrics import aggregate
from avp_bringup.experiment.paper import EPISODES_PER_MODE, TABLE_I
from avp_bringup.experiment.profiles import TABLE_ORDER, ProfileError, load_profile

MODE_ORDER = (("non_reactive", "Non-Reactive Agents"), ("reactive", "Reactive Agents"))
HEADER = ("| Group | Method | | n | Success (%) ↑ | Spots Stolen (%) ↓ | Interrupted Timesteps ↓ "
          "| Spot Selection (s) ↓ | Path Planning (s) ↓ | Parking Time (s) ↓ | minADE (m) ↓ | minFDE (m) ↓ |")
RULE = "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"


def _labels(methods: Sequence[str]) -> dict[str, tuple[str, str]]:
    out = {}
    for m in methods:
        try:
            p = load_profile(m)
            out[m] = (p.group, p.label)
        except ProfileError:
            out[m] = ("", m)
    return out


def _ms(s: Mapping | None, digits: int) -> str:
    if not s or s.get("mean") is None:
        return "—"
    return f"{s['mean']:.{digits}f} ± {s['std']:.{digits}f}"


def _rate(s: Mapping | None) -> str:
    if not s or s.get("percent") is None:
        return "—"
    lo, hi = s["ci95"]
    return f"{s['percent']:.1f} [{lo:.1f}, {hi:.1f}]"


def _paper_ms(v, digits: int) -> str:
    return f"{v[0]:.{digits}f} ± {v[1]:.{digits}f}"


COLUMNS = (("success", "rate", 1), ("spot_stolen", "rate", 1), ("interrupted_steps", "ms", 3),
           ("spot_selection_time", "ms", 4), ("path_planning_time", "ms", 4), ("parking_time", "ms", 1),
           ("min_ade", "ms", 2), ("min_fde", "ms", 2))


def markdown_table(stats: Mapping[tuple[str, str], Mapping], methods: Sequence[str],
                   skipped: Mapping[str, str]) -> str:
    """Table I layout: one block per mode, for each method a row of ours and a row of the paper's."""
    labels = _labels(methods)
    lines = [HEADER, RULE]
    for mode, title in MODE_ORDER:
        lines.append(f"| **{title}** | | | | | | | | | | | |")
        for m in methods:
            group, label = labels[m]
            s = stats.get((m, mode))
            ours = []
            for col, kind, d in COLUMNS:
                ours.append(_rate(s.get(col)) if s and kind == "rate" else _ms(s.get(col) if s else None, d))
            n = str(s["episodes"]) if s else "0"
            note = " *(not run)*" if m in skipped and not s else ""
            lines.append(f"| {group} | {label}{note} | ours | {n} | " + " | ".join(ours) + " |")
            p = TABLE_I.get(mode, {}).get(m)
            if p is not None:
                cells = [f"{p[c]:.1f}" if k == "rate" else _paper_ms(p[c], d) for c, k, d in COLUMNS]
                lines.append(f"| | | paper | {EPISODES_PER_MODE} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def method_order(records: Sequence[Mapping], skipped: Mapping[str, str]) -> list[str]:
    names = {r["method"] for r in records} | set(skipped)
    return [m for m in TABLE_ORDER if m in names] + sorted(names - set(TABLE_ORDER))


def write_summary(out: Path, records: Sequence[Mapping], skipped: Mapping[str, str], info: Mapping) -> dict:
    """summary.md, summary.json and plots/ under ``out``; returns the statistics."""
    out = Path(out)
    stats = aggregate(records)
    methods = method_order(records, skipped)
    table = markdown_table(stats, methods, skipped)
    n_by_mode = {mode: len({r["seed"] for r in records if r["mode"] == mode}) for mode, _ in MODE_ORDER}
    text = [
        "# Table I — our runs beside the paper's",
        "",
        f"Episodes: {len(records)} ({', '.join(f'{k}: {v} scenarios' for k, v in n_by_mode.items())}); "
        f"t_f = {info.get('t_final')} s; minADE/minFDE horizon H = {info.get('ade_horizon')} s; "
        f"intent CNN: {info.get('intent')}."
        + (f" Seeds without a scenario (skipped): {info['seeds_without_scenario']}."
           if info.get("seeds_without_scenario") else "")
        + (f" Simulator overrides: {info['sim_overrides']}." if info.get("sim_overrides") else ""),
        "",
        "Rates: % of episodes with a 95 % Wilson interval; other columns mean ± std over episodes (parking time:",
        "successful episodes; minADE/minFDE: episodes with at least one prediction whose ground-truth future",
        "covers H). Spot selection: mean per decision step (perception + the planner's candidate selection and",
        "pricing); path planning: mean over the steps that ran a Hybrid A* search. Definitions: docs/experiment.md.",
        "",
        table,
        "",
    ]
    if skipped:
        text += ["Not run: " + "; ".join(f"`{k}`: {v}" for k, v in skipped.items()), ""]
    text += failures_section(records, methods) + compute_section(records, methods)
    (out / "summary.md").write_text("\n".join(text))
    js = {f"{m}/{mode}": s for (m, mode), s in sorted(stats.items())}
    (out / "summary.json").write_text(json.dumps({"info": dict(info), "skipped": dict(skipped), "stats": js},
                                                 indent=2, allow_nan=False) + "\n")
    if not methods:  # nothing recorded yet: no plots
        return stats
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    labels = {m: lab for m, (_, lab) in _labels(methods).items()}
    plot_bars(plots / "success.png", "Success rate (%) - 95% Wilson interval", methods, labels, stats, "success",
              rate=True)
    plot_bars(plots / "min_ade.png", "minADE (m) - mean +- std", methods, labels, stats, "min_ade", rate=False)
    plot_timings(plots / "timings.png", methods, labels, records)
    return stats


def failures_section(records: Sequence[Mapping], methods: Sequence[str]) -> list[str]:
    """Markdown lines listing every failed episode, one row per (seed, mode), so that what the failures have in
    common (one scenario failing several methods, or one method failing many scenarios) shows at a glance."""
    failed = [r for r in records if not r["success"]]
    lines = ["## Failed episodes", ""]
    if not failed:
        return lines + ["None.", ""]
    by_case: dict[tuple[int, str], list[Mapping]] = {}
    for r in failed:
        by_case.setdefault((int(r["seed"]), r["mode"]), []).append(r)
    per_method = {m: sum(1 for r in failed if r["method"] == m) for m in methods}
    lines += [f"{len(failed)} of {len(records)} episodes failed, in {len(by_case)} (seed, mode) cases over "
              f"{len({s for s, _ in by_case})} seeds; per method: "
              + ", ".join(f"{m} {n}" for m, n in per_method.items() if n) + ".", "",
              "| seed | mode | method | status | with | steps | interrupted steps |", "|--:|---|---|---|---|--:|--:|"]
    order = {m: i for i, m in enumerate(methods)}
    for (seed, mode), rs in sorted(by_case.items()):
        for r in sorted(rs, key=lambda r: order.get(r["method"], len(order))):
            why = r["status"] + (" (spot stolen)" if r.get("spot_stolen") and r["status"] != "spot_stolen" else "")
            lines.append(f"| {seed} | {mode} | {r['method']} | {why} | {r.get('collision_with') or '—'} | "
                         f"{r['steps']} | {r['interrupted_steps']} |")
    return lines + [""]


def compute_section(records: Sequence[Mapping], methods: Sequence[str]) -> list[str]:
    """Markdown lines with the compute the episodes took (sum of each episode's wall time in its worker)."""
    walls = {m: [float(r["timings"]["wall_s"]) for r in records if r["method"] == m] for m in methods}
    total = sum(sum(w) for w in walls.values())
    if not total:
        return []
    cells = ", ".join(f"{m} {np.median(w):.2f} s" for m, w in walls.items() if w)
    return ["## Compute", "",
            f"Sum of the episodes' wall times (each in one worker process): {total / 3600:.2f} h, i.e. "
            f"{total / 7200:.2f} h of wall time with 2 workers on 2 free cores. Median episode: {cells}.", ""]


# ------------------------------------------------------------------------------------------ plotting

W, H = 1000, 560
LEFT, RIGHT, TOP, BOTTOM = 90, 20, 60, 150
COLORS = {"non_reactive": (200, 120, 40), "reactive": (60, 140, 230)}  # BGR
FONT = cv2.FONT_HERSHEY_SIMPLEX


def _ascii(s: str) -> str:
    return s.replace("é", "e").replace("É", "E").encode("ascii", "replace").decode()


def _nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    span = max(hi - lo, 1e-12)
    step = 10 ** math.floor(math.log10(span / n))
    for f in (1, 2, 2.5, 5, 10):
        if span / (f * step) <= n:
            step *= f
            break
    return np.arange(math.ceil(lo / step) * step, hi + 1e-9 * span, step)


class _Axes:
    def __init__(self, title: str, ylo: float, yhi: float, log: bool = False):
        self.img = np.full((H, W, 3), 255, np.uint8)
        self.log = log
        self.ylo, self.yhi = (math.log10(ylo), math.log10(yhi)) if log else (ylo, yhi)
        cv2.putText(self.img, _ascii(title), (LEFT, 35), FONT, 0.7, (0, 0, 0), 2, cv2.LINE_AA)
        cv2.rectangle(self.img, (LEFT, TOP), (W - RIGHT, H - BOTTOM), (0, 0, 0), 1)
        if log:
            ticks = [10.0**e for e in range(math.floor(self.ylo), math.ceil(self.yhi) + 1)]
        else:
            ticks = list(_nice_ticks(ylo, yhi))
        for t in ticks:
            y = self.y(t)
            if TOP <= y <= H - BOTTOM:
                cv2.line(self.img, (LEFT - 5, y), (W - RIGHT, y), (225, 225, 225), 1)
                cv2.putText(self.img, f"{t:g}", (5, y + 5), FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)

    def y(self, v: float) -> int:
        if self.log:
            v = math.log10(max(v, 10.0**self.ylo))
        f = (v - self.ylo) / max(self.yhi - self.ylo, 1e-12)
        return int(round(H - BOTTOM - f * (H - BOTTOM - TOP)))

    def xlabels(self, labels: Sequence[str]) -> list[float]:
        n = max(len(labels), 1)
        width = (W - RIGHT - LEFT) / n
        centres = [LEFT + width * (i + 0.5) for i in range(n)]
        for c, lab in zip(centres, labels, strict=True):
            words, lines, cur = _ascii(lab).split(), [], ""
            for w in words:
                if len(cur) + len(w) > 16 and cur:
                    lines.append(cur)
                    cur = w
                else:
                    cur = (cur + " " + w).strip()
            lines.append(cur)
            for j, t in enumerate(lines[:3]):
                (tw, _), _ = cv2.getTextSize(t, FONT, 0.45, 1)
                cv2.putText(self.img, t, (int(c - tw / 2), H - BOTTOM + 22 + 18 * j), FONT, 0.45, (0, 0, 0), 1,
                            cv2.LINE_AA)
        return centres

    def legend(self, extra_paper: bool = True) -> None:
        x, y = LEFT + 10, H - 40
        for mode, name in (("non_reactive", "non-reactive"), ("reactive", "reactive")):
            cv2.rectangle(self.img, (x, y - 12), (x + 18, y + 2), COLORS[mode], -1)
            cv2.putText(self.img, name, (x + 24, y), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
            x += 170
        if extra_paper:
            _diamond(self.img, x + 8, y - 5)
            cv2.putText(self.img, "paper (Table I)", (x + 24, y), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)

    def save(self, path: Path) -> None:
        cv2.imwrite(str(path), self.img)


def _diamond(img: np.ndarray, x: int, y: int, r: int = 6) -> None:
    pts = np.array([[x, y - r], [x + r, y], [x, y + r], [x - r, y]], np.int32)
    cv2.fillConvexPoly(img, pts, (0, 0, 0), cv2.LINE_AA)


def plot_bars(path: Path, title: str, methods: Sequence[str], labels: Mapping[str, str], stats: Mapping,
              key: str, rate: bool) -> None:
    vals, paper = [], []
    for m in methods:
        for mode, _ in MODE_ORDER:
            s = stats.get((m, mode), {}).get(key)
            if rate and s and s.get("percent") is not None:
                vals.append((m, mode, s["percent"], s["ci95"][0], s["ci95"][1]))
            elif not rate and s and s.get("mean") is not None:
                vals.append((m, mode, s["mean"], s["mean"] - s["std"], s["mean"] + s["std"]))
            p = TABLE_I.get(mode, {}).get(m, {}).get(key)
            if p is not None:
                paper.append((m, mode, p if rate else p[0]))
    hi = 100.0 if rate else max([v[4] for v in vals] + [p[2] for p in paper] + [1.0]) * 1.1
    ax = _Axes(title, 0.0, hi)
    centres = dict(zip(methods, ax.xlabels([labels.get(m, m) for m in methods]), strict=True))
    bw = (W - RIGHT - LEFT) / max(len(methods), 1) * 0.35
    off = {"non_reactive": -0.5 * bw, "reactive": 0.5 * bw}
    for m, mode, v, lo, hi_ in vals:
        c = centres[m] + off[mode]
        cv2.rectangle(ax.img, (int(c - bw / 2 + 2), ax.y(v)), (int(c + bw / 2 - 2), ax.y(0.0)), COLORS[mode], -1)
        cv2.line(ax.img, (int(c), ax.y(max(lo, 0.0))), (int(c), ax.y(hi_)), (0, 0, 0), 2)
        for yy in (ax.y(max(lo, 0.0)), ax.y(hi_)):
            cv2.line(ax.img, (int(c - 6), yy), (int(c + 6), yy), (0, 0, 0), 2)
    for m, mode, v in paper:
        _diamond(ax.img, int(centres[m] + off[mode]), ax.y(v))
    ax.legend()
    ax.save(path)


def plot_timings(path: Path, methods: Sequence[str], labels: Mapping[str, str], records: Sequence[Mapping]) -> None:
    """Box plots (5-25-50-75-95 %) of per-episode mean spot-selection (left box) and path-planning (right box)
    times per method, both modes pooled; log scale."""
    data = {}
    for m in methods:
        for key in ("spot_selection_time", "path_planning_time"):
            v = [r.get("timings", {}).get(key) for r in records if r["method"] == m]
            data[(m, key)] = np.array([x for x in v if x is not None and x > 0], dtype=float)
    allv = np.concatenate([v for v in data.values() if len(v)] or [np.array([1e-3, 1.0])])
    ax = _Axes("Per-episode mean time per step (s), log scale: spot selection | path planning",
               float(10 ** math.floor(math.log10(allv.min()))), float(10 ** math.ceil(math.log10(allv.max()))),
               log=True)
    centres = dict(zip(methods, ax.xlabels([labels.get(m, m) for m in methods]), strict=True))
    bw = (W - RIGHT - LEFT) / max(len(methods), 1) * 0.3
    colors = {"spot_selection_time": (90, 170, 90), "path_planning_time": (70, 90, 200)}
    for m in methods:
        for j, key in enumerate(("spot_selection_time", "path_planning_time")):
            v = data[(m, key)]
            if not len(v):
                continue
            c = centres[m] + (j - 0.5) * bw * 1.1
            p5, p25, p50, p75, p95 = np.percentile(v, [5, 25, 50, 75, 95])
            cv2.rectangle(ax.img, (int(c - bw / 2), ax.y(p75)), (int(c + bw / 2), ax.y(p25)), colors[key], -1)
            cv2.line(ax.img, (int(c - bw / 2), ax.y(p50)), (int(c + bw / 2), ax.y(p50)), (0, 0, 0), 2)
            cv2.line(ax.img, (int(c), ax.y(p95)), (int(c), ax.y(p75)), (0, 0, 0), 1)
            cv2.line(ax.img, (int(c), ax.y(p25)), (int(c), ax.y(p5)), (0, 0, 0), 1)
    x, y = LEFT + 10, H - 40
    for key, name in (("spot_selection_time", "spot selection"), ("path_planning_time", "path planning")):
        cv2.rectangle(ax.img, (x, y - 12), (x + 18, y + 2), colors[key], -1)
        cv2.putText(ax.img, name, (x + 24, y), FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        x += 190
    ax.save(path)
