"""The SDK's models (``client_sdk/_models.py``) cannot drift from the server's schemas.

The SDK mirrors the server's response models by hand (it imports no server
code).  This test reads the server's OpenAPI document and, for every endpoint
the SDK describes (``BaseClient._get_run`` ...), builds a full answer from the
operation's response schema, lets the SDK's own parser read it and notes every
key the parser looks at.  It reports:

* an operation the SDK calls that the server does not have;
* a key the SDK reads that the response schema does not have (a renamed or
  removed field: the SDK would silently fall back to its default);
* a key the SDK reads with ``data[key]``, or a field the SDK model requires,
  that the schema does not require (the SDK would fail when it is absent);
* a field whose SDK type does not accept the schema's type (``int`` for a
  ``number``, ``str`` for a nullable string ...);
* a field the server sends that the SDK does not expose, unless
  :data:`NOT_EXPOSED` says why.

The last test shows each report on a deliberately drifted copy of the document.
"""

from __future__ import annotations

import copy
import dataclasses
import re
import types
import typing
from datetime import datetime
from typing import Any, Iterator, Optional, Union

import httpx
import numpy as np
import pytest

from client_sdk import _models
from client_sdk._base import BaseClient, Call
from server.app import create_app
from server.core.settings import Settings

#: every endpoint of the SDK and the arguments to describe one call of it
ENDPOINTS: dict[str, tuple[Any, ...]] = {
    "_health": (),
    "_list_environments": (0, 10),
    "_get_environment": ("room",),
    "_create_environment": ({"name": "e", "size": [1.8, 1.8], "blocks": []},),
    "_submit": (None, {"environment": "room"}),
    "_list_experiments": (None, 0, 10),
    "_get_experiment": (1,),
    "_cancel": (1,),
    "_cancel_many": ([1, 2],),
    "_get_metrics": (1,),
    "_compare": ([1, 2], None, "t", "metric", 0.95),
    "_get_run": (1,),
    "_get_poses": (1, "array"),
    "_get_obstacles": (1,),
    "_get_messages": (1, 0, 10),
    "_list_subfields": (),
    "_list_robots": (),
    "_upload_program": ({"name": "p", "content_base64": "eA=="},),
    "_list_programs": (0, 10),
    "_get_program": (1,),
    "_sandbox_info": (),
    "_list_controllers": (),
    "_list_planners": (),
    "_me": (),
    "_list_users": (),
    "_create_user": ("u", False),
}

#: fields the server sends that the SDK leaves out on purpose: schema -> {field: why}
NOT_EXPOSED: dict[str, dict[str, str]] = {
    "PluginPage_ControllerPublic_": {"count": "list_controllers() returns the list",
                                     "load_errors": "plugin_load_errors() reads them"},
    "PluginPage_PlannerPublic_": {"count": "list_planners() returns the list",
                                  "load_errors": "plugin_load_errors() reads them"},
    "ObstacleTrackPublic": {"index": "tracks[k] is moving_obstacles[k]", "count": "len(tracks[k])"},
    "RunObstaclesPublic": {"columns": "always t, x, y, theta: the array's columns"},
    "RunPosesPublic": {"run_id": "the caller's own argument", "count": "len() of the array"},
}

#: keys the SDK asks for (``in``, ``.get``) that a schema does not have, on purpose: schema -> {key: why}
NOT_SENT: dict[str, dict[str, str]] = {
    "UserPublic": {"token": "User also parses UserWithToken, the answer that has it"},
}

#: an array in a built answer: 12 items, so that rows reshape to 3 (a planned path) or 4 (poses) columns
ITEMS = 12
ANY = frozenset({"null", "boolean", "integer", "number", "string", "array", "object"})


@pytest.fixture(scope="module")
def document(tmp_path_factory) -> dict[str, Any]:
    data = tmp_path_factory.mktemp("openapi")
    return create_app(Settings(data_dir=data, database_url=f"sqlite:///{data / 'twb.db'}")).openapi()


# --------------------------------------------------------------------------- answers that note what is read


class Answer(dict):
    """A JSON object of the response schema ``name`` that notes the keys read: ``[key]`` (it must be there,
    unless ``key in`` asked first) apart from ``.get(key)`` and ``key in``; iterating it reads every key."""

    def __init__(self, name: str, items: dict[str, Any], reads: "Reads") -> None:
        super().__init__(items)
        self.name, self._reads, self._asked = name, reads, set()

    def __getitem__(self, key: str) -> Any:
        self._reads.note(self.name, key, must=key not in self._asked)
        return super().__getitem__(key)

    def get(self, key: str, default: Any = None) -> Any:
        self._reads.note(self.name, key, must=False)
        return super().get(key, default)

    def __contains__(self, key: object) -> bool:
        self._reads.note(self.name, str(key), must=False)
        self._asked.add(key)
        return super().__contains__(key)

    def __iter__(self) -> Iterator[str]:
        for key in super().keys():
            self._reads.note(self.name, key, must=False)
        return super().__iter__()

    def items(self):  # type: ignore[no-untyped-def]
        list(self)
        return super().items()


