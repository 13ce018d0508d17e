"""``GET /api/v1/meta``: the run vocabulary, for clients that cannot import :mod:`contract.vocabulary`."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from contract.vocabulary import vocabulary

router = APIRouter(prefix="/meta", tags=["meta"])


class Vocabulary(BaseModel):
    """Modes, run statuses, failure kinds and outcomes (docs/design.md, "Run states")."""

    modes: list[str] = Field(description="where a run drives: sim (idealised) or twb (the emulated field)")
    statuses: list[str] = Field(description="every run and experiment status, in the order a run passes them")
    active: list[str] = Field(description="the statuses of a run under way")
    terminal: list[str] = Field(description="the statuses a run ends in")
    judged: list[str] = Field(description="the endings that are the job's own (completed, failed)")
    failure_kinds: list[str] = Field(description="why a failed run failed")
    job_outcomes: list[str] = Field(description="the outcomes a success rate counts")
    not_counted: list[str] = Field(description="the outcomes a success rate leaves out (the testbed's, the owner's)")


class Meta(BaseModel):
    """What a client needs to know of this testbed's vocabulary."""

    vocabulary: Vocabulary


@router.get("", response_model=Meta)
def get_meta() -> Meta:
    """The run vocabulary (open: no token needed)."""
    return Meta(vocabulary=Vocabulary(**vocabulary()))
