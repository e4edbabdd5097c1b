"""Method profiles of Table I: one YAML file per method, shared by the runner and the live graph.

A profile (``src/avp_episode/config/methods/<name>.yaml``) says how a method differs from the paper's
pipeline — §VI-A: "all compared methods only differ in how they choose the ego's parking spot":

.. code-block:: yaml

    name: bezier                  # = the file name
    label: Cubic Bézier (ours)    # row label of Table I
    group: Explicit, past         # row group of Table I
    available: true               # false: listed with the paper's numbers only (unavailable_reason: why)
    perception:
      beliefs: intent             # after eq. (7): intent (eq. 8 from the intent CNN of the other vehicles),
                                  # nawaz (Nawaz et al.'s occupancy from predictions) or observation (eq. 7 only)
      predictor: bezier           # trajectory predictor of the other agents (avp_perception make_predictor)
      ego_intent: false           # true: the intent CNN on the ego's own BEV orders its candidate spots
      ground_truth: false         # true only for the oracle bound: true targets and futures (in-process only)
      intent_weights: ""          # optional: the intent CNN's weights (a file or a name in models/) this method
                                  # reads, over the run's (--intent-weights) and the belief node's file
    prediction:                   # optional: avp_prediction parameters over prediction.param.yaml (not `method`,
      mu: 0.3                     # which is perception.predictor), e.g. learned.weights for the learned model
    planner:                      # avp_planner parameters over planner.param.yaml — a planner profile
      use_beliefs: true
      use_predictions: true
    coordination: none            # several egos only: reserve = plan to spots granted by the spot-reservation
                                  # book (avp_planner.core.reservation; in-process fleets)

In the live graph a method is the same 4-node graph as always (simulator, belief node, prediction node,
planner) with per-node parameters: :func:`method_node_params` is the one mapping from a profile to them, used by
``avp launch|demo --method`` and ``avp experiment --transport ros`` (through ``avp_bringup.graph.method_graph``):

=============================  ====================================================================
profile field                  node parameter
=============================  ====================================================================
``perception.beliefs``         avp_belief ``belief_source`` (intent | nawaz | observation)
``perception.ego_intent``      avp_belief ``ego_intent`` and avp_planner ``use_ego_intention``
``perception.predictor``       avp_prediction ``method``
``perception.intent_weights``  avp_belief ``intent.weights`` (when set)
``prediction.*``               avp_prediction parameters as they are
``planner.*``                  avp_planner parameters as they are
=============================  ====================================================================

:func:`planner_profile_yaml` turns the ``planner`` block into a planner parameter file (the format of
``avp_planner/config/profiles/*.yaml``). Any problem raises :class:`ProfileError` with one line naming the
file and the field.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from avp_common.params import ParameterError, check_value

COORDINATIONS = ("none", "reserve")  # among several egos (avp_planner.core.reservation)
BELIEF_SOURCES = ("intent", "nawaz", "observation")  # = the belief node's belief_source (tests/test_experiment.py)
TABLE_ORDER = ("bezier", "constant_velocity", "hybrid_astar", "learned", "implicit", "nawaz",  # rows of Table I
               "oracle", "blind",  # reference bounds below the paper's six (docs/experiment.md)
               "reserve")  # the reference of several egos (coordination: reserve; skipped with one ego)
# The planner's wall-clock caps are its only timing-dependent knobs (search.time_cap, decision.decision_time_cap,
# decision.fallback_time_cap): the experiment lifts them so that iteration caps alone end searches and the
# same command gives the same episodes (tests/test_dds_lockstep.py does the same).
DETERMINISTIC_PLANNER = {"search.time_cap": 1.0e3, "decision.decision_time_cap": 1.0e4,
                         "decision.fallback_time_cap": 1.0e3}
DETERMINISTIC_PREDICTION = {"hybrid_astar.time_cap": 60.0}  # the Hybrid A* predictor's wall-clock safety net (its max)


class ProfileError(ValueError):
    """A method profile is missing or malformed; the message names the file and the field."""


@dataclass(frozen=True)
class MethodProfile:
    name: str
    label: str
    group: str
    available: bool
    beliefs: str
    predictor: str
    ego_intent: bool
    ground_truth: bool = False  # the oracle bound: told the true targets and futures (in-process only, .oracle)
    coordination: str = "none"  # "reserve": spots granted by the reservation book only (several egos, in-process)
    planner: dict[str, Any] = field(default_factory=dict)  # flat dotted keys
    prediction: dict[str, Any] = field(default_factory=dict)  # avp_prediction parameters, flat dotted keys
    intent_weights: str = ""  # the intent CNN's weights; "" = the run's (--intent-weights, else shipped)
    unavailable_reason: str = ""
    source: str = ""

    def planner_overrides(self) -> dict[str, Any]:
        return dict(self.planner)


def methods_dir() -> Path:
    """The shipped profiles: the package share directory, else the source tree next to this package."""
    from avp_common.share import SRC, package_share

    d = package_share("avp_episode") / "config" / "methods"
    return d if d.is_dir() else SRC / "avp_episode" / "config" / "methods"


#: directories of user method profiles (``:``-separated, like PATH), searched after the shipped ones: a plugin's
#: profile (docs/custom_predictor.md) is found by name there — also by the experiment's worker processes
METHODS_PATH_ENV = "AVP_METHODS_PATH"


def user_method_dirs() -> list[Path]:
    return [Path(d) for d in os.environ.get(METHODS_PATH_ENV, "").split(os.pathsep) if d]


def add_user_method_dir(directory: Path) -> None:
    """Put ``directory`` on :data:`METHODS_PATH_ENV` (this process and the workers it starts)."""
    dirs = user_method_dirs()
    if Path(directory).resolve() not in [d.resolve() for d in dirs]:
        os.environ[METHODS_PATH_ENV] = os.pathsep.join(str(d) for d in [*dirs, Path(directory).resolve()])


def available_names() -> list[str]:
    """Shipped profile names in Table I order (then any others alphabetically), then the user profiles'."""
    names = sorted(p.stem for p in methods_dir().glob("*.yaml"))
    user = sorted({p.stem for d in user_method_dirs() for p in d.glob("*.yaml")} - set(names))
    return [n for n in TABLE_ORDER if n in names] + [n for n in names if n not in TABLE_ORDER] + user


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _planner_specs():
    from avp_planner.params import PLANNER_PARAMS

    return {s.name: s for s in PLANNER_PARAMS}


