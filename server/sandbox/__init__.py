"""The sandbox of uploaded planner programs (docs/uploads.md, "The sandbox: what is enforced where").

In the server (asyncio):

- :mod:`.service` — :class:`Sandbox`: starts the launcher, probes the isolation, limits, sandbox uids;
- :mod:`.program` — :class:`ProgramSpec`, the program's files, environment and command line;
- :mod:`.outcome` — the launcher's result as a :class:`ProgramOutcome`, :func:`explain`.

In the launcher (``python -m server.sandbox.launch``, one process tree per program):

- :mod:`.link` — the line link between the two: its message kinds, and how a line is encoded and parsed;
- :mod:`.launch` — the entry point: JSON job in, one JSON result line out;
- :mod:`.lifetime` — ending early: SIGTERM from the server, or its death;
- :mod:`.cgroups` — the program's cgroup: one memory limit for all its processes;
- :mod:`.bwrap` — the sandbox, made by bubblewrap: namespaces, mounts, the robot ports inside it;
- :mod:`.seccomp` — the system-call allowlist, compiled by libseccomp;
- :mod:`.isolation` — the kernel calls left: ``prctl``, capabilities, entering a network namespace;
- :mod:`.confine` — the process between fork and exec: cgroup, uid, rlimits (seccomp without bwrap);
- :mod:`.workdir` — its working directory, environment and command line;
- :mod:`.supervise` — spawn, pump (output and robot port), reap, report;
- :mod:`.robot_port` — the robot port, on :mod:`contract.protocol`;
- :mod:`.processes` — counting and killing the sandbox's processes.
"""

from .outcome import ProgramOutcome, explain
from .program import ProgramSpec, program_argv
from .service import Sandbox, launcher_env

__all__ = ["ProgramOutcome", "ProgramSpec", "Sandbox", "explain", "launcher_env", "program_argv"]
