"""Studies: a cross-product of environments, plans, planners, repetitions and modes, run on a testbed.

>>> from client_sdk import Client
>>> from client_sdk.study import load_spec, run_study, write_report, export_ompl
>>> with Client() as twb:                                   # doctest: +SKIP
...     data = run_study(twb, load_spec("paper"))           # 48 runs
>>> data.save(Path("study-out")); write_report(data)        # doctest: +SKIP
>>> export_ompl(data, "study-out/study.db")                 # doctest: +SKIP

Collecting talks to the server (:func:`run_study`); everything after works
offline from the study directory (:func:`load_study`): outcomes
(:meth:`StudyData.outcomes`), comparisons between configurations
(:meth:`StudyData.compare`, after SciPy's result objects), the answer in words
(:func:`which_is_better`), figures and the report.  A study of fleets (several
robots per problem: ``robots`` or ``circle`` plans) gets fleet tables
(:func:`fleet_groups`) and figures (:func:`figure_fleet_metrics`,
:func:`figure_fleet_paths`).  The command line is
``twb study``; see ``docs/study.md``.  Needs matplotlib for the figures.
"""

from ._collect import StudyJob, flat_metrics, plan_jobs, run_study, study_planner_seed
from ._compare import COMPARED_METRICS, CONTROLLER_METRICS, Comparison, Comparisons, compare
from ._replay import replay_animation
from ._data import StudyData, load_study
from ._figure_set import make_figures
from ._figures import figure_metrics, figure_outcomes, figure_paths, figure_ratios, save_figures
from ._limits import StudyRefused, check_study
from ._findings import FINDINGS, Finding, findings_json, findings_markdown, paper_findings, write_findings
from ._predictivity import (PREDICTIVITY_METRICS, MetricPredictivity, predictivity, predictivity_json,
                            predictivity_markdown, write_predictivity)
from ._ompl import OmplExport, OmplExportError, PlannerStatus, export_ompl
from ._outcomes import OutcomeSummary, outcome_table
from ._report import summary_markdown, write_report
from ._fleet import Circle, circle_robots
from ._fleet_figures import figure_fleet_metrics, figure_fleet_paths
from ._fleet_results import FLEET_METRICS, FleetGroup, fleet_groups
from ._spec import (ARENA, CONTROLLERS, DISCS, FLEET, FLEET_DISCS, NOISE, PAPER, PREDICTIVITY, ControllerChoice, PlannerSpec, PlanSpec,
                    ProfileSpec, StudySpec, StudySpecError, controllers_spec, fleet_discs_spec, fleet_spec, load_spec,
                    noise_spec, paper_spec, predictivity_spec)
from ._verdict import Answer, which_is_better
from ._worlds import DIFFICULTY_METRICS, DifficultyCorrelation, difficulty_correlations, figure_difficulty

__all__ = sorted(
    [
        "Answer",
        "Circle",
        "DIFFICULTY_METRICS",
        "DifficultyCorrelation",
        "difficulty_correlations",
        "figure_difficulty",
        "ARENA",
        "DISCS",
        "FLEET",
        "FLEET_DISCS",
        "FLEET_METRICS",
        "FleetGroup",
        "circle_robots",
        "figure_fleet_metrics",
        "figure_fleet_paths",
        "fleet_groups",
        "fleet_discs_spec",
        "fleet_spec",
        "COMPARED_METRICS",
        "CONTROLLER_METRICS",
        "Comparison",
        "Comparisons",
        "OutcomeSummary",
        "FINDINGS",
        "Finding",
        "NOISE",
        "PAPER",
        "CONTROLLERS",
        "PREDICTIVITY",
        "predictivity_spec",
        "ControllerChoice",
        "controllers_spec",
        "PlanSpec",
        "ProfileSpec",
        "PlannerSpec",
        "StudyData",
        "StudyJob",
        "StudySpec",
        "StudyRefused",
        "StudySpecError",
        "check_study",
        "compare",
        "export_ompl",
        "OmplExport",
        "OmplExportError",
        "PlannerStatus",
        "noise_spec",
        "figure_metrics",
        "figure_outcomes",
        "findings_json",
        "findings_markdown",
        "flat_metrics",
        "figure_paths",
        "figure_ratios",
        "load_spec",
        "load_study",
        "make_figures",
        "outcome_table",
        "paper_findings",
        "paper_spec",
        "plan_jobs",
        "replay_animation",
        "run_study",
        "save_figures",
        "study_planner_seed",
        "summary_markdown",
        "which_is_better",
        "write_findings",
        "PREDICTIVITY_METRICS",
        "MetricPredictivity",
        "predictivity",
        "predictivity_json",
        "predictivity_markdown",
        "write_predictivity",
        "write_report",
    ]
)
