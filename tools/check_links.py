"""Every relative link of the Markdown docs resolves to a file or folder of the clone.

    python tools/check_links.py [FILE.md ...]

Without arguments it reads README.md, CHANGELOG.md, docs/**/*.md and src/**/README.md. A link is an inline link or
image (``[text](target)``, ``![alt](target)``) or a reference definition (``[id]: target`` with at most a title
after it) outside code blocks and inline code; web addresses (``http:``, ``https:``, ``mailto:``) and in-page
anchors (``#...``) are not checked, and a target's own ``#anchor`` is dropped. Prints each broken link as
``FILE:LINE: TARGET`` and exits 1 if there is one.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from urllib.parse import unquote

ROOT = Path(__file__).resolve().parents[1]
INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?([^\s>]+)>?(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^)]*\)))?\s*$")
CODE_SPAN = re.compile(r"(`+).+?\1")
SKIP = ("http://", "https://", "mailto:", "ftp://", "#")


def markdown_files(root: Path = ROOT) -> list[Path]:
    """The documents whose links are checked."""
    files = [root / "README.md", root / "CHANGELOG.md"]
    files += sorted((root / "docs").rglob("*.md"))
    files += sorted((root / "src").rglob("README.md"))
    return [p for p in files if p.is_file()]


def links(text: str) -> list[tuple[int, str]]:
    """(line number, target) of every link outside fenced code blocks and code spans."""
    out: list[tuple[int, str]] = []
    fence = ""
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        if stripped.startswith(("```", "~~~")):
            mark = stripped[:3]
            fence = "" if fence == mark else (fence or mark)
            continue
        if fence:
            continue
        line = CODE_SPAN.sub("", line)
        out += [(n, m.group(1)) for m in INLINE.finditer(line)]
        ref = REFERENCE.match(line)
        if ref:
            out.append((n, ref.group(1)))
    return out


def broken(path: Path, root: Path = ROOT) -> list[str]:
    """'FILE:LINE: TARGET' for each link of ``path`` that resolves to nothing."""
    bad = []
    for n, target in links(path.read_text(encoding="utf-8")):
        if target.startswith(SKIP):
            continue
        rel = unquote(target.split("#", 1)[0].split("?", 1)[0])
        if not rel:
            continue
        resolved = root / rel.lstrip("/") if rel.startswith("/") else path.parent / rel
        if not resolved.exists():
            bad.append(f"{path.relative_to(root)}:{n}: {target}")
    return bad


def main(argv: list[str]) -> int:
    files = [Path(a).resolve() for a in argv] if argv else markdown_files()
    bad = [b for f in files for b in broken(f)]
    print("\n".join(bad) if bad else f"{len(files)} Markdown files: every relative link resolves")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
