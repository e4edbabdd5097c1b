"""Where a result came from: the commit written into runs.jsonl and the training reports (avp_common.provenance)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from avp_common.provenance import source_commit
from avp_experiment.results import code_commit

REPO = Path(__file__).resolve().parents[1]


def test_source_commit_finds_the_repository_above_a_file(tmp_path):
    (tmp_path / ".git").mkdir()
    (tmp_path / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (tmp_path / ".git" / "refs" / "heads").mkdir(parents=True)
    (tmp_path / ".git" / "refs" / "heads" / "main").write_text("0123abcd" * 5 + "\n")
    deep = tmp_path / "src" / "pkg" / "pkg" / "mod.py"
    deep.parent.mkdir(parents=True)
    deep.write_text("")
    assert source_commit(deep) == "0123abcd" * 5
    assert source_commit(Path("/") / "no" / "such" / "file.py") == "unknown"


@pytest.mark.skipif(shutil.which("git") is None or not (REPO / ".git").is_dir(), reason="not a git checkout")
def test_the_runner_records_the_checked_out_commit():
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True)
    assert code_commit() == head.stdout.strip()  # was "unknown": it looked one folder above the checkout
