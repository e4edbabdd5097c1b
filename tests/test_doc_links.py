"""tools/check_links.py: every relative link of README.md, CHANGELOG.md, docs/**/*.md and src/**/README.md resolves
to a file or folder of the clone (result folders are renamed and moved; a link left behind is a dead end)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import check_links  # noqa: E402


def test_every_relative_link_of_the_docs_resolves():
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "check_links.py")], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stdout
    files = {p.relative_to(ROOT).as_posix() for p in check_links.markdown_files()}
    assert {"README.md", "docs/results/README.md", "docs/results/table1/README.md"} <= files


def test_a_broken_link_is_named_and_code_web_links_and_anchors_are_not_checked(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "there.md").write_text("# There\n")
    doc = tmp_path / "docs" / "page.md"
    doc.write_text("\n".join([
        "[fine](there.md#there) and ![figure](there.md) and [folder](../docs/)",
        "[gone](results/old_name/README.md) and [web](https://example.org/x) and [anchor](#top)",
        "`[in code](nowhere.md)`",
        "```",
        "[in a block](nowhere.md)",
        "```",
        "[ref]: missing%20file.md",
        "[0.1.0]: git tag v0.1.0 (not a link definition)",
    ]) + "\n")
    assert check_links.broken(doc, tmp_path) == ["docs/page.md:2: results/old_name/README.md",
                                                 "docs/page.md:7: missing%20file.md"]