@dataclasses.dataclass
class Reads:
    """Keys read per schema: all of them, and those read with ``[key]``."""

    keys: dict[str, set[str]] = dataclasses.field(default_factory=dict)
    must: dict[str, set[str]] = dataclasses.field(default_factory=dict)

    def note(self, schema: str, key: str, must: bool) -> None:
        self.keys.setdefault(schema, set()).add(key)
        if must:
            self.must.setdefault(schema, set()).add(key)


def component(document: dict[str, Any], schema: dict[str, Any]) -> tuple[Optional[str], dict[str, Any]]:
    """The schema itself, or the component a ``$ref`` names (with its name)."""
    ref = schema.get("$ref")
    if ref is None:
        return None, schema
    name = ref.removeprefix("#/components/schemas/")
    return name, document["components"]["schemas"][name]


def build(document: dict[str, Any], schema: dict[str, Any], reads: Reads) -> Any:
    """One value of ``schema`` with every property present (the first choice of a union that is not null)."""
    name, schema = component(document, schema)
    if "anyOf" in schema or "oneOf" in schema:
        choices = schema.get("anyOf") or schema["oneOf"]
        return build(document, next((c for c in choices if c.get("type") != "null"), choices[0]), reads)
    if "const" in schema:
        return schema["const"]
    if "enum" in schema:
        return schema["enum"][0]
    kind = schema.get("type")
    if kind == "object" or "properties" in schema:
        if "properties" in schema:
            return Answer(name or schema.get("title", "?"),
                          {k: build(document, v, reads) for k, v in schema["properties"].items()}, reads)
        extra = schema.get("additionalProperties", True)
        return {"key": build(document, extra if isinstance(extra, dict) else {}, reads)}
    if kind == "array":
        n = min(max(schema.get("minItems", ITEMS), ITEMS), schema.get("maxItems", ITEMS))
        return [build(document, schema.get("items", {}), reads) for _ in range(n)]
    return {"string": "2026-01-02T03:04:05Z" if schema.get("format") == "date-time" else "text",
            "integer": 1, "number": 0.5, "boolean": True, "null": None}.get(kind, 1)


class Recorded(httpx.Response):
    """An answer whose ``json()`` is the built, reading-noting object (its bytes are never parsed)."""

    def __init__(self, body: Any) -> None:
        super().__init__(200, json=None)
        self._body = body

    def json(self, **kwargs: Any) -> Any:
        return self._body


# --------------------------------------------------------------------------- types


def json_types(document: dict[str, Any], schema: dict[str, Any]) -> frozenset[str]:
    """The JSON types a schema allows (every type for ``{}``)."""
    _, schema = component(document, schema)
    if "anyOf" in schema or "oneOf" in schema:
        return frozenset().union(*(json_types(document, c) for c in schema.get("anyOf") or schema["oneOf"]))
    if "const" in schema:
        return frozenset({{bool: "boolean", int: "integer", float: "number", str: "string"}[type(schema["const"])]})
    kind = schema.get("type")
    if kind is None:
        return frozenset({"object"}) if "properties" in schema else ANY
    return frozenset(kind if isinstance(kind, list) else [kind])


def incompatible(document: dict[str, Any], hint: Any, schema: dict[str, Any]) -> Optional[str]:
    """Why an SDK field of type ``hint`` cannot hold what ``schema`` allows, or None."""
    if hint is Any or isinstance(hint, typing.TypeVar):
        return None
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    options = args if origin in (Union, types.UnionType) else (hint,)
    accepted: set[str] = set()
    for h in options:
        o = typing.get_origin(h) or h
        accepted |= {type(None): {"null"}, bool: {"boolean"}, int: {"integer"}, float: {"number", "integer"},
                     str: {"string"}, datetime: {"string"}, list: {"array"}, np.ndarray: {"array"},
                     dict: {"object"}}.get(o, {"object"} if dataclasses.is_dataclass(o) else ANY)
    allowed = json_types(document, schema)
    if not allowed <= accepted:
        return f"{_name(hint)} does not accept {'/'.join(sorted(allowed - accepted))}"
    _, schema = component(document, schema)
    for member in schema.get("anyOf") or schema.get("oneOf") or [schema]:
        _, member = component(document, member)
        for h in options:
            inner = typing.get_args(h)
            if typing.get_origin(h) is list and member.get("type") == "array" and inner:
                why = incompatible(document, inner[0], member.get("items", {}))
                if why:
                    return f"{_name(h)}: {why}"
            extra = member.get("additionalProperties")
            if typing.get_origin(h) is dict and member.get("type") == "object" and isinstance(extra, dict):
                why = incompatible(document, inner[1], extra)
                if why:
                    return f"{_name(h)}: {why}"
    return None


