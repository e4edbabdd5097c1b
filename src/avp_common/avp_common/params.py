"""Parameter specifications validated at start-up (Autoware style: the YAML file is the single source).

Each node lists its parameters as :class:`ParamSpec` rows (name, type, description, the paper's symbol
and section, allowed range/choices). :func:`declare_and_validate` declares them on a node without
defaults, so a key missing from the YAML is an error, and checks types and ranges; every problem
gives one line naming the node, the key and the parameter file. :func:`load_yaml_params` applies the
same checks to a YAML file without ROS (tests and the in-process experiment runner).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml


class ParameterError(ValueError):
    """A parameter is missing, of the wrong type or out of range."""


@dataclass(frozen=True)
class ParamSpec:
    name: str
    type: type  # float, int, bool, str, or list (list of float)
    description: str
    symbol: str = ""  # the paper's symbol, e.g. "t_f"
    section: str = ""  # e.g. "§VI-A"
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] = ()
    default: Any = None  # documented default (the shipped YAML value)


def check_value(spec: ParamSpec, value: Any, where: str) -> Any:
    """Validate one value against its spec; returns the (type-normalised) value."""
    key = f"{where}: parameter '{spec.name}'"
    if value is None:
        raise ParameterError(f"{key}: missing")
    t = spec.type
    if t is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(f"{key}: must be finite, got {value!r}")
    elif t is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"{key}: expected an integer, got {value!r}")
    elif t is bool:
        if not isinstance(value, bool):
            raise ParameterError(f"{key}: expected true/false, got {value!r}")
    elif t is str:
        if not isinstance(value, str):
            raise ParameterError(f"{key}: expected a string, got {value!r}")
    elif t is list:
        if not isinstance(value, (list, tuple)) or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value
        ):
            raise ParameterError(f"{key}: expected a list of finite numbers, got {value!r}")
        value = [float(x) for x in value]
    if spec.min is not None and t in (int, float) and value < spec.min:
        raise ParameterError(f"{key}: {value} is below the minimum {spec.min}")
    if spec.max is not None and t in (int, float) and value > spec.max:
        raise ParameterError(f"{key}: {value} is above the maximum {spec.max}")
    if spec.choices and value not in spec.choices:
        raise ParameterError(f"{key}: {value!r} is not one of {list(spec.choices)}")
    return value


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, name + "."))
        else:
            out[name] = v
    return out


def load_yaml_params(path: str | Path, node_name: str, specs: list[ParamSpec]) -> dict[str, Any]:
    """Read ``/**`` or ``<node_name>`` -> ``ros__parameters`` from a ROS 2 parameter file and validate."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"{p}: cannot read parameter file ({exc})") from None
    if not isinstance(data, dict):
        raise ParameterError(f"{p}: top level must be a mapping")
    values: dict[str, Any] = {}
    for key in ("/**", node_name, "/" + node_name):
        block = data.get(key)
        if isinstance(block, dict):
            params = block.get("ros__parameters")
            if not isinstance(params, dict):
                raise ParameterError(f"{p}: {key}: missing 'ros__parameters'")
            values.update(_flatten(params))
    return validate_values(values, specs, f"{p} [{node_name}]")


def validate_values(values: dict[str, Any], specs: list[ParamSpec], where: str) -> dict[str, Any]:
    known = {s.name for s in specs}
    unknown = sorted(set(values) - known - {"use_sim_time"})
    if unknown:
        raise ParameterError(f"{where}: parameter '{unknown[0]}': unknown key")
    return {s.name: check_value(s, values.get(s.name), where) for s in specs}


def declare_and_validate(node, specs: list[ParamSpec], param_file: str = "") -> dict[str, Any]:
    """Declare ``specs`` on an rclpy node (no defaults: the YAML must give every key) and validate.

    Every parameter is declared **read-only**: the nodes read their parameters once (at start-up or lifecycle
    configure), so a value set later from another process would be reported but never run with. A
    ``set_parameters`` call is refused by rclpy with a reason naming the parameter (docs/bad_input.md)."""
    from rcl_interfaces.msg import ParameterDescriptor

    where = f"node '{node.get_name()}'" + (f" (params file {param_file})" if param_file else "")
    values = {}
    for s in specs:
        desc = ParameterDescriptor(description=s.description, dynamic_typing=True, read_only=True)
        param = node.declare_parameter(s.name, None, desc)
        values[s.name] = param.value
    return {s.name: check_value(s, values[s.name], where) for s in specs}


def markdown_table(specs: list[ParamSpec]) -> str:
    """Table of docs/parameters.md: parameter | type | default | paper | description."""
    rows = ["| parameter | type | default | paper | description |", "|---|---|---|---|---|"]
    for s in specs:
        rng = ""
        if s.min is not None or s.max is not None:
            rng = f" Range [{s.min if s.min is not None else '-inf'}, {s.max if s.max is not None else 'inf'}]."
        if s.choices:
            rng = f" One of {', '.join(s.choices)}."
        paper = " ".join(x for x in (f"`{s.symbol}`" if s.symbol else "", s.section) if x)
        desc = s.description + ("." if rng and s.description and not s.description.endswith(".") else "")
        rows.append(f"| `{s.name}` | {s.type.__name__} | `{s.default}` | {paper} | {desc}{rng} |")
    return "\n".join(rows)


# ------------------------------------------------------------------- parameters from settings dataclasses


def _field_comments(cls) -> dict[str, str]:
    """Trailing ``# comments`` of a dataclass's field lines (the settings' documentation)."""
    import inspect
    import re

    try:
        src = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    out = {}
    for line in src.splitlines():
        m = re.match(r"\s+(\w+)\s*:\s*[^=]+=.*?#\s*(.+)$", line)
        if m:
            out[m.group(1)] = m.group(2).strip()
    return out


def _init_fields(instance, prefix: str):
    """(field, value, dotted name) of each init field of a settings dataclass."""
    import dataclasses

    for f in dataclasses.fields(instance):
        if f.init:
            yield f, getattr(instance, f.name), f"{prefix}{f.name}"


def specs_from_dataclass(instance, prefix: str = "") -> list[ParamSpec]:
    """One :class:`ParamSpec` per leaf field of a (nested) frozen settings dataclass, named ``a.b.c``.

    Types follow the default values (tuples of numbers become lists); descriptions are the trailing
    comments of the field lines, so the settings class is the single source of the parameter table.
    """
    import dataclasses

    specs: list[ParamSpec] = []
    docs = _field_comments(type(instance))
    for f, value, name in _init_fields(instance, prefix):
        if dataclasses.is_dataclass(value):
            specs += specs_from_dataclass(value, name + ".")
            continue
        if isinstance(value, bool):
            t = bool
        elif isinstance(value, int):
            t = int
        elif isinstance(value, float):
            t = float
        elif isinstance(value, str):
            t = str
        elif isinstance(value, (tuple, list)):
            t = list
            value = [float(x) for x in value]
        else:
            continue
        specs.append(ParamSpec(name, t, docs.get(f.name, ""), default=value))
    return specs


def dataclass_from_values(instance, values: dict[str, Any], prefix: str = ""):
    """A copy of ``instance`` with leaf fields replaced by ``values[prefix + name]`` where present."""
    import dataclasses

    changes = {}
    for f, value, name in _init_fields(instance, prefix):
        if dataclasses.is_dataclass(value):
            changes[f.name] = dataclass_from_values(value, values, name + ".")
        elif name in values:
            v = values[name]
            changes[f.name] = tuple(v) if isinstance(value, tuple) else v
    return dataclasses.replace(instance, **changes)


def yaml_block(specs: list[ParamSpec]) -> str:
    """``/**: ros__parameters:`` YAML with every spec's default, nested by the dotted names."""
    tree: dict = {}
    for s in specs:
        node = tree
        *parents, leaf = s.name.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = s.default
    return yaml.safe_dump({"/**": {"ros__parameters": tree}}, sort_keys=False, default_flow_style=False)
