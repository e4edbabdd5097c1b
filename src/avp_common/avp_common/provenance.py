"""Where a result came from: the checked-out commit, read without running git."""

from __future__ import annotations

from pathlib import Path


def git_commit(root: Path) -> str:
    """The checked-out commit, read from .git (no git process)."""
    try:
        git = root / ".git"
        head = (git / "HEAD").read_text().strip()
        if not head.startswith("ref:"):
            return head
        ref = head.split(" ", 1)[1]
        f = git / ref
        if f.is_file():
            return f.read_text().strip()
        for line in (git / "packed-refs").read_text().splitlines():
            if line.endswith(" " + ref):
                return line.split(" ", 1)[0]
    except OSError:
        pass
    return "unknown"


def source_commit(source_file: str | Path) -> str:
    """The checked-out commit of the repository that holds ``source_file`` (the first folder above it with a .git;
    the file's real path, so a colcon symlink install finds the source tree); "unknown" outside one."""
    for folder in Path(source_file).resolve().parents:
        if (folder / ".git").is_dir():
            return git_commit(folder)
    return "unknown"