def _name(hint: Any) -> str:
    return re.sub(r"\b(typing|datetime|numpy|client_sdk\._models)\.", "", str(hint).replace("NoneType", "None")) \
        if not isinstance(hint, type) else hint.__name__


# --------------------------------------------------------------------------- the check


def operation(document: dict[str, Any], call: Call) -> Optional[tuple[str, dict[str, Any]]]:
    """The operation ``call`` goes to: its path template and its success answer's JSON schema."""
    for template, operations in document["paths"].items():
        if re.fullmatch(re.sub(r"\{[^}]+\}", "[^/]+", template), call.path) and call.method.lower() in operations:
            answers = operations[call.method.lower()]["responses"]
            ok = next(a for status, a in answers.items() if status.startswith("2"))
            return template, ok["content"]["application/json"]["schema"]
    return None


def pairs(result: Any, body: Any) -> Iterator[tuple[Any, Answer]]:
    """The SDK objects a parser made and the answer objects they were made from (matched by field name)."""
    if isinstance(result, list) and isinstance(body, Answer) and dict.__contains__(body, "data"):
        body = dict.__getitem__(body, "data")
    if dataclasses.is_dataclass(result) and isinstance(body, Answer):
        yield result, body
        for f in dataclasses.fields(result):
            if dict.__contains__(body, f.name):
                yield from pairs(getattr(result, f.name), dict.__getitem__(body, f.name))
    elif isinstance(result, list) and isinstance(body, list) and len(result) == len(body):
        for r, b in zip(result, body):
            yield from pairs(r, b)
    elif isinstance(result, dict) and isinstance(body, dict) and not isinstance(body, Answer):
        for k in result.keys() & body.keys():
            yield from pairs(result[k], body[k])


def parse_all(document: dict[str, Any], out: list[str]) -> tuple[Reads, list[tuple[Any, Answer]]]:
    """Every SDK endpoint's parser run on a built answer of its operation: the keys read, and the SDK objects
    made with the answer objects they were made from; an operation the server lacks is added to ``out``."""
    reads, made = Reads(), []
    client = BaseClient("http://twb.test", "token")
    for method, args in ENDPOINTS.items():
        call: Call = getattr(client, method)(*args)
        found = operation(document, call)
        if found is None:
            out.append(f"{method}: the SDK calls {call.method} {call.path}, an operation the server does not have")
            continue
        body = build(document, found[1], reads)
        try:
            made += pairs(call.parse(Recorded(body)), body)
        except Exception as exc:  # noqa: BLE001 - what the SDK would raise on such an answer, reported
            out.append(f"{method}: the SDK cannot parse the server's answer to {call.method} {found[0]}: "
                       f"{type(exc).__name__}: {exc}")
    return reads, made


def _generic(cls: type) -> bool:
    """Whether ``cls`` takes each field straight from the key of its name (``_FromJson``, converters aside)."""
    return getattr(cls.from_json, "__func__", None) is _models._FromJson.from_json.__func__ \
        if hasattr(cls, "from_json") else False


def drift(document: dict[str, Any]) -> list[str]:
    """Every way the SDK's endpoints and models disagree with ``document`` (empty: none)."""
    out: list[str] = []
    reads, made = parse_all(document, out)
    schemas = document["components"]["schemas"]
    for name, keys in sorted(reads.keys.items()):
        schema = schemas[name]
        props, required = set(schema.get("properties", {})), set(schema.get("required", []))
        missing = keys - props - set(NOT_SENT.get(name, {}))
        out += [f"{name}: the SDK reads `{k}`, which the server's {name} does not have" for k in sorted(missing)]
        out += [f"{name}: the SDK reads `{k}` with [{k!r}], but the server's {name} may leave it out"
                for k in sorted(reads.must.get(name, set()) & props - required)]
        unread = props - keys - set(NOT_EXPOSED.get(name, {}))
        out += [f"{name}: the server sends `{k}`, which the SDK does not expose" for k in sorted(unread)]
    checked = set()
    for obj, answer in made:
        cls, name = type(obj), answer.name
        props, required = schemas[name].get("properties", {}), set(schemas[name].get("required", []))
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            # a custom parser's field is checked where it holds the answer's value as it came
            raw = f.name in props and (_generic(cls) or getattr(obj, f.name) == dict.get(answer, f.name))
            if not raw or (cls, name, f.name) in checked:
                continue
            checked.add((cls, name, f.name))
            why = incompatible(document, hints[f.name], props[f.name])
            if why:
                out.append(f"{cls.__name__}.{f.name}: {why} ({name}.{f.name})")
            no_default = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            if no_default and f.name not in required:
                out.append(f"{cls.__name__}.{f.name} is required by the SDK, but the server's {name} may leave it out")
    return sorted(out)


