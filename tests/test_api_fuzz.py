"""The REST API under schemathesis: generated requests (valid and invalid) against a real `twb server`.

Every response must be documented (status code, content type, headers,
body schema), no request may cause a 5xx, invalid requests must be refused
and invalid credentials answered 401/403.  Deterministic: fixed seeds and a
bounded number of examples per operation; the robots' live event stream is
left out (it never ends).

Not checked: ``positive_data_acceptance`` ("a schema-valid request is
accepted").  By contract a job the testbed cannot run is refused with 422
and the reason — an unknown environment, a start inside an obstacle — which
no schema can express.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from servers import serve

ST = Path(sys.executable).with_name("st")
CHECKS = ["--checks", "all", "--exclude-checks", "positive_data_acceptance"]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    # the limit on unknown tokens would answer 429 to the fuzzer's invalid-credential probes
    yield from serve(["server", "--enable-uploads"], tmp_path_factory.mktemp("fuzzed"),
                     env={"TWB_AUTH_FAILURES_PER_MINUTE": "1000000"})


def schemathesis(server, tmp_path, *args: str) -> subprocess.CompletedProcess:
    if not ST.exists():
        pytest.skip("schemathesis is not installed (it is a dev dependency: make test installs it)")
    return subprocess.run(
        [str(ST), "run", f"{server.url}/openapi.json", *CHECKS, "--exclude-path", "/api/v1/events",
         "--generation-database", "none", "--no-color", "--workers", "1", "--request-timeout", "20", *args],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)


def assert_no_failures(stdout: str) -> None:
    """Every generated case passed.  Schemathesis's warnings (an operation that mostly got 404s or
    422s, e.g. a job naming an environment that does not exist) are advice on coverage, not failures."""
    counts = re.search(r"(\d+) generated, (\d+) passed", stdout)
    assert counts, stdout[-6000:]
    assert counts[1] == counts[2] and int(counts[1]) > 0, stdout[-6000:]
    assert "FAILURES" not in stdout, stdout[-6000:]


def test_every_operation_with_an_admin_token(server, tmp_path):
    out = schemathesis(server, tmp_path, "-H", f"Authorization: Bearer {server.token}", "--max-examples", "25",
                       "--seed", "7")
    assert out.returncode == 0, out.stdout[-6000:]
    assert_no_failures(out.stdout)


def test_every_operation_with_a_user_token_and_an_agent_token(server, tmp_path):
    with server.client() as admin:
        user = admin.post("/api/v1/users", json={"name": "fuzzy"}).json()["token"]
        agent = admin.post("/api/v1/users/fuzzy/tokens", params={"kind": "agent"}).json()["token"]
    for token, seed in ((user, "8"), (agent, "9")):
        out = schemathesis(server, tmp_path, "-H", f"Authorization: Bearer {token}", "--max-examples", "10",
                           "--seed", seed)
        assert out.returncode == 0, out.stdout[-6000:]


def test_every_operation_without_a_token(server, tmp_path):
    out = schemathesis(server, tmp_path, "--max-examples", "10", "--seed", "10")
    assert out.returncode == 0, out.stdout[-6000:]
