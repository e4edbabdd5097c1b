"""Where a requested scenario may come from: served directories or the request's own text.

The simulator's ``reset_episode`` service is open to any process on the DDS domain, so a scenario named in a
request is never opened as given. A name is looked up only inside the directories the simulator is configured to
serve (the bundled ``share/avp_sim/config/scenarios`` and the ``scenario_dir`` parameter); the path is resolved
(symlinks, ``..``) before the check, so nothing outside them is read, and the answer for a path outside them is the
same whether or not it exists (no existence oracle). Only regular files, at most ``max_bytes`` read. A scenario can
also come as YAML text in the request (``scenario_yaml``), with the same size cap. Errors name the field at fault
(``scenario_file`` / ``scenario_yaml``) and never quote the file's content: YAML errors give line, column and the
parser's problem only.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

from avp_scenario.scenario import ScenarioError
from avp_world.safe_yaml import YamlInputError, load_bounded, read_bounded

DEFAULT_MAX_BYTES = 1_000_000
#: YAML nodes and nesting a scenario may have (docs/bad_input.md row 50): 5 000 vacant spot ids + 64 vehicles x 11 nodes
#: fit three times over; a larger or deeper request is refused after at most this many parser events (< 20 ms)
MAX_SCENARIO_NODES = 16_384
MAX_SCENARIO_DEPTH = 8


def bundled_scenario_dir() -> Path | None:
    """``share/avp_sim/config/scenarios`` of the installed package (None outside a sourced workspace)."""
    try:
        from ament_index_python.packages import get_package_share_directory

        d = Path(get_package_share_directory("avp_sim")) / "config" / "scenarios"
        return d if d.is_dir() else None
    except Exception:  # noqa: BLE001 - not installed: no bundled directory
        return None


def served_dirs(extra: str = "") -> list[Path]:
    """The absolute directories scenario files may come from: the bundled one and ``extra`` ("" = none)."""
    dirs = [d for d in (bundled_scenario_dir(), Path(extra) if extra else None) if d is not None]
    return [Path(os.path.normpath(os.path.abspath(d))) for d in dirs]


def resolve_scenario_file(name: str, dirs: list[Path]) -> Path:
    """The served regular file called ``name`` (relative: looked up in ``dirs`` in order; absolute: must lie in
    one of them). The requested path is checked lexically — no ``..`` part, inside a served directory — before
    anything is opened; links placed inside a served directory by whoever configured it are followed. The answer
    for a path outside is the same whether it exists or not. ScenarioError naming ``scenario_file`` otherwise."""
    refused = ScenarioError("scenario_file: not a file of the served scenario directories (simulator parameter "
                            "scenario_dir); send the scenario as text in scenario_yaml instead")
    if not name or "\x00" in name or ".." in Path(name).parts:
        raise refused
    p = Path(name)
    candidates = [Path(os.path.normpath(p))] if p.is_absolute() else [d / p for d in dirs]
    for c in candidates:
        if not any(d in c.parents for d in dirs):
            continue
        try:
            st = os.stat(c)  # follows a link placed in the served directory
        except OSError:
            continue
        if stat.S_ISREG(st.st_mode):
            return c
    raise refused


def read_capped(path: Path, max_bytes: int) -> bytes:
    """At most ``max_bytes`` of a regular file; ScenarioError naming ``scenario_file`` if it is larger."""
    data = read_bounded(path, max_bytes)
    if len(data) > max_bytes:
        raise ScenarioError(f"scenario_file: larger than {max_bytes} bytes (simulator parameter scenario_max_bytes)")
    return data


def parse_scenario_text(data: bytes | str, field: str, max_bytes: int = DEFAULT_MAX_BYTES) -> Any:
    """YAML of a scenario (:func:`avp_world.safe_yaml.load_bounded`: size, node and depth caps checked before
    anything is built, UTF-8, no aliases); ScenarioError naming ``field`` with line, column and problem only (never
    the text)."""
    try:
        return load_bounded(data, field, max_bytes, MAX_SCENARIO_NODES, MAX_SCENARIO_DEPTH)
    except YamlInputError as exc:
        raise ScenarioError(str(exc)) from None


def requested_scenario(scenario_file: str, scenario_yaml: str, dirs: list[Path],
                       max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[str, Any] | None:
    """(source name, parsed data) of a ``reset_episode`` request, or None when it names no scenario."""
    if scenario_file and scenario_yaml:
        raise ScenarioError("scenario_file, scenario_yaml: give one of them, not both")
    if scenario_yaml:
        if len(scenario_yaml.encode("utf-8", "surrogatepass")) > max_bytes:
            raise ScenarioError(f"scenario_yaml: larger than {max_bytes} bytes (simulator parameter "
                                "scenario_max_bytes)")
        return "scenario_yaml", parse_scenario_text(scenario_yaml, "scenario_yaml", max_bytes)
    if scenario_file:
        path = resolve_scenario_file(scenario_file, dirs)
        return f"scenario_file {path.name}", parse_scenario_text(read_capped(path, max_bytes), "scenario_file",
                                                                 max_bytes)
    return None
