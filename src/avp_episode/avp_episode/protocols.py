"""Experiment protocols: how the episodes of every method are set up (docs/experiment.md "Protocols").

A protocol (``src/avp_episode/config/protocols/<name>.yaml``) fixes what is *not* the method: avp_sim
parameters (the scenario generator, the agents' reactivity) and avp_planner parameters shared by every method
(ego speed, idle behaviour, safety extras). It never depends on which method runs — §VI-A: "all compared methods
only differ in how they choose the ego's parking spot" — and scenario generation never reads the method.

.. code-block:: yaml

    name: paper
    description: one line
    sim:        # avp_sim parameters (`avp params avp_sim`), over the shipped sim.param.yaml
      scenario.passiveness_step: 0.5
    planner:    # avp_planner parameters, over planner.param.yaml and under each method profile's own block
      control.v_max: 3.0

``default`` (empty) is the protocol of the earlier sweeps (docs/results/table1): today's shipped parameters.
:data:`SAFETY_EXTRAS` names the planner behaviours beyond the paper's §V-D that the ablation switches
(``avp experiment --ablation``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from avp_episode.profiles import MethodProfile, ProfileError

#: planner behaviours beyond §V-D, each {parameter: (on value, off value)}; "off" is the paper's rule. The
#: defaults of planner.param.yaml have the first three on and ``reactive_agents`` (with
#: ``collision.reactive_evidence: assumed``: every agent is assumed to stop for the ego from the first step; the
#: ``wary`` planner profile waits until one has been seen to, ``lot``); the others off.
SAFETY_EXTRAS: dict[str, dict[str, tuple[Any, Any]]] = {
    # "If no safe plans were found ... the ego would stay put" (§V-D-3): no escape manoeuvre when standing still
    # is predicted to be hit
    "evasive": {"decision.evasive": (True, False)},
    # idle = stay put: no second search that treats stopped agents as static obstacles to drive around
    "detour": {"decision.dynamic_as_static_fallback": (True, False)},
    # "avoids collisions with the predicted trajectories" (§V-D-1): the same margin to every agent, also to one
    # already nearer than it
    "keep_gap": {"collision.keep_current_gap": (True, False)},
    # the unfreezing mechanisms (docs/research/unfreezing.md; off in planner.param.yaml, the ablation did not pick
    # them): "the ego would stay put" while any prediction blocks — a) a car that stands or brakes with the ego ahead of
    # it is predicted to keep standing (§III-B's reactive agents); b) beyond a 1 s commit window a plan is blocked only
    # by hypotheses whose probabilities sum to more than collision.risk_bound
    "yielding": {"decision.assume_yielding": (True, False)},
    "commit_window": {"collision.commit_horizon": (1.0, 0.0)},
    # d) after standing decision.stuck_time, creep along the best blocked plan while its next 2 s are clear
    "deadlock_breaker": {"decision.deadlock_breaker": (True, False)},
    # "avoids collisions with the predicted trajectories" (§V-D-1) as if each agent went on whatever the ego does:
    # the agents stop for the ego as §III-B's do (look-ahead 2 steps, avp_collision.reactive), on in planner.param.yaml
    # for every agent from the first step (collision.reactive_evidence: assumed)
    "reactive_agents": {"collision.reactive_steps": (2, 0)},
    # c) "wait-and-go" (Nawaz et al.) waits before starting only: wait at a stop on the path instead
    "wait_anywhere": {"decision.wait_anywhere": (True, False)},
    # e) "the ego would stay put" (§V-D-3) also where a standing car waits for it: step out of its way
    "make_way": {"decision.make_way": (True, False)},
    # the same sentence for two egos of a fleet that wait for each other: the one that entered later gives way to the
    # other's announced path (a message between egos, avp_planner.core.ego_yield; on in planner.param.yaml, inert
    # with one ego)
    "ego_yield": {"decision.ego_yield": (True, False)},
    # "If this path also avoids collisions with the predicted trajectories" (§V-D-1), re-checked whole every step:
    # keep driving a plan whose first meeting is more than 2 s ahead (debouncing)
    "keep_plan": {"decision.keep_plan_window": (2.0, 0.0)},
    # "avoids collisions with the predicted trajectories" (§V-D-1), every hypothesis >= mu: only each agent's most
    # probable one
    "most_likely": {"collision.hypotheses": ("most_likely", "all")},
    # the same sentence, for a car driving away from the ego: straight on (constant velocity) instead of its curves
    "receding_straight": {"collision.receding": ("straight", "hypotheses")},
    # with the reaction assumed for an agent (reactive_agents), it is predicted where it is, as blind predicts all
    "reactive_hold": {"collision.reactive_model": ("hold", "rollout")},
}


@dataclass(frozen=True)
class Protocol:
    name: str
    description: str = ""
    sim: dict[str, Any] = field(default_factory=dict)
    planner: dict[str, Any] = field(default_factory=dict)
    source: str = ""


def protocols_dir() -> Path:
    """The shipped protocols (package share directory, else the source tree)."""
    from avp_episode.profiles import methods_dir

    return methods_dir().parent / "protocols"


def protocol_names() -> list[str]:
    return sorted(p.stem for p in protocols_dir().glob("*.yaml"))


def load_protocol(name_or_path: str) -> Protocol:
    """A shipped protocol by name or a protocol file; ProfileError names the file and the field."""
    from avp_episode.profiles import _flatten, _planner_specs, checked_params, read_config_yaml
    from avp_sim.params import SIM_PARAMS

    p, data = read_config_yaml(name_or_path, protocols_dir(), "protocol", protocol_names())
    if not isinstance(data, dict) or not isinstance(data.get("name"), str):
        raise ProfileError(f"{p}: a protocol is a mapping with a string field 'name'")
    unknown = sorted(set(data) - {"name", "description", "sim", "planner"})
    if unknown:
        raise ProfileError(f"{p}: field '{unknown[0]}': unknown key (known: description, name, planner, sim)")
    out: dict[str, dict[str, Any]] = {}
    for block, specs in (("sim", {s.name: s for s in SIM_PARAMS}), ("planner", _planner_specs())):
        raw = data.get(block) or {}
        if not isinstance(raw, dict):
            raise ProfileError(f"{p}: field '{block}': expected a mapping of parameters")
        out[block] = checked_params(_flatten(raw), specs, str(p), block, f"avp_{block}")
    return Protocol(name=data["name"], description=str(data.get("description", "")), sim=out["sim"],
                    planner=out["planner"], source=str(p))


def apply_planner(profile: MethodProfile, *layers: dict[str, Any]) -> MethodProfile:
    """The profile with the protocol's (then the command line's) planner parameters under its own block: the
    method's own keys win, but a method profile that sets a key a layer sets is refused (a method must not change
    the shared set-up)."""
    merged: dict[str, Any] = {}
    for layer in layers:
        merged.update(layer)
    clash = sorted(set(merged) & set(profile.planner))
    if clash:
        raise ProfileError(f"{profile.source}: field 'planner.{clash[0]}': set by the protocol for every method; "
                           "a method profile may not change it")
    return replace(profile, planner={**merged, **profile.planner})


def ablation_variants(extras: dict[str, dict[str, tuple[Any, Any]]] = SAFETY_EXTRAS) -> dict[str, dict[str, Any]]:
    """Named planner overrides: ``all_on``, ``all_off`` (the paper's §V-D) and ``no_<extra>`` (that one off)."""
    on = {k: v[0] for e in extras.values() for k, v in e.items()}
    off = {k: v[1] for e in extras.values() for k, v in e.items()}
    variants = {"all_on": on, "all_off": off}
    for name, params in extras.items():
        variants[f"no_{name}"] = {**on, **{k: v[1] for k, v in params.items()}}
    return variants
