#!/usr/bin/env python3
"""The live graph under a flood (docs/bad_input.md row 48): closed-loop step time, RSS growth and log volume.

Runs ``avp demo`` (real time by default: the simulator steps on its 1/dt wall timer, a late command means a held
step) once alone and once while bench/flood_publisher.py floods `cmd`, `observation` and `beliefs` at ``--rate``
messages a second each, and prints per run: the outcome and parking time (the episode must not change), the
demo monitor's closed-loop step time (median, p95, max: DDS source time of observation k to reception of
command k), steps answered late, each node's RSS at the start of the flood and its peak, the lines in each
node's log, and what the flooder achieved.

Usage: python bench/bench_flood.py [--seed 2] [--t-final 40] [--rate 1000] [--lockstep] [--out out/bench_flood]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

FLOODER = Path(__file__).resolve().parent / "flood_publisher.py"


def _children(pid: int) -> list[int]:
    """Every descendant process of ``pid`` (from /proc)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                parent[int(d.name)] = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def _rss_by_name(pid: int) -> dict[str, float]:
    out = {}
    for c in _children(pid):
        try:
            cmd = Path(f"/proc/{c}/cmdline").read_bytes().split(b"\0")
            status = Path(f"/proc/{c}/status").read_text()
        except OSError:
            continue
        name = next((Path(a.decode()).name for a in cmd if b"/lib/avp_" in a), None)
        if name is None:
            continue
        rss = next(int(ln.split()[1]) / 1024 for ln in status.splitlines() if ln.startswith("VmRSS:"))
        out[name] = rss
    return out


def run(seed: int, t_final: float, rate: float, lockstep: bool, out: Path) -> dict:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = env.get("ROS_DOMAIN_ID") or str(random.randint(110, 200))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "avp_bringup.cli", "demo", "--seed", str(seed), "--t-final", str(t_final),
           "--out", str(out), "--bag", str(out / "bag"), "--no-gif", "--timeout", str(10 * t_final + 120)]
    if not lockstep:
        cmd.append("--realtime")
    demo = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    flood = None
    rss: dict[str, list[float]] = {}
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(1.0):
            for name, mb in _rss_by_name(demo.pid).items():
                rss.setdefault(name, []).append(mb)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    if rate > 0:
        flood = subprocess.Popen([sys.executable, str(FLOODER), "--rate", str(rate), "--duration", "100000"],
                                 env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    text, _ = demo.communicate()
    stop.set()
    flooded = None
    if flood is not None:
        flood.send_signal(signal.SIGTERM)
        fo, fe = flood.communicate(timeout=60)
        flooded = json.loads(fo.strip().splitlines()[-1]) if fo.strip() else {"error": fe[-500:]}
    if demo.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{text[-3000:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    logs = {p.stem: sum(1 for _ in p.open()) for p in (out / "logs").glob("*.log")}
    return {"metrics": metrics, "rss_mb": rss, "log_lines": logs, "flood": flooded}


def _machine() -> str:
    load = os.getloadavg()
    return f"{platform.node()}, {os.cpu_count()} CPUs, load average " + " ".join(f"{x:.2f}" for x in load)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--t-final", type=float, default=40.0)
    ap.add_argument("--rate", type=float, default=1000.0, help="flood messages per second on each topic")
    ap.add_argument("--lockstep", action="store_true", help="lock-step instead of real time")
    ap.add_argument("--out", default="out/bench_flood")
    args = ap.parse_args()
    out = Path(args.out)
    print(f"# {_machine()} before; seed {args.seed}, {'lock-step' if args.lockstep else 'real time'}")
    print("| run | outcome | parking time s | steps | step median ms | p95 ms | max ms | late steps | wall s | "
          "RSS start → peak MB (sim, belief, prediction, planner) | log lines | flood achieved |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    results = {}
    for label, rate in (("alone", 0.0), (f"flood {args.rate:g} Hz × 3 topics", args.rate)):
        r = run(args.seed, args.t_final, rate, args.lockstep, out / ("alone" if rate == 0 else "flood"))
        results[label] = r
        m, lat = r["metrics"], r["metrics"]["closed_loop_step_time"]
        rss = ", ".join(f"{s[min(2, len(s) - 1)]:.0f} → {max(s):.0f}" for _, s in sorted(
            r["rss_mb"].items(), key=lambda kv: ["avp_sim", "avp_belief", "avp_prediction", "avp_planner"].index(
                kv[0]) if kv[0] in ("avp_sim", "avp_belief", "avp_prediction", "avp_planner") else 9))
        achieved = "" if r["flood"] is None else ", ".join(f"{v:g}" for v in r["flood"].get("rate_hz", {}).values())
        print(f"| {label} | {m['state']} | {m.get('parking_time')} | {m['steps']} | {lat.get('median_ms')} | "
              f"{lat.get('p95_ms')} | {lat.get('max_ms')} | {lat.get('late_steps', '')} | {m.get('wall_time_s')} | "
              f"{rss} | {sum(r['log_lines'].values())} | {achieved} |", flush=True)
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print(f"# {_machine()} after; raw results in {out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