# --------------------------------------------------------------------------- tests


def test_every_endpoint_of_the_sdk_is_checked():
    described = {name for name, fn in vars(BaseClient).items()
                 if callable(fn) and typing.get_type_hints(fn).get("return") is Call}
    assert described == set(ENDPOINTS)


def test_the_sdk_models_match_the_servers_schemas(document):
    assert drift(document) == []


def test_every_response_model_of_the_sdk_is_reached(document):
    """Each model of ``client_sdk._models`` that parses a response is paired with a schema by the check."""
    _, made = parse_all(document, [])
    models = {getattr(_models, n) for n in dir(_models)
              if dataclasses.is_dataclass(getattr(_models, n)) and hasattr(getattr(_models, n), "from_json")}
    assert models - {type(obj) for obj, _ in made} == set()


def _drifted(document: dict[str, Any], change) -> list[str]:  # type: ignore[no-untyped-def]
    copied = copy.deepcopy(document)
    change(copied["components"]["schemas"], copied["paths"])
    return drift(copied)


def test_a_drifted_schema_is_reported(document):
    def rename(schemas, paths):  # type: ignore[no-untyped-def]
        run = schemas["RunPublic"]
        run["properties"]["sub_field"] = run["properties"].pop("subfield")
        run["required"] = [k if k != "subfield" else "sub_field" for k in run["required"]]

    assert _drifted(document, rename) == [
        "RunPublic: the SDK reads `subfield`, which the server's RunPublic does not have",
        "RunPublic: the server sends `sub_field`, which the SDK does not expose"]

    def retype(schemas, paths):  # type: ignore[no-untyped-def]
        schemas["RunPublic"]["properties"]["repetition"] = {"type": "number"}
        schemas["RobotPublic"]["properties"]["subfield"] = {"anyOf": [{"type": "string"}, {"type": "null"}]}

    assert _drifted(document, retype) == [
        "Robot.subfield: Optional[int] does not accept string (RobotPublic.subfield)",
        "Run.repetition: int does not accept number (RunPublic.repetition)"]

    def optional(schemas, paths):  # type: ignore[no-untyped-def]
        schemas["RunPublic"]["required"].remove("experiment_id")
        schemas["ExperimentMetricsPublic"]["required"].remove("status")

    assert _drifted(document, optional) == [
        "ExperimentMetrics.status is required by the SDK, but the server's ExperimentMetricsPublic may leave it out",
        "ExperimentMetricsPublic: the SDK reads `status` with ['status'], but the server's ExperimentMetricsPublic "
        "may leave it out",
        "Run.experiment_id is required by the SDK, but the server's RunPublic may leave it out"]

    def rows(schemas, paths):  # type: ignore[no-untyped-def]
        track = schemas["ObstacleTrackPublic"]
        track["properties"]["rows"] = track["properties"].pop("poses")

    assert _drifted(document, rows) == [  # the parser stopped at `poses`, before it read `radius`
        "ObstacleTrackPublic: the SDK reads `poses`, which the server's ObstacleTrackPublic does not have",
        "ObstacleTrackPublic: the server sends `radius`, which the SDK does not expose",
        "ObstacleTrackPublic: the server sends `rows`, which the SDK does not expose",
        "_get_obstacles: the SDK cannot parse the server's answer to GET /api/v1/runs/{run_id}/obstacles: "
        "KeyError: 'poses'"]

    def move(schemas, paths):  # type: ignore[no-untyped-def]
        paths["/api/v1/runs/{run_id}/lines"] = paths.pop("/api/v1/runs/{run_id}/messages")

    assert _drifted(document, move) == [
        "_get_messages: the SDK calls GET /api/v1/runs/1/messages, an operation the server does not have"]
