"""The ``avp experiment`` command line: its arguments (:func:`add_arguments`; the runner is :mod:`.runner`)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from avp_episode.run_config import DEFAULT_HORIZON
from avp_experiment.transports import transport_names

#: --mode -> which agent modes run (reactive: True)
MODES = {"reactive": (True,), "non-reactive": (False,), "both": (False, True)}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenarios", type=int, default=500,
                   help="number of scenarios per mode [500, §VI-B]: the first seeds >= --seed-base that the §VI-A "
                   "generator can build")
    p.add_argument("--seed-base", type=int, default=0, help="first seed")
    p.add_argument("--mode", choices=tuple(MODES), default="both", help="reactive and/or non-reactive agents")
    p.add_argument("--methods", default="all",
                   help="comma-separated method profiles (names of config/methods/ or files), or 'all'")
    p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 1)),
                   help="worker processes for --transport inproc (0: run in this process)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="where --transport inproc runs its episodes: local worker processes, or one Ray task each "
                   "(docs/experiment.md 'On a Ray cluster')")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="--backend ray: the cluster to join (default: a private Ray instance with --workers CPUs)")
    p.add_argument("--out", default=str(Path("out") / "experiment"), help="output folder [out/experiment]")
    p.add_argument("--transport", choices=transport_names(), default="inproc",
                   help="inproc: simulator and ego cores in worker processes; ros: the live DDS graph (avp_bringup's "
                        "plugin; others: entry-point group avp.experiment_transports)")
    p.add_argument("--t-final", type=float, default=100.0, help="episode time limit t_f [s] (§VI-A: 100)")
    p.add_argument("--ade-horizon", type=float, default=DEFAULT_HORIZON, help="minADE/minFDE horizon H [s]")
    p.add_argument("--intent-weights", default="", help="intent CNN weights (default: shipped, else random)")
    p.add_argument("--intent-seed", type=int, default=0, help="seed of random intent weights")
    p.add_argument("--lot", default="", metavar="FILE",
                   help="lot map YAML to simulate and plan on (default: the bundled paper lot); the scenario roles "
                   "come from its scenario: block or its geometry (docs/world.md, 'Any lot')")
    p.add_argument("--sim-param", action="append", metavar="KEY=VALUE",
                   help="override an avp_sim parameter for every episode (repeatable), e.g. the earlier scenario "
                   "reading: --sim-param scenario.maneuver_max_speed=2.0 --sim-param scenario.outer_row_max=9")
    p.add_argument("--protocol", default="default",
                   help="experiment protocol (config/protocols/: default, paper, ... or a file): avp_sim and "
                   "avp_planner values shared by every method (docs/experiment.md)")
    p.add_argument("--planner-param", action="append", metavar="KEY=VALUE",
                   help="override an avp_planner parameter for every method (repeatable), after the protocol's")
    p.add_argument("--tracker-param", action="append", metavar="KEY=VALUE",
                   help="override an avp_tracking parameter of the tracker between noisy sensing and the ego "
                   "(repeatable; `avp params avp_tracker`), e.g. --tracker-param tracking.coast_deceleration=4")
    p.add_argument("--sweep", metavar="KEY=V1,V2,...",
                   help="run the whole table once per value of one avp_sim or avp_planner parameter (into "
                   "OUT/<KEY>=<V>/) and plot the rates against it (OUT/sweep.png, OUT/sweep.md)")
    p.add_argument("--ablation", action="store_true",
                   help="run the table once per safety-extras variant (all_on, all_off, no_<extra>) into "
                   "OUT/<variant>/ and tabulate them (OUT/ablation.md)")
    p.add_argument("--suite", metavar="NAME|FILE",
                   help="run a suite of experiments (config/suites/: headline, the README's results table; fleet, "
                   "the fleet grid) into OUT/<column>/<row>/ and tabulate it (OUT/<suite>.md); --workers/--backend "
                   "apply to each")
    p.add_argument("--quick", action="store_true",
                   help="with --suite: each column's small scenario count (minutes; make results QUICK=1)")
    p.add_argument("--columns", default="", metavar="ID,ID,...",
                   help="with --suite: run only these columns (the table still shows every column run so far)")
    p.add_argument("--rows", default="", metavar="ID,ID,...",
                   help="with --suite: run only these rows (say --columns fleet --rows nawaz,learned)")
    p.add_argument("--egos", type=int, default=1,
                   help="automated cars per episode (1-8): each method of --methods runs as a fleet of this many "
                   "(in process; docs/world.md 'Several egos'); a record per ego")
    p.add_argument("--fleet", default="", metavar="M1,M2,...",
                   help="one mixed fleet instead of --methods: a method per ego, e.g. bezier,bezier,blind,blind")
    p.add_argument("--float64-messages", action="store_true",
                   help="do not round beliefs/intentions to the float32 of the messages (inproc only differs)")
    p.add_argument("--episode-timeout", type=float, default=600.0, help="ros: wall seconds per episode")
    p.add_argument("--summary-only", action="store_true", help="only rewrite the summary from the results file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
