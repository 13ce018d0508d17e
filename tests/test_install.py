"""The project as a wheel: built, installed into a fresh virtualenv, and the server started from it.

The Docker image installs the wheel too; this is what shows that the server
finds everything it needs (migrations, built-in environments, dashboard
files) as package data, not next to a source tree.  The migrations live in the
repository's top-level alembic/ and go into the wheel as server/migrations
(pyproject.toml), never as a top-level package that would shadow the library.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
import zipfile
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _uv() -> list[str] | None:
    """How to run uv (the Makefile installs it into the machine's python3 when it can), if it is here."""
    if shutil.which("uv"):
        return ["uv"]
    if shutil.which("python3") and subprocess.run(["python3", "-m", "uv", "--version"],
                                                  capture_output=True).returncode == 0:
        return ["python3", "-m", "uv"]
    return None


@pytest.mark.slow
def test_the_server_runs_from_an_installed_wheel(tmp_path):
    uv = _uv()
    if uv is None:
        pytest.skip("uv is not installed (the Makefile installs it with pip when it can)")
    env = {**os.environ, "UV_NO_PROGRESS": "1"}
    env.pop("VIRTUAL_ENV", None)
    # sdist first, then the wheel from it (in a temporary tree: no build/ left in the checkout,
    # and only what the sdist ships reaches the wheel)
    built = subprocess.run([*uv, "build", "--out-dir", str(tmp_path / "dist"), str(ROOT)],
                           capture_output=True, text=True, env=env, timeout=300)
    assert built.returncode == 0, built.stderr
    wheel = next((tmp_path / "dist").glob("teleworkbench-*.whl"))
    with zipfile.ZipFile(wheel) as whl:  # PEP 561: the packages users import say they are typed
        assert {"client_sdk/py.typed", "contract/py.typed", "planners/py.typed"} <= set(whl.namelist())
    venv = tmp_path / "venv"
    subprocess.run([*uv, "venv", "-q", "--python", sys.executable, str(venv)], check=True, env=env, timeout=120)
    python = venv / "bin" / "python"
    installed = subprocess.run([*uv, "pip", "install", "-q", "--python", str(python), str(wheel)],
                               capture_output=True, text=True, env=env, timeout=600)
    assert installed.returncode == 0, installed.stderr
    where = subprocess.run([str(python), "-c", "import server; print(server.__file__)"], cwd=tmp_path,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(where).is_relative_to(venv), where  # the wheel's copy, not this checkout

    # the migrations: the repository's alembic/ as server/migrations, file for file; no top-level alembic
    names = zipfile.ZipFile(wheel).namelist()
    assert not [n for n in names if n.startswith("alembic/")], names
    repo = sorted(p.relative_to(ROOT / "alembic").as_posix() for p in (ROOT / "alembic").rglob("*")
                  if p.is_file() and p.suffix in (".py", ".mako"))
    assert sorted(n[len("server/migrations/"):] for n in names if n.startswith("server/migrations/")) == repo
    found = subprocess.run(
        [str(python), "-c", "import alembic; from alembic.script import ScriptDirectory; "
         "from server.core.db import MIGRATIONS; print(alembic.__file__); print(MIGRATIONS); "
         "print(' '.join(sorted(s.revision for s in ScriptDirectory(MIGRATIONS).walk_revisions())))"],
        cwd=tmp_path, capture_output=True, text=True, check=True).stdout.split("\n")
    library, migrations, revisions = Path(found[0]), Path(found[1]), found[2].split()
    assert library.is_relative_to(venv) and library.parent.name == "alembic", library  # the library itself
    assert migrations.is_relative_to(venv) and migrations.parts[-2:] == ("server", "migrations"), migrations
    for name in repo:
        assert (migrations / name).read_bytes() == (ROOT / "alembic" / name).read_bytes(), name
    from alembic.script import ScriptDirectory

    assert revisions == sorted(s.revision for s in ScriptDirectory(str(ROOT / "alembic")).walk_revisions())

    out = open(tmp_path / "server.log", "w")
    proc = subprocess.Popen([str(venv / "bin" / "twb"), "server", "--port", "0", "--data-dir", str(tmp_path / "data"),
                             "--token", "wheel-token"], cwd=tmp_path, stdout=out, stderr=subprocess.STDOUT,
                            env={**env, "PYTHONUNBUFFERED": "1"})
    try:
        deadline = time.monotonic() + 60
        url = None
        while url is None:
            text = (tmp_path / "server.log").read_text()
            m = re.search(r"(http://127\.0\.0\.1:\d+)", text)
            if m and "API docs" in text:
                url = m.group(1)
            assert proc.poll() is None, text
            assert time.monotonic() < deadline, text
            time.sleep(0.1)
        with httpx.Client(base_url=url, headers={"Authorization": "Bearer wheel-token"}, timeout=30) as c:
            assert c.get("/health").json()["status"] == "ok"
            names = {e["name"] for e in c.get("/api/v1/environments").json()["data"]}
            assert {"room", "blocks"} <= names  # migrated store, built-ins from package data
            assert "Teleworkbench" in c.get("/").text  # the dashboard's files
            assert c.get("/static/js/app.js").status_code == 200
    finally:
        proc.terminate()  # its fresh workers may still be compiling the simulation kernels: it stops at once anyway
        proc.wait(30)
        out.close()


def _packaging() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_the_package_list_names_every_directory_of_the_tree():
    """pyproject.toml lists the packages (discovery cannot map alembic/ to server.migrations): a directory
    missing from the list would be missing from the wheel, so every one of the tree is there."""
    cfg = _packaging()
    dirs = {name: ROOT / name for name in cfg["packages"] if "." not in name}
    dirs |= {name: ROOT / path for name, path in cfg["package-dir"].items()}
    tree = set()
    for name, where in dirs.items():
        for d in [where, *where.rglob("*")]:
            if d.is_dir() and "__pycache__" not in d.parts and not d.name.endswith(".egg-info"):
                tree.add(".".join([name, *d.relative_to(where).parts]))
    assert sorted(cfg["packages"]) == sorted(tree)
    assert cfg["package-dir"] == {"server.migrations": "alembic"}
    assert "alembic" not in cfg["packages"]  # it would shadow the Alembic library


def test_the_docker_image_copies_every_packaged_directory():
    """The Dockerfile's build stage copies the source directories one by one: each the wheel is built from."""
    import re

    cfg = _packaging()
    needed = {name for name in cfg["packages"] if "." not in name} | set(cfg["package-dir"].values())
    copied = set(re.findall(r"^COPY (\S+) \1$", (ROOT / "Dockerfile").read_text(), re.M))
    assert needed <= copied, needed - copied
