"""How well could any predictor do on the held-out traffic? A Bayes observer that knows the driver model.

For the samples of goal-directed parkers (``training/traffic.py``), the posterior over the spots the driver chose
among at the entrance, given where the car is on its route now and how it is moving:

    P(g | x) ∝ w_g · P(stop | g) · L(x | g, stop)

* w_g: the driver's own choice weights (exp(-d / L) with *its* L, x far_factor; the options free at *its*
  estimated arrival) — privileged: no observer knows L or the future departures;
* the stop before / after the spot: p_stop_before, or certain when only one of the two fits the lane (the
  generator's fall-back, brake distance from the driver's own cruise speed — privileged);
* L: the route to g must pass the car's current lane (shortest routes from the entrance form a tree), and
  - cruising: the roll has not begun, slow_distance ~ U[6, 12] m < the route length left to g's maneuver start:
    clip((rem - 6) / 6, 0, 1);
  - rolling: the roll began at s_roll (known exactly, even when it lies beyond the 4 s history — privileged):
    g's maneuver start lies 6-12 m after it (density 1/6) and not behind the car;
  - stopped at the maneuver start or maneuvering: counted as right.
The option probabilities map to the sample's options (its candidates; "none" = every other spot), the oracle
answers the most probable. Leaving cars, explorers and wanderers are not modelled: reported with the CNN's figure
beside them. Route positions use lane coordinates (turn arcs are a little shorter): approximate near junctions.

Usage: ``python -m avp_training.oracle OUT/data/test.npz [--weights FILE]`` (the held-out split).
"""

from __future__ import annotations

import numpy as np

from avp_scenario.maneuvers import ManeuverKey
from avp_traffic.lanes import A_DEC
from avp_traffic.traffic import PARK, AgentPlan, TrafficGenerator, TrafficParams
from avp_training.dataset import DataSpec, Samples, episode_lot

GROUPS = ("cruising", "rolling", "maneuvering", "not modelled")


class OracleEpisode:
    """One held-out episode regenerated from its seed: the generator, its plans and maneuver starts."""

    def __init__(self, seed: int, spec: DataSpec):
        self.lot, _ = episode_lot(seed, spec, np.random.default_rng([int(seed), 7]))
        self.gen = TrafficGenerator(self.lot, TrafficParams(t_final=spec.t_final))
        self.plans = self.gen.generate(seed).plans
        self._starts: dict[tuple, float | None] = {}

    def maneuver_start(self, row: int, lane: int, side: str, stop: str) -> float | None:
        """Lane coordinate where a maneuver into ``row`` from ``lane`` starts (None if there is none)."""
        key = (row, lane, side, stop)
        if key not in self._starts:
            self._starts[key] = None
            for entry in ("head_in", "tail_in"):
                man = self.gen.lib.world(row, ManeuverKey(side, stop, entry), self.gen.p.dt)
                if man is not None:
                    ln = self.gen.graph.lanes[lane]
                    self._starts[key] = float((man[0][:2] - ln.a) @ ln.d)
                    break
        return self._starts[key]

    def posterior(self, plan: AgentPlan, xy: np.ndarray) -> tuple[str, dict[int, float]]:
        """(group, {spot id: probability}) for the car of ``plan`` at ``xy``."""
        gen, g = self.gen, self.gen.graph
        p = gen.p
        route = gen.entry_routes[plan.end_lane]
        cum = np.concatenate([[0.0], np.cumsum([g.lanes[ln].length for ln in route[:-1]])])
        best = (np.inf, 0.0, -1)
        for j, ln_id in enumerate(route):  # the car's place on its route: the nearest lane point
            ln = g.lanes[ln_id]
            t = float(np.clip((xy - ln.a) @ ln.d, 0.0, ln.length))
            dist = float(np.hypot(*(ln.a + t * ln.d - xy)))
            if dist < best[0] - 1e-9:
                best = (dist, float(cum[j]) + t, ln_id)
        dist, s_car, lane_now = best
        s_end = float(cum[-1]) + plan.end_t
        if dist > 1.0 or s_car >= s_end - 0.3:
            return "maneuvering", {}
        rolling = s_end - s_car <= plan.roll_distance
        s_roll = s_end - plan.roll_distance
        lo, hi = p.slow_distance
        brake_d = plan.cruise_speed**2 / (2.0 * A_DEC) + 0.5
        post: dict[int, float] = {}
        for (row, lane, side), w in zip(plan.goal_options, plan.goal_weights, strict=True):
            seq = gen.entry_routes.get(lane)
            if seq is None or lane_now not in seq:
                continue
            t_in = g.turns[(seq[-2], lane)].t2 if len(seq) > 1 else 0.0
            fits = {}
            for stop in ("before", "after"):
                ts = self.maneuver_start(row, lane, side, stop)
                fits[stop] = ts if ts is not None and t_in + brake_d <= ts <= g.lanes[lane].length + 1.0 else None
            n_fit = sum(v is not None for v in fits.values())
            for stop, p_stop in (("before", p.p_stop_before), ("after", 1.0 - p.p_stop_before)):
                if fits[stop] is None:
                    continue
                s_t = gen.entry_dist[lane] + fits[stop]
                if rolling:
                    like = 1.0 / (hi - lo) if lo - 1e-6 <= s_t - s_roll <= hi + 1e-6 and s_t >= s_car - 0.3 else 0.0
                else:
                    like = float(np.clip((s_t - s_car - lo) / (hi - lo), 0.0, 1.0))
                sid = int(self.lot.spot_ids[row])
                post[sid] = post.get(sid, 0.0) + w * (1.0 if n_fit == 1 else p_stop) * like
        total = sum(post.values())
        return ("rolling" if rolling else "cruising"), {k: v / total for k, v in post.items()} if total > 0 else {}


