"""``twb upload``: upload a planner program to a testbed (docs/uploads.md), over the SDK.

The program's id goes into a job as ``"program": ID`` (``twb submit job.json``
or ``Client.submit(..., program=ID)``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Optional

import typer

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client

__all__ = ["upload"]


def upload(
    file: Annotated[Path, typer.Argument(help="The program: a .py file, a script or a Linux binary.")],
    name: Annotated[Optional[str], typer.Option(help="Its name on the testbed (default: the file's name).")] = None,
    kind: Annotated[Optional[str], typer.Option(
        help="python or executable (default: python for .py, else executable).")] = None,
    interpreter: Annotated[Optional[str], typer.Option(
        help="Run an executable with sh, bash or python3 (default: the file itself, a binary or #! script).")] = None,
    arg: Annotated[Optional[list[str]], typer.Option(
        "--arg", "-a", help="A command-line argument (repeatable); {robot_port}, {env_file}, {start}, ... are filled in.")] = None,
    stochastic: Annotated[bool, typer.Option(
        "--stochastic", help="Its path depends on the seed it gets (TWB_SEED): run it once per repetition with "
                             "that repetition's planner seed (default: once per experiment).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the uploaded program as JSON.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Upload a planner program; prints its id (use it as "program" in a job)."""
    import dataclasses

    if kind not in (None, "python", "executable"):
        fail(f"--kind must be python or executable, got {kind!r}")
    if not file.is_file():
        fail(f"no such file: {file}")
    with sdk_client(url, token) as client:
        prog = client.upload_program(file, name=name, kind=kind, interpreter=interpreter, args=arg or [],
                                     stochastic=stochastic)
    if as_json:
        d = dataclasses.asdict(prog)
        d["created_at"] = prog.created_at.isoformat() if prog.created_at else None
        typer.echo(json.dumps(d, indent=2))
        return
    how = prog.kind + (f" ({prog.interpreter})" if prog.interpreter else "") + (", stochastic" if prog.stochastic
                                                                                  else "")
    typer.echo(f"Uploaded program {prog.id}: {prog.name}, {how}, {prog.size} bytes. "
               f'Use it in a job as "program": {prog.id}.')
