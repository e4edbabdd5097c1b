"""The experiment's summary: a Markdown table laid out like Table I with the paper's numbers beside ours,
``summary.json``, and PNG plots drawn with matplotlib (:mod:`.plots`).

Plots (``OUT/plots/``): ``success.png`` (success rate per method and mode, 95 % Wilson intervals, axis fitted
to the data), ``min_ade.png`` (minADE mean ± std), ``timings.png`` (distributions of the per-episode mean
spot-selection and path-planning times, log scale); the paper's values are drawn as black diamonds.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from avp_episode.metrics import aggregate
from avp_episode.profiles import TABLE_ORDER, ProfileError, load_profile
from avp_report.paper import EPISODES_PER_MODE, TABLE_I
from avp_report.plots import plot_bars, plot_timings

MODE_ORDER = (("non_reactive", "Non-Reactive Agents"), ("reactive", "Reactive Agents"))
HEADER = ("| Group | Method | | n | Success (%) ↑ | Spots Stolen (%) ↓ | Interrupted Timesteps ↓ "
          "| Spot Selection (s) ↓ | Path Planning (s) ↓ | Parking Time (s) ↓ | minADE (m) ↓ | minFDE (m) ↓ |")
RULE = "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"


def _labels(methods: Sequence[str], given: Mapping[str, tuple[str, str]] | None = None
            ) -> dict[str, tuple[str, str]]:
    """(group, label) of each method: as the run had them (``given``: profiles from files), else its shipped
    profile's, else the bare name."""
    out = {}
    for m in methods:
        if given and m in given:
            out[m] = tuple(given[m])
            continue
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
                   skipped: Mapping[str, str], given: Mapping[str, tuple[str, str]] | None = None) -> str:
    """Table I layout: one block per mode, for each method a row of ours and a row of the paper's."""
    labels = _labels(methods, given)
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


def write_summary(out: Path, records: Sequence[Mapping], skipped: Mapping[str, str], info: Mapping,
                  labels: Mapping[str, tuple[str, str]] | None = None) -> dict:
    """summary.md, summary.json and plots/ under ``out``; returns the statistics."""
    out = Path(out)
    stats = aggregate(records)
    methods = method_order(records, skipped)
    table = markdown_table(stats, methods, skipped, labels)
    n_by_mode = {mode: len({r["seed"] for r in records if r["mode"] == mode}) for mode, _ in MODE_ORDER}
    text = [
        "# Table I — our runs beside the paper's",
        "",
        f"Episodes: {len(records)} ({', '.join(f'{k}: {v} scenarios' for k, v in n_by_mode.items())}); "
        f"t_f = {info.get('t_final')} s; minADE/minFDE horizon H = {info.get('ade_horizon')} s; "
        f"intent CNN: {info.get('intent')}."
        + (f" Seeds without a scenario (skipped): {info['seeds_without_scenario']}."
           if info.get("seeds_without_scenario") else "")
        + (f" Simulator overrides: {info['sim_overrides']}." if info.get("sim_overrides") else "")
        + (f" Tracker overrides: {info['tracker_overrides']}." if info.get("tracker_overrides") else ""),
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
    short = {m: lab for m, (_, lab) in _labels(methods, labels).items()}
    plot_bars(plots / "success.png", "Success rate (%) - 95% Wilson interval", methods, short, stats, "success",
              rate=True)
    plot_bars(plots / "min_ade.png", "minADE (m) - mean +- std", methods, short, stats, "min_ade", rate=False)
    plot_timings(plots / "timings.png", methods, short, records)
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
