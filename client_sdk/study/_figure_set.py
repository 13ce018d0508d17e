"""Which figures a study gets: the paper's for one robot, the fleet's for several."""

from __future__ import annotations

from typing import Any

from ._data import StudyData
from ._figures import figure_metrics, figure_outcomes, figure_paths, figure_ratios
from ._fleet_figures import figure_fleet_metrics, figure_fleet_paths
from ._fleet_results import fleet_outcomes
from ._worlds import figure_difficulty

__all__ = ["make_figures"]


def make_figures(data: StudyData) -> dict[str, Any]:
    """``{"fig5_outcomes": Figure, "fig6_metrics": Figure, "fig7_ratios": Figure, "fig8_paths": Figure}``; a
    fleet study's: ``{"fig5_outcomes", "fig6_fleet_metrics" (fleet metrics against the robot count),
    "fig8_fleet_paths" (every robot's path)}`` (:mod:`._fleet_figures`); a study of a world set adds
    ``"fig9_difficulty"`` (success against difficulty, :mod:`._worlds`)."""
    if data.spec.fleet:
        return {"fig5_outcomes": figure_outcomes(data, fleet_outcomes(data)),
                "fig6_fleet_metrics": figure_fleet_metrics(data),
                "fig8_fleet_paths": figure_fleet_paths(data)}
    figures = {"fig5_outcomes": figure_outcomes(data), "fig6_metrics": figure_metrics(data),
               "fig7_ratios": figure_ratios(data), "fig8_paths": figure_paths(data)}
    if data.spec.worlds:  # a world set: success against difficulty (:mod:`._worlds`)
        figures["fig9_difficulty"] = figure_difficulty(data)
    return figures
