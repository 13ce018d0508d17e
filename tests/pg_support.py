"""A real PostgreSQL server for the tests, started from Debian's binaries (initdb in a temporary directory,
a free port on 127.0.0.1), as the ``postgres`` user when the tests run as root.

The server is a child of the test process and gets SIGTERM when it dies (parent-death signal), so a killed
test run leaves no database server behind.  Tests get a fresh database each (:meth:`PostgresServer.database`).
"""

from __future__ import annotations

import ctypes
import glob
import os
import pwd
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Optional

__all__ = ["PostgresServer", "postgres_bin"]

_PR_SET_PDEATHSIG = 1


def postgres_bin() -> Optional[Path]:
    """The directory of Debian's PostgreSQL binaries (the newest installed), if any."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(p.split("/")[4]))
    return Path(found[-1]).parent if found else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PostgresServer:
    """``postgres`` on 127.0.0.1:``port`` with a throw-away cluster in ``root``; user ``twb``, trust auth."""

    def __init__(self, root: Path) -> None:
        binaries = postgres_bin()
        if binaries is None:
            raise RuntimeError("PostgreSQL is not installed (Debian: apt-get install postgresql)")
        self.root = Path(root)
        self.data = self.root / "data"
        self.sockets = self.root / "sockets"
        self.root.mkdir(parents=True, exist_ok=True)
        self.sockets.mkdir(exist_ok=True)
        self.port = _free_port()
        self._uid: Optional[int] = None
        if os.geteuid() == 0:  # initdb and postgres refuse to run as root
            pw = pwd.getpwnam("postgres")
            self._uid, self._gid = pw.pw_uid, pw.pw_gid
            for p in (self.root, self.sockets):
                os.chown(p, self._uid, self._gid)
        self._run([str(binaries / "initdb"), "-D", str(self.data), "-U", "twb", "-A", "trust", "-E", "UTF8",
                   "--no-sync", "--no-instructions"])
        self.log = open(self.root / "postgres.log", "a")
        self.start()
        self._count = 0

    def start(self) -> None:
        """Start the server on its port (again, after :meth:`crash`: it recovers from its log)."""
        binaries = postgres_bin()
        self.proc = subprocess.Popen(
            [str(binaries / "postgres"), "-D", str(self.data), "-p", str(self.port), "-k", str(self.sockets),
             "-c", "listen_addresses=127.0.0.1", "-c", "fsync=off", "-c", "synchronous_commit=off",
             "-c", "full_page_writes=off", "-c", "max_connections=200"],
            stdout=self.log, stderr=subprocess.STDOUT, preexec_fn=self._as_postgres(die_with_parent=True))
        self._wait_ready()

    def crash(self) -> None:
        """End the server at once, as a crash would (immediate shutdown: no checkpoint, connections cut)."""
        self.proc.send_signal(signal.SIGQUIT)
        self.proc.wait(30)

    def _as_postgres(self, die_with_parent: bool = False):  # type: ignore[no-untyped-def]
        uid, gid = self._uid, getattr(self, "_gid", None)

        def preexec() -> None:
            if uid is not None:
                os.setgroups([])
                os.setgid(gid)
                os.setuid(uid)
            if die_with_parent:  # after setuid: a change of credentials clears it
                ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)

        return preexec

    def _run(self, argv: list[str]) -> None:
        out = subprocess.run(argv, capture_output=True, text=True, preexec_fn=self._as_postgres(), timeout=120)
        if out.returncode != 0:
            raise RuntimeError(f"{argv[0]} failed: {out.stderr or out.stdout}")

    def _wait_ready(self, timeout_s: float = 30.0) -> None:
        import psycopg

        deadline = time.monotonic() + timeout_s
        while True:
            try:
                psycopg.connect(self.dsn("postgres"), connect_timeout=2).close()
                return
            except psycopg.OperationalError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"PostgreSQL did not start: {(self.root / 'postgres.log').read_text()}")
                time.sleep(0.1)

    def dsn(self, database: str) -> str:
        return f"postgresql://twb@127.0.0.1:{self.port}/{database}"

    def database(self, name: Optional[str] = None) -> str:
        """A new, empty database; its SQLAlchemy URL."""
        import psycopg

        self._count += 1
        name = name or f"twb_test_{self._count}"
        with psycopg.connect(self.dsn("postgres"), autocommit=True) as con:
            con.execute(f'DROP DATABASE IF EXISTS "{name}"')
            con.execute(f'CREATE DATABASE "{name}"')
        return f"postgresql+psycopg://twb@127.0.0.1:{self.port}/{name}"

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)  # fast shutdown
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()
        shutil.rmtree(self.root, ignore_errors=True)
