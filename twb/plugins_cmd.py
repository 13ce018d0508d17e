"""``twb plugins list`` and ``twb plugins install``: planner and controller plug-ins of the interpreter running ``twb``.

A plug-in is a distribution declaring an entry point in ``teleworkbench.planners``
(docs/planners.md) or ``teleworkbench.controllers`` (docs/controllers.md).  ``install``
puts it into the environment ``twb`` runs in: with uv when it is on PATH (a uv-made
virtualenv has no pip), else with ``python -m pip``.  ``list`` shows each plug-in that
does not load with its :class:`~contract.plugins.LoadError` (message and type).
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from typing import TYPE_CHECKING, Annotated

import typer

from .errors import fail

if TYPE_CHECKING:
    from contract.plugins import PluginStatus

__all__ = ["install", "installer_command", "list_plugins", "plugins_app", "status_line"]

plugins_app = typer.Typer(help="Planner and controller plug-ins: list them, install one into this twb's environment.",
                          no_args_is_help=True)


def where() -> str:
    """The environment and interpreter ``twb`` runs in, in words."""
    return f"{sys.prefix} (Python {sys.version.split()[0]}, {sys.executable})"


def status_line(p: PluginStatus) -> str:
    """One plug-in's line: name, ``module:object``, distribution, and ``ok`` or why it fails to load (the
    :class:`~contract.plugins.LoadError`'s message and type, and what to do)."""
    from contract.plugins import RESTART_HINT

    state = "ok" if p.error is None else f"FAILED to load: {p.error.message} [{p.error.error_type}] ({RESTART_HINT})"
    return f"  {p.name:12s} {p.target}  [{p.distribution or 'unknown distribution'}]  {state}"


@plugins_app.command("list")
def list_plugins() -> None:
    """The installed planner and controller plug-ins, loaded now: which work and why the others fail (exit
    status 1 if any fails)."""
    from contract.controller_specs import controller_report
    from planners.registry import plugin_report

    report = plugin_report()
    typer.echo(f"Planner plug-ins in {where()}:")
    if not report:
        typer.echo("  none (install one with `twb plugins install SPEC`, see docs/planners.md)")
    for p in report:
        typer.echo(status_line(p))
    controllers = controller_report()
    if controllers:
        typer.echo("Controller plug-ins (docs/controllers.md):")
    for p in controllers:
        typer.echo(status_line(p))
    if any(not p.loaded for p in (*report, *controllers)):
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
    """Install a planner or controller plug-in into the environment this twb runs in, then list the plug-ins."""
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
