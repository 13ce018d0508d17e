"""The core both clients share, without any I/O: URLs, auth, request bodies, parsing, errors, waiting.

Every endpoint is described once by a method returning a :class:`Call`
(method, path, parameters, body and the function that parses the answer);
:class:`~client_sdk.Client` sends it with ``httpx.Client`` and
:class:`~client_sdk.AsyncClient` with ``httpx.AsyncClient``.  HTTP errors
become the SDK's exceptions in :func:`raise_for_status` and
:func:`translate_errors`, nowhere else.
"""

from __future__ import annotations

import base64
import contextlib
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Optional, Sequence

import httpx
import numpy as np

from ._config import resolve_token, resolve_url
from ._exceptions import STATUS_ERRORS, ApiError, TransportError, TwbError, WaitTimeout
from ._models import (
    CancelResult,
    Environment,
    Experiment,
    ExperimentMetrics,
    ExperimentSummary,
    Message,
    Page,
    Program,
    Robot,
    Run,
    Subfield,
    User,
)

__all__ = ["API_PREFIX", "BaseClient", "Call", "Waiter", "raise_for_status", "translate_errors"]

API_PREFIX = "/api/v1"
USER_AGENT = "teleworkbench-sdk/0.1"


@dataclass(frozen=True)
class Call:
    """One HTTP request and how to turn its answer into a result."""

    method: str
    path: str
    parse: Callable[[httpx.Response], Any]
    params: Optional[dict[str, Any]] = None
    json: Any = None


def raise_for_status(response: httpx.Response) -> None:
    """Raise the :class:`ApiError` subclass for an error status, carrying the server's ``detail``."""
    if response.status_code < 400:
        return
    try:
        body = response.json()
        detail = body.get("detail", body) if isinstance(body, dict) else body
    except ValueError:
        detail = response.text.strip() or response.reason_phrase
    cls = STATUS_ERRORS.get(response.status_code, ApiError)
    raise cls(response.status_code, detail, method=response.request.method, url=str(response.request.url))


@contextlib.contextmanager
def translate_errors(base_url: str) -> Iterator[None]:
    """Turn httpx's errors into :class:`TransportError` (``raise ... from exc``)."""
    try:
        yield
    except httpx.TimeoutException as exc:
        raise TransportError(f"the testbed at {base_url} did not answer in time ({type(exc).__name__})") from exc
    except httpx.TransportError as exc:
        reason = str(exc) or type(exc).__name__
        raise TransportError(f"cannot reach the testbed at {base_url}: {reason}") from exc
    except httpx.HTTPError as exc:  # e.g. a malformed URL
        raise TwbError(f"request to {base_url} failed: {exc}") from exc


def _json(response: httpx.Response) -> Any:
    try:
        return response.json()
    except ValueError as exc:
        raise TwbError(f"the server sent a response that is not JSON ({response.headers.get('content-type')})") from exc


def _page(item: Callable[[dict[str, Any]], Any]) -> Callable[[httpx.Response], Page]:
    def parse(response: httpx.Response) -> Page:
        body = _json(response)
        return Page(data=[item(d) for d in body["data"]], count=body["count"])

    return parse


def _one(item: Callable[[dict[str, Any]], Any]) -> Callable[[httpx.Response], Any]:
    return lambda response: item(_json(response))


def _poses_array(response: httpx.Response) -> np.ndarray:
    body = _json(response)
    return np.asarray(body["poses"], dtype=float).reshape(-1, 4)


