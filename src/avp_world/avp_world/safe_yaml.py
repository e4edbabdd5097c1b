"""YAML from files and requests that may be hostile (issue #20 item 3): bounded size, UTF-8, no aliases.

``yaml.safe_load`` constructs no objects, but an alias bomb ("billion laughs": nested anchors referenced many
times) still yields a structure whose walk or ``repr`` takes exponential time and memory, and a 50 MB file takes
the pure-Python parser tens of seconds. :func:`load_bounded` reads at most ``max_bytes``, refuses anchors/aliases
(no map or scenario of ours needs them) and reports errors with line, column and the parser's problem — never
the text itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent


class YamlInputError(ValueError):
    """The text is too large, not UTF-8, not YAML or uses aliases; the message names ``source``."""


class _NoAliasLoader(yaml.SafeLoader):
    def compose_node(self, parent, index):  # noqa: ANN001 - PyYAML's signature
        if self.check_event(AliasEvent):
            mark = self.peek_event().start_mark
            raise YamlInputError(f"line {mark.line + 1}, column {mark.column + 1}: YAML aliases (*name) are not "
                                 "allowed here")
        return super().compose_node(parent, index)


def load_bounded(data: bytes | str, source: str, max_bytes: int) -> Any:
    """Parse ``data``; :class:`YamlInputError` ``"<source>: ..."`` for anything but plain YAML of at most
    ``max_bytes``."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data
    if len(raw) > max_bytes:
        raise YamlInputError(f"{source}: larger than {max_bytes} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlInputError(f"{source}: not UTF-8 text (byte {exc.start})") from None
    try:
        return yaml.load(text, Loader=_NoAliasLoader)  # noqa: S506 - a SafeLoader subclass
    except YamlInputError as exc:
        raise YamlInputError(f"{source}: not valid YAML ({exc})") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        raise YamlInputError(f"{source}: not valid YAML ({where}{exc.problem or 'syntax error'})") from None
    except yaml.YAMLError:
        raise YamlInputError(f"{source}: not valid YAML") from None


def read_bounded(path: Path, max_bytes: int) -> bytes:
    """At most ``max_bytes`` + 1 bytes of ``path`` (so that a larger file is detected without reading it all)."""
    with open(path, "rb") as f:
        return f.read(max_bytes + 1)
