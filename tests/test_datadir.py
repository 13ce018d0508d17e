"""`twb up` / `twb server` in any git repository leave `git status` clean: a new data dir ignores itself."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from twb.datadir import GITIGNORE, make_data_dir


def git(repo, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True).stdout


@pytest.mark.slow
def test_a_new_data_dir_keeps_itself_out_of_git(tmp_path):
    repo = tmp_path / "my-project"
    repo.mkdir()
    git(repo, "init", "-q")
    (repo / "planner.py").write_text("print('mine')\n")
    data = repo / "runs" / "twb-data"  # --data-dir anywhere in the repository, parents made too
    proc = subprocess.Popen([sys.executable, "-m", "twb", "server", "--port", "0", "--data-dir", str(data),
                             "--token", "datadir-test-token"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env={**os.environ, "TWB_EXIT_WITH_PARENT": "1"})
    try:
        deadline = time.monotonic() + 60
        out = ""
        while "API docs" not in out and time.monotonic() < deadline:
            out += proc.stdout.readline()
        assert "API docs" in out, out
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(30)
    assert (data / "token").read_text().strip() == "datadir-test-token" and (data / "twb.db").exists()
    assert (data / ".gitignore").read_text() == GITIGNORE
    assert git(repo, "status", "--porcelain", "--untracked-files=all") == "?? planner.py\n"


def test_an_existing_directory_is_left_as_it_is(tmp_path):
    mine = tmp_path / "project"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    assert make_data_dir(mine) == mine
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]  # no .gitignore of '*' over someone's files
