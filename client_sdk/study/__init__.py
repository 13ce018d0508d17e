"""Studies: a cross-product of environments, plans, planners, repetitions and modes, run on a testbed.

>>> from client_sdk import Client
>>> from client_sdk.study import load_spec, run_study, write_report, export_ompl
>>> with Client() as twb:                                   # doctest: +SKIP
...     data = run_study(twb, load_spec("paper"))           # 48 runs
>>> data.save(Path("study-out")); write_report(data)        # doctest: +SKIP
>>> export_ompl(data, "study-out/study.db")                 # doctest: +SKIP

Collecting talks to the server (:func:`run_study`); everything after works
offline from the study directory (:func:`load_study`).  The command line is
``twb study``; see ``docs/study.md``.  Needs matplotlib for the figures.
"""

from ._collect import StudyJob, flat_metrics, plan_jobs, run_study
from ._replay import replay_animation
from ._data import StudyData, load_study
from ._findings import FINDINGS, Finding, findings_json, findings_markdown, paper_findings, write_findings
from ._figures import figure_metrics, figure_paths, figure_ratios, make_figures, save_figures
from ._ompl import export_ompl
from ._report import summary_markdown, write_report
from ._spec import PAPER, PlannerSpec, PlanSpec, StudySpec, StudySpecError, load_spec, paper_spec

__all__ = sorted(
    [
        "FINDINGS",
        "Finding",
        "PAPER",
        "PlanSpec",
        "PlannerSpec",
        "StudyData",
        "StudyJob",
        "StudySpec",
        "StudySpecError",
        "export_ompl",
        "figure_metrics",
        "findings_json",
        "findings_markdown",
        "flat_metrics",
        "figure_paths",
        "figure_ratios",
        "load_spec",
        "load_study",
        "make_figures",
        "paper_findings",
        "paper_spec",
        "plan_jobs",
        "replay_animation",
        "run_study",
        "save_figures",
        "summary_markdown",
        "write_findings",
        "write_report",
    ]
)