def _prediction_specs():
    """The avp_prediction parameters a profile may set: the §V-C settings (PredictionConfig), not the node's own
    (``method`` is ``perception.predictor``; ``auth_inputs`` is the node's security, not the method's)."""
    from avp_perception.params import PREDICTION_NODE_PARAMS, PREDICTION_PARAMS

    node = {s.name for s in PREDICTION_NODE_PARAMS}
    return {s.name: s for s in PREDICTION_PARAMS if s.name not in node}


def checked_params(flat: dict[str, Any], specs: dict, source: str, block: str, node: str) -> dict[str, Any]:
    """``flat`` ({dotted key: value}) with each value checked against ``specs``; ProfileError names the field."""
    out = {}
    for key, value in flat.items():
        if key not in specs:
            raise ProfileError(f"{source}: field '{block}.{key}': not an {node} parameter")
        try:
            out[key] = check_value(specs[key], value, f"{source}: field '{block}'")
        except ParameterError as exc:
            raise ProfileError(str(exc)) from None
    return out


def profile_from_dict(data: Any, source: str) -> MethodProfile:
    """Validate a parsed profile; :class:`ProfileError` names ``source`` and the field."""
    if not isinstance(data, dict):
        raise ProfileError(f"{source}: top level must be a mapping")
    known = {"name", "label", "group", "available", "unavailable_reason", "perception", "prediction", "planner",
             "coordination"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ProfileError(f"{source}: field '{unknown[0]}': unknown key (known: {sorted(known)})")

    def req(d: dict, key: str, typ: type, where: str):
        if key not in d:
            raise ProfileError(f"{source}: field '{where}{key}': missing")
        v = d[key]
        if not isinstance(v, typ) or (typ is not bool and isinstance(v, bool)):
            raise ProfileError(f"{source}: field '{where}{key}': expected {typ.__name__}, got {v!r}")
        return v

    name = req(data, "name", str, "")
    per = req(data, "perception", dict, "")
    unknown = sorted(set(per) - {"beliefs", "predictor", "ego_intent", "ground_truth", "intent_weights"})
    if unknown:
        raise ProfileError(f"{source}: field 'perception.{unknown[0]}': unknown key")
    beliefs = req(per, "beliefs", str, "perception.")
    if beliefs not in BELIEF_SOURCES:
        raise ProfileError(f"{source}: field 'perception.beliefs': {beliefs!r} is not one of {list(BELIEF_SOURCES)}")
    planner = data.get("planner") or {}
    if not isinstance(planner, dict):
        raise ProfileError(f"{source}: field 'planner': expected a mapping of avp_planner parameters")
    flat = _flatten(planner)
    ego_intent = req(per, "ego_intent", bool, "perception.")
    ground_truth = req(per, "ground_truth", bool, "perception.") if "ground_truth" in per else False
    if "use_ego_intention" in flat and flat["use_ego_intention"] is not ego_intent:
        raise ProfileError(f"{source}: field 'planner.use_ego_intention': follows perception.ego_intent "
                           f"({ego_intent}); leave it out")
    flat = checked_params(flat, _planner_specs(), source, "planner", "avp_planner")
    prediction = data.get("prediction") or {}
    if not isinstance(prediction, dict):
        raise ProfileError(f"{source}: field 'prediction': expected a mapping of avp_prediction parameters")
    prediction = checked_params(_flatten(prediction), _prediction_specs(), source, "prediction", "avp_prediction")
    intent_weights = req(per, "intent_weights", str, "perception.") if "intent_weights" in per else ""
    coordination = req(data, "coordination", str, "") if "coordination" in data else "none"
    if coordination not in COORDINATIONS:
        raise ProfileError(f"{source}: field 'coordination': {coordination!r} is not one of {list(COORDINATIONS)}")
    return MethodProfile(
        name=name, label=str(data.get("label", name)), group=str(data.get("group", "")),
        available=req(data, "available", bool, ""), beliefs=beliefs,
        predictor=req(per, "predictor", str, "perception."), ego_intent=ego_intent, ground_truth=ground_truth,
        planner=flat, prediction=prediction, intent_weights=intent_weights,
        unavailable_reason=str(data.get("unavailable_reason", "")), source=source, coordination=coordination,
    )


def read_config_yaml(name_or_path: str | Path, directory: Path, what: str, shipped: list[str], noun: str = ""
                     ) -> tuple[Path, Any]:
    """(path, parsed YAML) of a shipped config by name (``directory/<name>.yaml``) or of a file by path;
    :class:`ProfileError` for an unknown name ("unknown ``noun`` 'x'"; default ``what``) or an unreadable file
    (``what``: 'method profile', 'protocol')."""
    s = str(name_or_path)
    p = Path(s)
    if not (s.endswith((".yaml", ".yml")) or p.is_file()):
        p = directory / f"{s}.yaml"
        if not p.is_file():
            raise ProfileError(f"unknown {noun or what} {s!r}; shipped: {shipped} ({directory})")
    try:
        return p, yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ProfileError(f"{p}: cannot read {what} ({exc})") from None


def load_profile(name_or_path: str | Path) -> MethodProfile:
    """A shipped profile by name (``bezier``), a user profile by name (a directory on ``AVP_METHODS_PATH``), or
    a profile file by path."""
    directory = methods_dir()
    s = str(name_or_path)
    if not (s.endswith((".yaml", ".yml")) or Path(s).is_file()) and not (directory / f"{s}.yaml").is_file():
        directory = next((d for d in user_method_dirs() if (d / f"{s}.yaml").is_file()), directory)
    p, data = read_config_yaml(name_or_path, directory, "method profile", available_names(), "method")
    prof = profile_from_dict(data, str(p))
    if p.parent == directory and prof.name != p.stem:
        raise ProfileError(f"{p}: field 'name': {prof.name!r} differs from the file name {p.stem!r}")
    return prof


# ------------------------------------------------------------------------------------ derived settings


def shipped_planner_values() -> dict[str, Any]:
    """avp_planner parameter values of the shipped planner.param.yaml."""
    from avp_common.params import load_yaml_params
    from avp_common.share import package_share
    from avp_planner.params import PLANNER_PARAMS

    path = package_share("avp_planner") / "config" / "planner.param.yaml"
    return load_yaml_params(path, "avp_planner", PLANNER_PARAMS)


def planner_values(profile: MethodProfile, deterministic: bool = True) -> dict[str, Any]:
    """avp_planner parameter values: the shipped planner.param.yaml, the profile's ``planner`` block, and
    (``deterministic``) the lifted wall-clock caps."""
    values = shipped_planner_values()
    values.update(profile.planner)
    if deterministic:
        values.update(DETERMINISTIC_PLANNER)
    return values


def planner_settings(profile: MethodProfile, deterministic: bool = True):
    """(PlannerSettings, use_beliefs, use_predictions) of a profile."""
    from avp_common.params import dataclass_from_values
    from avp_motion.settings import DEFAULT_SETTINGS

    v = planner_values(profile, deterministic)
    return dataclass_from_values(DEFAULT_SETTINGS, v).validate(), bool(v["use_beliefs"]), bool(v["use_predictions"])


def prediction_config(deterministic: bool = True, values: dict[str, Any] | None = None):
    """The §V-C prediction settings: the library defaults, ``values`` (a profile's ``prediction`` block) on top, the
    Hybrid A* predictor's wall-clock cap lifted when ``deterministic``."""
    from avp_common.params import dataclass_from_values
    from avp_predictors.prediction import PredictionConfig

    cfg = dataclass_from_values(PredictionConfig(), dict(values)) if values else PredictionConfig()
    if deterministic:
        names = {f.name for f in dataclasses.fields(cfg)}
        vals = {k: v for k, v in DETERMINISTIC_PREDICTION.items() if k.split(".")[0] in names}
        cfg = dataclass_from_values(cfg, vals)
    return cfg.validate()


NODE_NAMES = ("avp_belief", "avp_prediction", "avp_planner")  # the pipeline nodes of avp_bringup.graph


def method_node_params(profile: MethodProfile, *, deterministic: bool = False, intent_weights: str | None = None,
                       intent_seed: int | None = None, coordinated: bool = False) -> dict[str, dict[str, Any]]:
    """The parameters that make the live graph's pipeline nodes run ``profile`` (the table in the module
    docstring), keyed by node name: ``avp_belief``, ``avp_prediction``, ``avp_planner``; applied on top of each
    node's parameter file (and a user file). ``deterministic``: lift the wall-clock caps of the planner and the
    Hybrid A* predictor (:data:`DETERMINISTIC_PLANNER`, :data:`DETERMINISTIC_PREDICTION`). ``intent_weights`` /
    ``intent_seed``: the belief node's ``intent.weights`` / ``intent.seed`` (None: the parameter file's).
    ProfileError for a profile that cannot run (not available), or that coordinates egos (``coordination``)
    outside a fleet graph that provides the coordination (``coordinated``: avp_bringup.graph.fleet_graph)."""
    if not profile.available:
        raise ProfileError(f"method {profile.name!r} is not available: {profile.unavailable_reason}")
    if profile.coordination != "none" and not coordinated:
        raise ProfileError(f"method {profile.name!r} coordinates egos through the reservation book "
                           f"(coordination: {profile.coordination}): run it among several egos (avp launch --egos K "
                           "--methods ..., avp experiment --egos K)")
    if profile.ground_truth:
        raise ProfileError(f"method {profile.name!r} is an oracle bound (perception.ground_truth): the live graph "
                           "never feeds ground truth to the ego; run it with avp experiment --transport inproc")
    belief: dict[str, Any] = {"belief_source": profile.beliefs, "ego_intent": profile.ego_intent}
    if profile.intent_weights or intent_weights is not None:  # the method's own, else the run's
        belief["intent.weights"] = str(profile.intent_weights or intent_weights)
    if intent_seed is not None:
        belief["intent.seed"] = int(intent_seed)
    prediction: dict[str, Any] = {**profile.prediction, "method": profile.predictor}
    planner: dict[str, Any] = {**profile.planner, "use_ego_intention": profile.ego_intent}
    if deterministic:
        prediction.update(DETERMINISTIC_PREDICTION)
        planner.update(DETERMINISTIC_PLANNER)
    return {"avp_belief": belief, "avp_prediction": prediction, "avp_planner": planner}


def planner_profile_yaml(profile: MethodProfile) -> str:
    """The ``planner`` block as a ROS 2 parameter file for avp_planner (``/**: ros__parameters:``)."""
    tree: dict = {}
    for key, value in profile.planner.items():
        node = tree
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    head = f"# avp_planner parameters of method profile '{profile.name}' ({profile.source})\n"
    return head + yaml.safe_dump({"/**": {"ros__parameters": tree}}, sort_keys=False)
