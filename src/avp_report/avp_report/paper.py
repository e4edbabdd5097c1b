"""Table I of the paper (Chung et al., §VI-C): 500 scenarios per mode, non-reactive and reactive agents.

The numbers live in ``paper_table_i.csv`` beside this module (transcribed from the paper's table). Rates in %;
every other entry (mean, std). Columns: success (%), spots stolen (%), interrupted timesteps, spot-selection time
(s), path-planning time (s), parking time (s), minADE (m), minFDE (m).
"""

from __future__ import annotations

import csv
from pathlib import Path

COLUMNS = ("success", "spot_stolen", "interrupted_steps", "spot_selection_time", "path_planning_time",
           "parking_time", "min_ade", "min_fde")
RATES = ("success", "spot_stolen")
EPISODES_PER_MODE = 500
TABLE_FILE = Path(__file__).with_name("paper_table_i.csv")


def read_table(path: Path = TABLE_FILE) -> dict[str, dict[str, dict[str, float | tuple[float, float]]]]:
    """{mode: {method: {column: rate or (mean, std)}}} from the CSV (``#`` lines are comments)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    table: dict[str, dict[str, dict[str, float | tuple[float, float]]]] = {}
    for row in rows:
        table.setdefault(row["mode"], {})[row["method"]] = {
            c: float(row[f"{c}_pct"]) if c in RATES else (float(row[f"{c}_mean"]), float(row[f"{c}_std"]))
            for c in COLUMNS}
    return table


TABLE_I = read_table()
