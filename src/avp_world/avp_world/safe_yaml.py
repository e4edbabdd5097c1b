"""YAML from files and requests that may be hostile (docs/bad_input.md rows 36 and 50): bounded size, nodes and
nesting, UTF-8, no aliases — each checked before any Python object is built.

``yaml.safe_load`` constructs no objects, but an alias bomb ("billion laughs": nested anchors referenced many
times) still yields a structure whose walk or ``repr`` takes exponential time and memory, and building the
objects of a large document is the expensive part of parsing (500 KB of 10 000 vehicles: 0.8 s with the pure-Python
loader, 0.16 s with libyaml's, 3 s on a machine half as fast). :func:`load_bounded` therefore

1. refuses more than ``max_bytes`` and non-UTF-8 text;
2. walks the parser's *event stream* (libyaml's C parser where PyYAML has it, the pure-Python one otherwise),
   which is produced lazily and builds no document, and stops at the first alias, at more than ``max_nodes``
   nodes (scalars, sequences, mappings) or at nesting deeper than ``max_depth`` — so a refusal costs at most
   ``max_nodes`` events, whatever the size of the text (a 500 KB list of 10 000 vehicles is refused after
   16 384 events, a 5 000-deep list after 33);
3. only then builds the document, with libyaml's ``CSafeLoader`` where present (``SafeLoader`` otherwise).

Errors give line, column and the parser's problem — never the text itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent, CollectionEndEvent, CollectionStartEvent, NodeEvent

#: libyaml's loader where PyYAML was built with it (the wheels are), else the pure-Python one
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
HAVE_LIBYAML = SAFE_LOADER is not yaml.SafeLoader
DEFAULT_MAX_NODES = 1_000_000
DEFAULT_MAX_DEPTH = 32


class YamlInputError(ValueError):
    """The text is too large, not UTF-8, not YAML, too big or deep a document or uses aliases; the message names
    ``source``."""


class _TooBig(YamlInputError):
    """More nodes or deeper nesting than allowed (a limit, not a syntax error)."""


def _where(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""


def check_events(text: str, max_nodes: int, max_depth: int, loader: type = SAFE_LOADER) -> int:
    """Walk the event stream of ``text``; :class:`YamlInputError` (without a source) at the first alias, node
    ``max_nodes + 1`` or nesting level ``max_depth + 1``. Returns the number of nodes. Builds no document."""
    parser = loader(text)
    nodes = depth = 0
    try:
        while parser.check_event():
            ev = parser.get_event()
            if isinstance(ev, AliasEvent):
                raise YamlInputError(f"{_where(ev.start_mark)}YAML aliases (*name) are not allowed here")
            if isinstance(ev, NodeEvent):
                nodes += 1
                if nodes > max_nodes:
                    raise _TooBig(f"{_where(ev.start_mark)}more than {max_nodes} YAML nodes (scalars, lists, "
                                         "mappings); at most that many are read")
            if isinstance(ev, CollectionStartEvent):
                depth += 1
                if depth > max_depth:
                    raise _TooBig(f"{_where(ev.start_mark)}nested deeper than {max_depth} levels")
            elif isinstance(ev, CollectionEndEvent):
                depth -= 1
    finally:
        parser.dispose()
    return nodes


def load_bounded(data: bytes | str, source: str, max_bytes: int, max_nodes: int = DEFAULT_MAX_NODES,
                 max_depth: int = DEFAULT_MAX_DEPTH) -> Any:
    """Parse ``data``; :class:`YamlInputError` ``"<source>: ..."`` for anything but plain YAML of at most
    ``max_bytes``, ``max_nodes`` nodes and ``max_depth`` levels (checked in that order, before building)."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data
    if len(raw) > max_bytes:
        raise YamlInputError(f"{source}: larger than {max_bytes} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlInputError(f"{source}: not UTF-8 text (byte {exc.start})") from None
    try:
        check_events(text, max_nodes, max_depth)
        return yaml.load(text, Loader=SAFE_LOADER)  # noqa: S506 - a safe loader (C or Python)
    except _TooBig as exc:
        raise YamlInputError(f"{source}: refused unread ({exc})") from None
    except YamlInputError as exc:
        raise YamlInputError(f"{source}: not valid YAML ({exc})") from None
    except yaml.MarkedYAMLError as exc:
        raise YamlInputError(f"{source}: not valid YAML ({_where(exc.problem_mark)}"
                             f"{exc.problem or 'syntax error'})") from None
    except yaml.YAMLError:
        raise YamlInputError(f"{source}: not valid YAML") from None


def read_bounded(path: Path, max_bytes: int) -> bytes:
    """At most ``max_bytes`` + 1 bytes of ``path`` (so that a larger file is detected without reading it all)."""
    with open(path, "rb") as f:
        return f.read(max_bytes + 1)
