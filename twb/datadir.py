"""The testbed's data directory (database, token, logs): a new one keeps itself out of git."""

from __future__ import annotations

from pathlib import Path

__all__ = ["GITIGNORE", "make_data_dir"]

#: what a new data directory's ``.gitignore`` says (everything in it, itself included, as a virtualenv's)
GITIGNORE = "# made by twb: the testbed's database, token and logs stay out of git\n*\n"


def make_data_dir(path: Path) -> Path:
    """Create ``path`` (and its parents) if needed; a directory made here gets a ``.gitignore`` of ``*``,
    so ``twb up`` in any repository leaves ``git status`` clean.  An existing directory is left as it is."""
    path = Path(path)
    if not path.exists():
        path.mkdir(parents=True)
        (path / ".gitignore").write_text(GITIGNORE)
    return path
