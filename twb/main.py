"""The ``twb`` command: one Typer app; each sub-command lives in its own module.

Command modules import their heavy dependencies inside the command function,
so ``twb --help`` and every command start quickly.
"""

from __future__ import annotations

import sys

import typer

from . import (agent_cmd, calibrate_cmd, demo_cmd, export_cmd, jobs_cmd, metrics_cmd, plan_cmd, plugins_cmd, replay_cmd,
               server_cmd, study_cmd, upload_cmd, worlds_cmd)
from .errors import report_exception

app = typer.Typer(
    name="twb",
    help="Teleworkbench emulator: plan paths, run robots and the testbed, get metrics.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)
app.command("plan")(plan_cmd.plan)
app.command("planners")(plan_cmd.planners)
app.add_typer(plugins_cmd.plugins_app, name="plugins")
app.command("demo")(demo_cmd.demo)
app.command("metrics")(metrics_cmd.metrics)
app.command("agent")(agent_cmd.agent)
app.command("up")(server_cmd.up)
app.command("server")(server_cmd.server)
app.add_typer(server_cmd.users_app, name="users")
app.command("submit")(jobs_cmd.submit)
app.command("status")(jobs_cmd.status)
app.command("wait")(jobs_cmd.wait)
app.command("results")(jobs_cmd.results)
app.command("cancel")(jobs_cmd.cancel)
app.add_typer(jobs_cmd.envs_app, name="envs")
app.command("upload")(upload_cmd.upload)
app.command("replay")(replay_cmd.replay)
app.command("export")(export_cmd.export)
app.command("study")(study_cmd.study)
app.command("export-ompl")(study_cmd.export_ompl)
app.command("calibrate")(calibrate_cmd.calibrate)
app.add_typer(worlds_cmd.worlds_app, name="worlds")


def main(argv: list[str] | None = None) -> int:
    """Console entry point: run the app and turn any error into one line on stderr.

    Typer handles usage errors itself (standalone mode); everything a command
    raises ends here.
    """
    try:
        app(args=argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except KeyboardInterrupt:
        print("twb: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the one place errors become messages
        return report_exception(exc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