def oracle_table(samples: Samples, cnn_hits: np.ndarray, spec: DataSpec = DataSpec()) -> dict:
    """Per group (GROUPS): samples, the oracle's top-1 (None where not modelled) and the CNN's."""
    group = np.full(len(samples), "not modelled", dtype=object)
    hit = np.zeros(len(samples), dtype=bool)
    unexplained = 0
    for seed in np.unique(samples.episode):
        ep = OracleEpisode(int(seed), spec)
        for i in np.nonzero(samples.episode == seed)[0]:
            plan = ep.plans.get(int(samples.vehicle[i]))
            if plan is None or plan.kind != PARK or not plan.goal_options:
                continue  # leaving cars, wanderers, explorers
            name, post = ep.posterior(plan, samples.pose[i, :2])
            group[i] = name
            if name == "maneuvering":
                hit[i] = True
                continue
            if not post:  # the model gives the observed motion no option: counted as right (an upper bound)
                unexplained += 1
                hit[i] = True
                continue
            c0, c1 = int(samples.cand_offsets[i]), int(samples.cand_offsets[i + 1])
            pc = np.array([post.get(int(c), 0.0) for c in samples.candidate_spot_ids[c0:c1]])
            hit[i] = int(np.argmax(np.concatenate([[1.0 - pc.sum()], pc]))) == int(samples.labels[i])
    rows = {}
    for name in GROUPS:
        m = group == name
        rows[name] = {"n": int(m.sum()), "oracle": float(hit[m].mean()) if m.any() and name != "not modelled" else None,
                      "cnn": float(cnn_hits[m].mean()) if m.any() else None}
    return {"groups": rows, "unexplained": unexplained, "n": len(samples),
            "cnn_top1": float(cnn_hits.mean()),
            "oracle_modelled_cnn_elsewhere": float(np.where(np.isin(group, ("cruising", "rolling")), hit,
                                                            cnn_hits).mean())}


def group_rows(t: dict, first: str = "") -> list[str]:
    """The Markdown rows of :func:`oracle_table`'s groups: name, n, the oracle's top-1, the CNN's (``first``: a
    leading cell)."""
    lead = f"| {first} " if first else ""
    return [f"{lead}| {name} | {r['n']} | {'—' if r['oracle'] is None else format(r['oracle'], '.3f')} | "
            f"{'—' if r['cnn'] is None else format(r['cnn'], '.3f')} |" for name, r in t["groups"].items()]


def main(argv: list[str] | None = None) -> int:
    from avp_training.analysis import load_split_and_logits
    from avp_training.train import topk_hits

    samples, logits, info = load_split_and_logits("python -m avp_training.oracle",
                                                  __doc__.split("\n")[0], argv)
    cnn_hits = topk_hits(logits, samples.labels, 1)
    t = oracle_table(samples, cnn_hits)
    print(f"{info}; {t['n']} samples, CNN top-1 {t['cnn_top1']:.3f}")
    print("| goal-directed parkers' samples | n | oracle top-1 | CNN top-1 |")
    print("|---|--:|--:|--:|")
    print("\n".join(group_rows(t)))
    print(f"top-1 of all with the oracle on cruising and rolling cars, the CNN elsewhere: "
          f"{t['oracle_modelled_cnn_elsewhere']:.3f} ({t['unexplained']} samples the model could not explain, "
          f"counted right)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
