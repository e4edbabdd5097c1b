"""Table I of the paper (Chung et al., §VI-C): 500 scenarios per mode, non-reactive and reactive agents.

Rates in %; every other entry (mean, std). Transcribed from ``chung2026-selecting-spots.tex``.
Columns: success (%), spots stolen (%), interrupted timesteps, spot-selection time (s), path-planning
time (s), parking time (s), minADE (m), minFDE (m).
"""

from __future__ import annotations

COLUMNS = ("success", "spot_stolen", "interrupted_steps", "spot_selection_time", "path_planning_time",
           "parking_time", "min_ade", "min_fde")
EPISODES_PER_MODE = 500

TABLE_I: dict[str, dict[str, dict[str, float | tuple[float, float]]]] = {
    "non_reactive": {
        "bezier": {"success": 99.8, "spot_stolen": 0.0, "interrupted_steps": (0.000, 0.000),
                   "spot_selection_time": (0.0052, 0.0026), "path_planning_time": (1.2812, 0.2516),
                   "parking_time": (20.1, 9.6), "min_ade": (2.02, 1.22), "min_fde": (2.40, 1.89)},
        "constant_velocity": {"success": 92.0, "spot_stolen": 0.2, "interrupted_steps": (0.000, 0.000),
                              "spot_selection_time": (0.0058, 0.0031), "path_planning_time": (1.2848, 0.2479),
                              "parking_time": (19.3, 9.2), "min_ade": (3.09, 1.33), "min_fde": (5.59, 2.32)},
        "hybrid_astar": {"success": 94.6, "spot_stolen": 0.0, "interrupted_steps": (0.000, 0.000),
                         "spot_selection_time": (0.7360, 0.3257), "path_planning_time": (1.3435, 0.2825),
                         "parking_time": (20.1, 9.7), "min_ade": (2.46, 1.39), "min_fde": (3.81, 2.04)},
        "learned": {"success": 96.4, "spot_stolen": 0.2, "interrupted_steps": (0.000, 0.000),
                    "spot_selection_time": (0.0535, 0.0278), "path_planning_time": (1.3476, 0.2717),
                    "parking_time": (20.9, 10.5), "min_ade": (1.82, 1.16), "min_fde": (2.46, 1.63)},
        "implicit": {"success": 90.4, "spot_stolen": 0.2, "interrupted_steps": (0.000, 0.000),
                     "spot_selection_time": (0.0006, 0.0000), "path_planning_time": (2.9143, 1.5890),
                     "parking_time": (21.1, 8.8), "min_ade": (2.77, 1.30), "min_fde": (5.00, 2.30)},
        "nawaz": {"success": 90.8, "spot_stolen": 0.0, "interrupted_steps": (0.000, 0.000),
                  "spot_selection_time": (0.0010, 0.0001), "path_planning_time": (1.5907, 0.4023),
                  "parking_time": (19.4, 9.4), "min_ade": (3.13, 1.35), "min_fde": (5.64, 2.33)},
    },
    "reactive": {
        "bezier": {"success": 100.0, "spot_stolen": 0.0, "interrupted_steps": (0.072, 0.599),
                   "spot_selection_time": (0.0052, 0.0027), "path_planning_time": (0.7564, 0.1698),
                   "parking_time": (20.4, 9.4), "min_ade": (2.02, 1.22), "min_fde": (2.39, 1.88)},
        "constant_velocity": {"success": 99.0, "spot_stolen": 2.8, "interrupted_steps": (0.870, 8.316),
                              "spot_selection_time": (0.0057, 0.0031), "path_planning_time": (0.7621, 0.1796),
                              "parking_time": (19.2, 8.8), "min_ade": (2.98, 1.23), "min_fde": (5.38, 2.18)},
        "hybrid_astar": {"success": 98.4, "spot_stolen": 2.8, "interrupted_steps": (0.672, 8.216),
                         "spot_selection_time": (0.4274, 0.2041), "path_planning_time": (0.7966, 0.1907),
                         "parking_time": (20.0, 9.1), "min_ade": (2.39, 1.28), "min_fde": (3.75, 1.92)},
        "learned": {"success": 99.0, "spot_stolen": 4.4, "interrupted_steps": (0.824, 11.032),
                    "spot_selection_time": (0.0529, 0.0266), "path_planning_time": (0.8062, 0.2205),
                    "parking_time": (20.7, 10.1), "min_ade": (1.80, 1.16), "min_fde": (2.46, 1.64)},
        "implicit": {"success": 98.6, "spot_stolen": 3.4, "interrupted_steps": (0.208, 1.022),
                     "spot_selection_time": (0.0006, 0.0000), "path_planning_time": (1.6834, 0.8825),
                     "parking_time": (20.9, 8.5), "min_ade": (2.52, 1.01), "min_fde": (4.59, 1.86)},
        "nawaz": {"success": 98.8, "spot_stolen": 4.6, "interrupted_steps": (0.408, 7.334),
                  "spot_selection_time": (0.0010, 0.0001), "path_planning_time": (1.0238, 0.3210),
                  "parking_time": (19.2, 9.0), "min_ade": (2.90, 1.16), "min_fde": (5.28, 2.06)},
    },
}
