"""What the analyses of a study read of it: its spec and its rows (:class:`StudyRecords`).

:class:`~client_sdk.study.StudyData` has these and more; the analyses (outcomes, comparisons, fleet
results) take anything that has them, so they never import the class that offers them as methods.
"""

from __future__ import annotations

from typing import Any, Protocol

from ._spec import StudySpec

__all__ = ["StudyRecords"]


class StudyRecords(Protocol):
    """A study's spec, experiments and run rows (runs.csv), and the orders derived from them."""

    spec: StudySpec
    experiments: list[dict[str, Any]]
    rows: list[dict[str, Any]]

    @property
    def configurations(self) -> list[str]:
        """The compared configurations in study order."""

    @property
    def modes(self) -> list[str]:
        """The study's modes in order (``sim``, ``twb``)."""

    @property
    def problems(self) -> list[tuple[str, str]]:
        """(environment, plan) pairs in study order."""