def _plain(value: Any) -> Any:
    """JSON-ready copy: numpy arrays and scalars, tuples become lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def program_body(program: str | os.PathLike[str] | bytes, name: Optional[str], kind: Optional[str],
                 interpreter: Optional[str], args: Sequence[str]) -> dict[str, Any]:
    """The upload body of ``POST /api/v1/programs`` from a file (or its bytes) and how to run it.

    ``name`` defaults to the file's name; ``kind`` to ``python`` for a
    ``.py`` file and ``executable`` otherwise.
    """
    if isinstance(program, bytes):
        if not name:
            raise ValueError("give a `name` when uploading a program's bytes")
        content = program
    else:
        path = Path(program)
        try:
            content = path.read_bytes()
        except OSError as exc:
            raise TwbError(f"cannot read program {path}: {exc.strerror or exc}") from exc
        name = name or re.sub(r"[^A-Za-z0-9_.+-]", "_", path.name)[:100]
        kind = kind or ("python" if path.suffix == ".py" and interpreter is None else None)
    kind = kind or "executable"
    body: dict[str, Any] = {"name": name, "kind": kind, "args": [str(a) for a in args],
                            "content_base64": base64.b64encode(content).decode()}
    if interpreter is not None:
        body["interpreter"] = interpreter
    return body


class BaseClient:
    """Configuration and endpoint descriptions shared by :class:`Client` and :class:`AsyncClient`.

    Parameters
    ----------
    url : str, optional
        Server URL; default ``$TWB_URL`` or ``http://127.0.0.1:8000``.
    token : str, optional
        Bearer token; default ``$TWB_TOKEN`` or the token file of ``twb up``
        (see :mod:`client_sdk._config`).
    timeout : float, s
        Timeout of each HTTP request (default 30 s).
    """

    def __init__(self, url: Optional[str] = None, token: Optional[str] = None, *, timeout: float = 30.0) -> None:
        self.url = resolve_url(url)
        self.token = resolve_token(token)
        self.timeout = timeout

    def __repr__(self) -> str:
        return f"{type(self).__name__}(url={self.url!r})"

    def _headers(self) -> dict[str, str]:
        headers = {"User-Agent": USER_AGENT, "Accept": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        return headers

    @staticmethod
    def _finish(call: Call, response: httpx.Response) -> Any:
        raise_for_status(response)
        return call.parse(response)

    # ------------------------------------------------------------------ endpoints (no I/O)

    def _health(self) -> Call:
        return Call("GET", "/health", _json)

    def _list_environments(self, offset: int, limit: int) -> Call:
        return Call("GET", f"{API_PREFIX}/environments", _page(Environment.from_json),
                    params={"offset": offset, "limit": limit})

    def _get_environment(self, name: str) -> Call:
        return Call("GET", f"{API_PREFIX}/environments/{name}", _one(Environment.from_json))

    def _create_environment(self, environment: Mapping[str, Any] | Environment) -> Call:
        body = environment.to_json() if isinstance(environment, Environment) else _plain(environment)
        return Call("POST", f"{API_PREFIX}/environments", _one(Environment.from_json), json=body)

    def _submit(self, job: Optional[Mapping[str, Any]], fields: dict[str, Any]) -> Call:
        body = dict(_plain(job) if job else {})
        body.update({k: _plain(v) for k, v in fields.items() if v is not None})
        if "environment" not in body:
            raise ValueError("a job needs an `environment` (a built-in name such as 'room' or one you created)")
        return Call("POST", f"{API_PREFIX}/experiments", _one(Experiment.from_json), json=body)

    def _list_experiments(self, status: Optional[str], offset: int, limit: int) -> Call:
        params: dict[str, Any] = {"offset": offset, "limit": limit}
        if status:
            params["status"] = status
        return Call("GET", f"{API_PREFIX}/experiments", _page(ExperimentSummary.from_json), params=params)

    def _get_experiment(self, experiment_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/experiments/{int(experiment_id)}", _one(Experiment.from_json))

    def _cancel(self, experiment_id: int) -> Call:
        return Call("POST", f"{API_PREFIX}/experiments/{int(experiment_id)}/cancel", _one(Experiment.from_json))

    def _cancel_many(self, experiment_ids: Sequence[int]) -> Call:
        return Call("POST", f"{API_PREFIX}/experiments/cancel", _one(CancelResult.from_json),
                    json={"ids": [int(i) for i in experiment_ids]})

    def _get_metrics(self, experiment_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/experiments/{int(experiment_id)}/metrics", _one(ExperimentMetrics.from_json))

    def _get_run(self, run_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/runs/{int(run_id)}", _one(Run.from_json))

    def _get_poses(self, run_id: int, format: str) -> Call:
        path = f"{API_PREFIX}/runs/{int(run_id)}/poses"
        if format == "csv":
            return Call("GET", path, lambda r: r.text, params={"format": "csv"})
        if format == "array":
            return Call("GET", path, _poses_array, params={"format": "json"})
        raise ValueError(f"`format` must be 'array' or 'csv', got {format!r}")

    def _get_messages(self, run_id: int, offset: int, limit: int) -> Call:
        return Call("GET", f"{API_PREFIX}/runs/{int(run_id)}/messages", _page(Message.from_json),
                    params={"offset": offset, "limit": limit})

    def _list_subfields(self) -> Call:
        return Call("GET", f"{API_PREFIX}/subfields", lambda r: _page(Subfield.from_json)(r).data)

    def _list_robots(self) -> Call:
        return Call("GET", f"{API_PREFIX}/robots", lambda r: _page(Robot.from_json)(r).data)

    def _upload_program(self, body: dict[str, Any]) -> Call:
        return Call("POST", f"{API_PREFIX}/programs", _one(Program.from_json), json=body)

    def _list_programs(self, offset: int, limit: int) -> Call:
        return Call("GET", f"{API_PREFIX}/programs", _page(Program.from_json), params={"offset": offset, "limit": limit})

    def _get_program(self, program_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/programs/{int(program_id)}", _one(Program.from_json))

    def _sandbox_info(self) -> Call:
        return Call("GET", f"{API_PREFIX}/programs/sandbox", _json)

    def _me(self) -> Call:
        return Call("GET", f"{API_PREFIX}/users/me", _one(User.from_json))

    def _list_users(self) -> Call:
        return Call("GET", f"{API_PREFIX}/users", lambda r: _page(User.from_json)(r).data)

    def _create_user(self, name: str, is_admin: bool) -> Call:
        return Call("POST", f"{API_PREFIX}/users", _one(User.from_json), json={"name": name, "is_admin": is_admin})


class Waiter:
    """The logic of ``wait()`` without sleeping: deadline, progress bar, timeout error.

    ``update(experiment)`` returns True once the experiment is finished;
    the clients poll and sleep ``interval`` between updates.
    """

    def __init__(self, experiment_id: int, timeout: Optional[float], progress: Optional[bool],
                 interval: float) -> None:
        if timeout is not None and not timeout > 0:
            raise ValueError(f"`timeout` must be > 0 seconds or None, got {timeout!r}")
        if not interval > 0:
            raise ValueError(f"`interval` must be > 0 seconds, got {interval!r}")
        self.experiment_id = int(experiment_id)
        self.timeout = timeout
        self.interval = interval
        self.t0 = time.monotonic()
        if progress is None:
            progress = sys.stderr.isatty()
        self._bar = _ProgressBar(f"experiment {self.experiment_id}") if progress else None
        self.last: Optional[Experiment] = None

    def update(self, exp: Experiment) -> bool:
        self.last = exp
        if self._bar is not None:
            self._bar.update(exp.runs_done, exp.runs_total, exp.status)
        return exp.finished

    def sleep_time(self) -> float:
        """Seconds to sleep before the next poll; raises :class:`WaitTimeout` when time is up."""
        if self.timeout is None:
            return self.interval
        left = self.timeout - (time.monotonic() - self.t0)
        if left <= 0:
            exp = self.last
            state = f"still {exp.status} ({exp.runs_done}/{exp.runs_total} runs done)" if exp else "not seen"
            raise WaitTimeout(f"experiment {self.experiment_id} {state} after {self.timeout:g} s; "
                              "it keeps running on the testbed: wait again or cancel it", exp)
        return min(self.interval, left)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


class _ProgressBar:
    """A rich progress bar on stderr: runs done / total and the experiment's status."""

    def __init__(self, label: str) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("runs"),
            TextColumn("[bold]{task.fields[status]}"), TimeElapsedColumn(),
            console=Console(stderr=True), transient=False,
        )
        self._task = self._progress.add_task(label, total=None, status="")
        self._progress.start()

    def update(self, done: int, total: int, status: str) -> None:
        self._progress.update(self._task, completed=done, total=total or None, status=status)

    def close(self) -> None:
        self._progress.stop()

