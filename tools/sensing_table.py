"""The sensing suite's cells beside exact sensing, paired on seeds (docs/results/sensing/README.md).

    python tools/sensing_table.py OUT [--columns contested_realistic,...]

OUT is a folder of ``avp experiment --suite sensing`` (OUT/<column>/<row>/). Exact sensing is read from the committed
records the headline suite names for the same setting (config/suites/headline.yaml: contested, paper, busy_dlp).
Per cell: the rate with its 95 % Wilson interval (failed or stolen on `contested`, parks elsewhere), the same rate
with exact sensing on the same seeds, the exact McNemar p of the two (paired by seed and mode), blind's rate under
the same noise on the same seeds and the McNemar p of the row against it, the collisions at fault (and with exact
sensing on the same seeds), and the mean minADE / minFDE with its ratio to exact sensing's (the predictions the ego
made during the episodes, each scored against the vehicle its track follows).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from motion_table import mcnemar

from avp_episode.metrics import wilson
from avp_experiment.headline import committed_records, load_suite
from avp_experiment.results import read_results, records_file

ROOT = Path(__file__).resolve().parents[1]
#: the headline column with exact sensing of each sensing column's setting
EXACT_COLUMN = {"contested": "contested", "paper": "paper", "busy": "busy_dlp"}
#: the headline row with exact sensing of a sensing row that has none of its own: every ``bezier_*`` row switches
#: something of the shipped default that exact sensing leaves unchanged (no localisation covariance, no tracker) or
#: that the row's comparison under noise measures; its exact-sensing figure is the shipped default's
EXACT_ROW = {"bezier_no_loc": "bezier", "learned_tracked": "learned"}
#: rows that change one thing of another row than the shipped default: paired with that row under the same noise too
BASE_ROW = {"learned_tracked": "learned"}


def exact_row(rid: str) -> str:
    """The headline row whose exact-sensing records pair with sensing row ``rid``."""
    return EXACT_ROW.get(rid, "bezier" if rid.startswith("bezier_") else rid)


def is_ablation(rid: str) -> bool:
    """Rows that switch one thing of the shipped default (or of :data:`BASE_ROW`'s row): paired with it under the
    same noise too."""
    return rid.startswith("bezier_") or rid in BASE_ROW


def _bad(metric: str, r: dict) -> bool:
    """The event counted: failed or stolen (`contested`), else not parked."""
    return (not r["success"]) or bool(r["spot_stolen"]) if metric == "failed_or_stolen" else not r["success"]


def _by_key(records) -> dict[tuple, dict]:
    return {(int(r["seed"]), r["mode"]): r for r in records}


def _rate(k: int, n: int) -> str:
    if not n:
        return "—"
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def _pair(metric: str, a: dict, b: dict) -> tuple[int, int, int, float]:
    """(n paired, events in a, events in b, McNemar p) over the keys both have."""
    keys = sorted(set(a) & set(b))
    ea = [_bad(metric, a[k]) for k in keys]
    eb = [_bad(metric, b[k]) for k in keys]
    only_a = sum(x and not y for x, y in zip(ea, eb, strict=True))
    only_b = sum(y and not x for x, y in zip(ea, eb, strict=True))
    return len(keys), sum(ea), sum(eb), mcnemar(only_a, only_b)


def _mean(values) -> float:
    v = [float(x) for x in values if x is not None and x == x]
    return sum(v) / len(v) if v else float("nan")


def table(out: Path, columns: list[str] | None = None) -> str:
    suite = load_suite("sensing")
    headline = load_suite("headline")
    lines = []
    for col in suite["columns"]:
        if columns and col["id"] not in columns:
            continue
        metric = "failed_or_stolen" if col["metric"] == "failed_or_stolen" else "success"
        what = "failed or stolen" if metric == "failed_or_stolen" else "not parked"
        exact_col = EXACT_COLUMN[col["id"].split("_")[0]]
        cells = {}
        for row in suite["rows"]:
            folder = out / col["id"] / row["id"]
            if not records_file(folder).is_file():
                continue
            cells[row["id"]] = (row, _by_key(read_results(records_file(folder))))
        if not cells:
            continue
        lines += [f"### {col['title']}", "",
                  f"| row | n | {what}, noisy | exact, same seeds | p (noisy vs exact) | blind, noisy, same seeds | "
                  "p (vs blind) | at fault, noisy / exact | minADE / minFDE (m) | minFDE noisy / exact |",
                  "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"]
        blind = cells.get("blind", (None, {}))[1]
        for rid, (row, recs) in cells.items():
            spec = headline.get("committed", {}).get(exact_col, {}).get(exact_row(rid))
            exact = _by_key(committed_records(spec, ROOT)[0]) if spec else {}
            n_e, k_noisy_e, k_exact, p_e = _pair(metric, recs, exact) if exact else (0, 0, 0, float("nan"))
            n_b, k_noisy_b, k_blind, p_b = _pair(metric, recs, blind) if blind and rid != "blind" else (0, 0, 0,
                                                                                                        float("nan"))
            fde_n = _mean(r.get("min_fde") for r in recs.values())
            keys = set(recs) & set(exact)
            fde_x = _mean(exact[k].get("min_fde") for k in keys)
            ade_n = _mean(r.get("min_ade") for r in recs.values())
            k_all = sum(_bad(metric, r) for r in recs.values())
            at_fault = sum(bool(r.get("collision_at_fault")) for r in recs.values())
            fault_x = sum(bool(exact[k].get("collision_at_fault")) for k in keys)  # same seeds, exact sensing
            lines.append(
                f"| {row['label']} | {len(recs)} | {_rate(k_all, len(recs))} | "
                f"{_rate(k_exact, n_e) if n_e else '—'} | {p_e:.3f} | "
                f"{_rate(k_blind, n_b) if n_b else '—'} | {p_b:.3f} | {at_fault} / {fault_x if keys else '—'} | "
                f"{ade_n:.2f} / {fde_n:.2f} | "
                f"{fde_n / fde_x if fde_x > 0.05 else float('nan'):.2f} |".replace("nan", "—"))  # oracle: ~0 exact
        lines.append("")
        for rid in (r for r in cells if is_ablation(r)):
            base = BASE_ROW.get(rid, "bezier")
            shipped = cells.get(base, (None, {}))[1]
            if not shipped:
                continue
            n, k_row, k_shipped, p = _pair(metric, cells[rid][1], shipped)
            shared = set(cells[rid][1]) & set(shipped)
            f_row, f_shipped = (sum(bool(recs[k].get("collision_at_fault")) for k in shared)
                                for recs in (cells[rid][1], shipped))
            against = "the shipped default" if base == "bezier" else f"row `{base}`"
            lines += [f"Row `{rid}` against {against} under the same noise, {n} paired episodes: {what} "
                      f"{_rate(k_row, n)} against {_rate(k_shipped, n)} (exact McNemar p = {p:.3f}); at fault "
                      f"{f_row} against {f_shipped}.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--columns", default="")
    args = ap.parse_args(argv)
    print(table(args.out, [c for c in args.columns.split(",") if c] or None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
