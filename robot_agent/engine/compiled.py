"""How the simulation kernels are compiled (numba) and where their machine code is cached.

Every compiled function of the agent is declared with :data:`kernel`.  numba
caches machine code per source file and only notices changes to *that*
file, not to the functions it calls from other files; so the cache lives in
a directory named after a hash of all kernel sources, and changing any of
them compiles everything afresh.  The directory is under
``$NUMBA_CACHE_DIR`` when set, else ``robot_agent/engine/__pycache__/kernels``, else
(read-only install) the user's cache directory.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numba
from numba import njit

__all__ = ["KERNEL_SOURCES", "cache_dir", "kernel"]

#: the modules whose compiled code depends on each other
KERNEL_SOURCES = ("compiled.py", "noise.py", "kinematics.py", "controllers.py", "follower.py", "physics.py", "contact.py",
                  "movers.py", "stepper.py", "backends.py")


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK)


def cache_dir() -> Path:
    """The cache directory of the current kernel sources."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256(b"".join((here / f).read_bytes() for f in KERNEL_SOURCES)).hexdigest()[:16]
    env = os.environ.get("NUMBA_CACHE_DIR")
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "teleworkbench" / "kernels"
    for base in ([Path(env)] if env else []) + [here / "__pycache__" / "kernels", user]:
        if _writable(base / digest):
            return base / digest
    return Path(tempfile.gettempdir()) / "teleworkbench-kernels" / digest


numba.config.CACHE_DIR = str(cache_dir())  # read when each kernel below is declared

#: the decorator of every kernel: nopython, cached, numpy's error model (no Python
#: exceptions for division by zero: every division is guarded or by a validated constant)
kernel = njit(cache=True, error_model="numpy")
