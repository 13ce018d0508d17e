"""The run vocabulary's one outcome rule, as the server, the SDK and the study tooling apply it."""

import pytest

from client_sdk import Run
from contract.vocabulary import JOB_OUTCOMES, NOT_COUNTED, TERMINAL, Mode, RunStatus, run_outcome

CASES = [("completed", None, "success"), ("failed", "collision", "collision"), ("failed", None, "failed"),
         ("failed", "planning", "planning"), ("error", None, "error"), ("cancelled", None, "cancelled"),
         ("interrupted", None, "interrupted"), ("running", None, "pending"), ("queued", None, "pending")]


@pytest.mark.parametrize("status,failure,outcome", CASES)
def test_every_surface_applies_the_one_outcome_rule(status, failure, outcome):
    from server.models import Run as RunRow
    from server.results import outcome_of

    assert run_outcome(status, failure) == outcome
    assert outcome_of(RunRow(status=status, failure=failure)) == outcome
    sdk = Run.from_json({"id": 1, "experiment_id": 1, "mode": "sim", "repetition": 0, "status": status,
                         "failure": failure})
    assert sdk.outcome == outcome and sdk.finished == (status in TERMINAL)


def test_every_ending_is_either_counted_or_not():
    """A success rate's denominator: the job's own outcomes; everything else is named as not counted."""
    endings = {run_outcome(s, None) for s in RunStatus} | set(JOB_OUTCOMES)
    assert endings == set(JOB_OUTCOMES) | set(NOT_COUNTED)
    assert not set(JOB_OUTCOMES) & set(NOT_COUNTED)


def test_the_enums_are_their_strings():
    """Stored and serialised as plain strings; plain strings compare and hash equal to them."""
    assert Mode.TWB == "twb" and "completed" in TERMINAL and {"sim": 1}[Mode.SIM] == 1
    assert f"{RunStatus.FAILED}" == "failed"
