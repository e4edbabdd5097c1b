"""The documented command line agrees with the parsers: every ``avp`` sub-command and option quoted in the synopsis of
docs/cli.md and in README.md's code blocks exists in ``avp``'s argparse parser, with the choices it quotes, and every
sub-command of the parser is in docs/cli.md. (A newcomer found a synopsis listing options the runner no longer had.)"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from avp_bringup.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _options(p: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {s: a for a in p._actions for s in a.option_strings}


def _code_lines(text: str) -> list[str]:
    """The lines of the ```bash blocks."""
    return [ln for block in re.findall(r"```bash\n(.*?)```", text, re.S) for ln in block.splitlines()]


def _statements(lines: list[str]) -> list[tuple[list[str], str]]:
    """(sub-commands, the text of their options) of each ``avp ...`` statement; continuation lines (starting with
    spaces and '[') belong to the statement above. ``avp launch|demo`` names two sub-commands."""
    out: list[tuple[list[str], str]] = []
    for ln in lines:
        code = ln.split("#", 1)[0]
        m = re.match(r"\s*avp ([a-z][a-z\-|]*)(.*)", code)
        if m:
            out.append((m.group(1).split("|"), m.group(2)))
        elif out and re.match(r"\s+\[", code):
            out[-1] = (out[-1][0], out[-1][1] + " " + code)
    return out


def test_every_documented_option_exists_with_its_choices():
    parser = build_parser()
    subs = _subparsers(parser)
    checked = 0
    for doc in (ROOT / "docs/cli.md", ROOT / "README.md"):
        for names, rest in _statements(_code_lines(doc.read_text())):
            for name in names:
                assert name in subs, f"{doc.name}: `avp {name}` is not a sub-command ({sorted(subs)})"
                opts = _options(subs[name])
                for opt, value in re.findall(r"(--[a-z][a-z0-9\-]*)(?:[ =]([a-z0-9_|\-]+))?", rest):
                    assert opt in opts, f"{doc.name}: `avp {name} {opt}` is not an option of avp {name}"
                    choices = opts[opt].choices
                    if choices is not None and value and "|" in value:
                        quoted = set(value.split("|"))
                        assert quoted <= {str(c) for c in choices}, (doc.name, name, opt, quoted, choices)
                    checked += 1
    assert checked > 30
    top = _options(parser)
    for doc in (ROOT / "docs/cli.md", ROOT / "README.md"):
        for opt in re.findall(r"^\s*avp (--[a-z\-]+)", "\n".join(_code_lines(doc.read_text())), re.M):
            assert opt in top, f"{doc.name}: `avp {opt}` is not an option of avp"


def test_every_sub_command_is_documented():
    text = (ROOT / "docs/cli.md").read_text()
    documented = {n for names, _ in _statements(_code_lines(text)) for n in names}
    missing = sorted(set(_subparsers(build_parser())) - documented)
    assert missing == [], f"docs/cli.md lacks `avp {missing[0]}`"
