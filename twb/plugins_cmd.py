"""``twb plugins list`` and ``twb plugins install``: planner plug-ins of the interpreter running ``twb``.

A plug-in is a distribution declaring an entry point in ``teleworkbench.planners``
(docs/planners.md).  ``install`` puts it into the environment ``twb`` runs in: with
uv when it is on PATH (a uv-made virtualenv has no pip), else with ``python -m pip``.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from typing import Annotated

import typer

from .errors import fail

__all__ = ["install", "installer_command", "list_plugins", "plugins_app"]

plugins_app = typer.Typer(help="Planner plug-ins: list them, install one into this twb's environment.",
                          no_args_is_help=True)


def where() -> str:
    """The environment and interpreter ``twb`` runs in, in words."""
    return f"{sys.prefix} (Python {sys.version.split()[0]}, {sys.executable})"


@plugins_app.command("list")
def list_plugins() -> None:
    """The installed planner plug-ins, loaded now: which work and why the others fail."""
    from contract.controller_specs import controller_report
    from planners.registry import plugin_report

    report = plugin_report()
    typer.echo(f"Planner plug-ins in {where()}:")
    if not report:
        typer.echo("  none (install one with `twb plugins install SPEC`, see docs/planners.md)")
    for p in report:
        state = "ok" if p.loaded else f"FAILED to load: {p.error}"
        typer.echo(f"  {p.name:12s} {p.target}  [{p.distribution or 'unknown distribution'}]  {state}")
    controllers = controller_report()
    if controllers:
        typer.echo("Controller plug-ins (docs/controllers.md):")
    for name, target, error in controllers:
        typer.echo(f"  {name:12s} {target}  {'ok' if not error else f'FAILED to load: {error}'}")
    if any(not p.loaded for p in report) or any(error for _, _, error in controllers):
        raise typer.Exit(1)


def installer_command(spec: str, *, editable: bool = False, no_deps: bool = False) -> list[str]:
    """The command that installs ``spec`` into this interpreter's environment: ``uv pip install --python
    <this python>`` when uv is on PATH, else ``<this python> -m pip install``."""
    args = (["-e", spec] if editable else [spec]) + (["--no-deps"] if no_deps else [])
    uv = shutil.which("uv")
    if uv:
        return [uv, "pip", "install", "--python", sys.executable, *args]
    if importlib.util.find_spec("pip") is not None:
        return [sys.executable, "-m", "pip", "install", *args]
    fail(f"cannot install into {sys.prefix}: uv is not on PATH and this Python has no pip "
         "(install uv: `python3 -m pip install uv`, or add pip: "
         f"`{sys.executable} -m ensurepip`)")


@plugins_app.command("install")
def install(
    spec: Annotated[str, typer.Argument(help="What to install: a directory, a wheel, or a package name (as for pip).")],
    editable: Annotated[bool, typer.Option("--editable", "-e", help="Install a directory in editable mode.")] = False,
    no_deps: Annotated[bool, typer.Option("--no-deps", help="Do not install its dependencies.")] = False,
) -> None:
    """Install a planner plug-in into the environment this twb runs in, then list the plug-ins."""
    cmd = installer_command(spec, editable=editable, no_deps=no_deps)
    typer.echo(f"Installing {spec} into {where()} with {'uv' if 'uv' in cmd[0] else 'pip'}:", err=True)
    typer.echo("  " + " ".join(cmd), err=True)
    if subprocess.run(cmd).returncode != 0:
        fail(f"installing {spec} failed (see the installer's messages above)")
    # a fresh process: an editable install's path hook is read at start-up only
    listed = subprocess.run([sys.executable, "-m", "twb", "plugins", "list"], capture_output=True, text=True)
    typer.echo(listed.stdout.rstrip())
    typer.echo("twb plan and the SDK see it now; restart a running testbed (`twb up`) so that the server does.")
    if listed.returncode != 0:
        raise typer.Exit(1)
