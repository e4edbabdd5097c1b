"""The headline suite's tables as Markdown (:mod:`.headline` computes them): the full table of docs/results/README.md
(:func:`render`), the README's narrow ones (:func:`render_narrow`, one per ``readme`` group of columns) and the
markers they sit between (:func:`replace_block`)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

BEGIN, END = "<!-- headline:begin -->", "<!-- headline:end -->"
MAIN = "main"  # the README's first narrow table; a column's ``readme: NAME`` puts it in another


def markers(group: str = MAIN) -> tuple[str, str]:
    """The README's begin and end markers of narrow table ``group``."""
    return (BEGIN, END) if group == MAIN else (f"<!-- headline:{group}:begin -->", f"<!-- headline:{group}:end -->")


def readme_groups(table: Mapping) -> list[str]:
    """The narrow tables of ``table``'s columns, in the order they first appear."""
    return list(dict.fromkeys(c.get("readme", MAIN) for c in table["columns"]))


def _pct(s: Mapping) -> str:
    lo, hi = s["ci95"]
    return f"{s['percent']:.1f} [{lo:.1f}, {hi:.1f}] ({s['n']})"


def _cells(metric: str, s: Mapping | None) -> list[str]:
    """The Markdown cells of one (column, row): one per sub-column of the metric."""
    if s is None:
        return ["not run"] + [""] * (2 if metric == "busy" else 0)
    if metric == "failed_or_stolen":
        return [_pct(s["failed_or_stolen"]) + (f"; {s['at_fault']} at fault" if s.get("at_fault") else "")]
    if metric == "success":
        return [_pct(s["success"])]
    if metric == "busy":
        m = s["interrupted_steps"]
        return [_pct(s["success"]) + (f"; {s['at_fault']} at fault" if s["at_fault"] else ""), _pct(s["spot_stolen"]),
                f"{m['mean']:.1f} [{m['ci95'][0]:.1f}, {m['ci95'][1]:.1f}]"]
    lost = s["episodes_with_ego_loss"]
    if lost is None:  # one ego: no other ego to lose a spot to, no gridlock measured
        return [_pct(s["success"])]
    extra = [f"a spot lost to another ego in {lost['k']} of {lost['n']} episodes"]
    extra += [f"{s['ego_ego_collisions']} egos in a collision with another ego"] if s["ego_ego_collisions"] else []
    grid = s["episodes_with_gridlock"]
    extra += [f"a gridlock in {grid['k']} of {grid['n']} episodes"] if grid["k"] else []
    return [_pct(s["success"]) + "; " + ", ".join(extra)]


def render(table: Mapping) -> str:
    """The Markdown table (and its footnotes) of :func:`suite_table`'s output."""
    head, sub = ["pick"], [":--"]
    for c in table["columns"]:
        if c["metric"] == "busy":
            head += [c["title"] + ": parks", "spots lost", "interrupted steps (mean)"]
            sub += ["--:"] * 3
        else:
            head.append(c["title"])
            sub.append("--:")
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(sub) + "|"]
    notes: list[str] = []
    for row in table["rows"]:
        cells = [row["label"]]
        for c in table["columns"]:
            s = table["cells"][c["id"]].get(row["id"])
            width = 3 if c["metric"] == "busy" else 1
            if row["id"] in table["na"].get(c["id"], []):
                cells += ["–"] * width
                continue
            out = _cells(c["metric"], s)
            for note in (s or {}).get("notes", []):
                if note not in notes:
                    notes.append(note)
                out[0] += "<sup>" + str(notes.index(note) + 1) + "</sup>"
            cells += out
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    maker = "make results" if table["suite"] == "headline" else f"avp experiment --suite {table['suite']}"
    unrun = any(table["cells"][c["id"]].get(r["id"]) is None and r["id"] not in table["na"].get(c["id"], [])
                for c in table["columns"] for r in table["rows"])
    lines.append("Percent [95 % Wilson interval] (episodes); interrupted steps: mean [95 % interval]"
                 + (f"; \"not run\": no committed records at full size yet (`{maker}` makes them)" if unrun else "")
                 + "; \"–\": does not apply.")
    lines += [f"<sup>{i + 1}</sup> {n}." for i, n in enumerate(notes)]
    return "\n".join(lines) + "\n"


def _num(x: float) -> str:
    """A percentage with one decimal, 100.0 and 0.0 without it."""
    return f"{x:.0f}" if x in (0.0, 100.0) else f"{x:.1f}"


def render_narrow(table: Mapping, group: str = MAIN) -> str:
    """A README table: the columns of narrow table ``group`` (a column's ``readme``), one rate [95 % interval] a cell
    (success for the busy and fleet columns), short labels, no counts; a row that runs in none of them is left out. A
    cell made with other settings than its row's carries its note's number (the notes under the table) —
    :func:`render`'s table, with every figure behind it, is on docs/results/README.md."""
    cols = [c for c in table["columns"] if c.get("readme", MAIN) == group]
    head = ["pick"] + [c["short"] for c in cols]
    lines = ["| " + " | ".join(head) + " |", "|:--" + "|--:" * len(cols) + "|"]
    notes: list[str] = []
    for row in table["rows"]:
        if all(row["id"] in table["na"].get(c["id"], []) for c in cols):
            continue
        cells = [row["short"]]
        for c in cols:
            s = table["cells"][c["id"]].get(row["id"])
            if row["id"] in table["na"].get(c["id"], []):
                cells.append("–")
                continue
            if s is None:
                cells.append("not run")
                continue
            r = s["failed_or_stolen"] if c["metric"] == "failed_or_stolen" else s["success"]
            cell = f"{_num(r['percent'])} [{_num(r['ci95'][0])}, {_num(r['ci95'][1])}]"
            if group != MAIN and s.get("at_fault") is not None:  # what noise costs in safety, beside the rate
                cell += f"; {s['at_fault']} at fault"
            if group != MAIN:  # the main table's notes are on docs/results/README.md (its rows are at their width)
                for note in s.get("notes", []):
                    notes += [note] if note not in notes else []
                    cell += f"<sup>{notes.index(note) + 1}</sup>"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    if notes:
        lines += [""] + [f"<sup>{i + 1}</sup> {n}." for i, n in enumerate(notes)]
    return "\n".join(lines) + "\n"


def write_table(table: Mapping, json_path: Path, md_path: Path | None = None) -> None:
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
    if md_path is not None:
        md_path.write_text(render(table))


def replace_block(text: str, block: str, group: str = MAIN) -> str:
    """``text`` with what lies between the markers of narrow table ``group`` replaced by ``block``."""
    begin, end = markers(group)
    if text.count(begin) != 1 or text.count(end) != 1:
        raise ValueError(f"the README must hold {begin} and {end} once each")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{block}{end}{tail}"
