"""The OpenAPI document describes every response body: each JSON answer of every operation is a named model
(``server/schemas.py``), and the routes that stream or serve files say their media type instead."""

from __future__ import annotations

import copy

import pytest

from server.app import create_app
from server.core.settings import Settings

#: operations whose success answer is not (only) JSON: their media types
NOT_JSON = {
    ("get", "/api/v1/events"): {"text/event-stream"},
    ("get", "/api/v1/programs/{program_id}/content"): {"application/octet-stream"},
    ("get", "/api/v1/runs/{run_id}/poses"): {"application/json", "text/csv"},
    ("get", "/api/v1/runs/{run_id}/export"): {"application/octet-stream", "application/zip"},
    ("get", "/api/v1/experiments/{experiment_id}/export"): {"application/octet-stream", "application/zip"},
}


@pytest.fixture(scope="module")
def document(tmp_path_factory) -> dict:
    data = tmp_path_factory.mktemp("openapi")
    return create_app(Settings(data_dir=data, database_url=f"sqlite:///{data / 'twb.db'}")).openapi()


def undescribed(document: dict) -> list[str]:
    """Every 2xx answer whose body the document does not describe: JSON that is not a named model with
    properties, or a media type other than the operation's own."""
    out = []
    for path, operations in document["paths"].items():
        for method, op in operations.items():
            for status, answer in op["responses"].items():
                if not status.startswith("2"):
                    continue
                where = f"{method.upper()} {path} {status}"
                content = answer.get("content", {})
                if set(content) != NOT_JSON.get((method, path), {"application/json"}):
                    out.append(f"{where}: media types {sorted(content)}")
                for media, entry in content.items():
                    schema = entry.get("schema", {})
                    if media != "application/json":
                        if schema.get("type") != "string":
                            out.append(f"{where}: {media} without a string schema")
                        continue
                    name = schema.get("$ref", "").removeprefix("#/components/schemas/")
                    model = document["components"]["schemas"].get(name, {})
                    if not model.get("properties"):
                        out.append(f"{where}: JSON without a model ({schema})")
    return out


def test_every_answer_is_described(document):
    operations = [(p, m) for p, ops in document["paths"].items() for m in ops]
    assert len(operations) >= 30
    assert undescribed(document) == []


def test_an_untyped_route_is_reported(document):
    """What the check reports: a route answering a plain ``dict`` (an object schema without properties)."""
    untyped = copy.deepcopy(document)
    ok = untyped["paths"]["/api/v1/planners"]["get"]["responses"]["200"]["content"]["application/json"]
    ok["schema"] = {"type": "object", "additionalProperties": True}
    assert undescribed(untyped) == ["GET /api/v1/planners 200: JSON without a model "
                                    "({'type': 'object', 'additionalProperties': True})"]
    streamed = copy.deepcopy(document)
    streamed["paths"]["/api/v1/events"]["get"]["responses"]["200"]["content"]["application/json"] = {"schema": {}}
    assert undescribed(streamed) == ["GET /api/v1/events 200: media types ['application/json', 'text/event-stream']",
                                     "GET /api/v1/events 200: JSON without a model ({})"]
