"""The core both clients share, without any I/O: URLs, auth, request bodies, parsing, errors, waiting.

Every endpoint is described once by a method returning a :class:`Call`
(method, path, parameters, body and the function that parses the answer);
:class:`~client_sdk.Client` sends it with ``httpx.Client`` and
:class:`~client_sdk.AsyncClient` with ``httpx.AsyncClient``.  What needs
several requests (waiting, making sure an environment exists) is a *flow*: a
generator that yields :class:`Call` s (and :class:`Sleep` s) and receives
their results, or their errors thrown in; each client drives it with its own
I/O.  HTTP errors become the SDK's exceptions in :func:`raise_for_status`
and :func:`translate_errors`, nowhere else.  Whether to send a request again
after a 429 or 503 with ``Retry-After``, and when, is decided here too
(:meth:`BaseClient._retry_delay`); the clients only sleep.
"""

from __future__ import annotations

import base64
import contextlib
import email.utils
import os
import re
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Generator, Iterator, Mapping, Optional, Sequence, TypeVar, Union
from urllib.parse import quote

import httpx
import numpy as np

from contract.plugins import LoadError
from contract.vocabulary import Mode

from ._config import missing_token_hint, resolve_token, resolve_url
from ._exceptions import STATUS_ERRORS, ApiError, Conflict, NotFound, TransportError, TwbError, WaitTimeout
from ._progress import BuildEstimate, LineReporter, ProgressBar, gripper_seconds_per_block
from ._models import (
    CancelResult,
    ComparisonReport,
    Environment,
    Experiment,
    ExperimentMetrics,
    ExperimentSummary,
    Message,
    ObstacleTracks,
    Page,
    Program,
    Robot,
    Run,
    Subfield,
    User,
)

__all__ = ["API_PREFIX", "BaseClient", "Call", "Flow", "Sleep", "Waiter", "raise_for_status", "retry_after",
           "translate_errors"]

T = TypeVar("T")

API_PREFIX = "/api/v1"
USER_AGENT = "teleworkbench-sdk/0.1"
#: answers after which a request may be sent again, when they say when (``Retry-After``)
RETRY_STATUSES = frozenset({429, 503})
#: methods whose request has the same effect sent once or twice (RFC 9110, 9.2.2): only these are sent again
IDEMPOTENT_METHODS = frozenset({"GET", "HEAD", "OPTIONS", "PUT", "DELETE"})


@dataclass(frozen=True)
class Call:
    """One HTTP request and how to turn its answer into a result."""

    method: str
    path: str
    parse: Callable[[httpx.Response], Any]
    params: Optional[dict[str, Any]] = None
    json: Any = None


@dataclass(frozen=True)
class Sleep:
    """A flow's pause of ``seconds`` (wall time) between two requests."""

    seconds: float


#: a generator of requests and pauses, sent their results; returns the flow's result
Flow = Generator[Union[Call, Sleep], Any, T]


def retry_after(value: Optional[str], now: Optional[datetime] = None) -> Optional[float]:
    """Seconds a ``Retry-After`` header value asks to wait: delay-seconds or an HTTP date (0 once past);
    None when there is none or it is neither (RFC 9110, 10.2.3)."""
    if value is None:
        return None
    text = value.strip()
    if text.isascii() and text.isdigit():
        return float(text)
    try:
        when = email.utils.parsedate_to_datetime(text)
    except (TypeError, ValueError):
        return None
    if when.tzinfo is None:  # "-0000": UTC by RFC 5322
        when = when.replace(tzinfo=timezone.utc)
    return max(0.0, (when - (now or datetime.now(timezone.utc))).total_seconds())


def raise_for_status(response: httpx.Response, hint_401: str = "") -> None:
    """Raise the :class:`ApiError` subclass for an error status, carrying the server's ``detail``
    (for a 401, ``hint_401``: what to do about it; ``retry_after`` from its header)."""
    if response.status_code < 400:
        return
    try:
        body = response.json()
        detail = body.get("detail", body) if isinstance(body, dict) else body
    except ValueError:
        detail = response.text.strip() or response.reason_phrase
    cls = STATUS_ERRORS.get(response.status_code, ApiError)
    hint = hint_401 if response.status_code == 401 else ""
    raise cls(response.status_code, detail, method=response.request.method, url=str(response.request.url), hint=hint,
              retry_after=retry_after(response.headers.get("Retry-After")))


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
    """``(N, 4)`` t, x, y, theta, or ``(N, 5)`` with the robot's index last (a multi-robot run's)."""
    body = _json(response)
    return np.asarray(body["poses"], dtype=float).reshape(-1, len(body.get("columns") or ("t", "x", "y", "theta")))


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
                 interpreter: Optional[str], args: Sequence[str], stochastic: bool = False) -> dict[str, Any]:
    """The upload body of ``POST /api/v1/programs`` from a file (or its bytes) and how to run it.

    ``name`` defaults to the file's name; ``kind`` to ``python`` for a
    ``.py`` file and ``executable`` otherwise; ``stochastic`` is sent only when set (older testbeds refuse
    the key).
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
    if stochastic:
        body["stochastic"] = True
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
    max_retries : int
        How often a GET (any idempotent request; never a POST) is sent again
        after a 429 or 503 whose ``Retry-After`` says when (default 3; 0:
        never).  Then the error is raised (:class:`RateLimited`,
        :class:`Unavailable`, carrying ``retry_after``).
    max_retry_wait : float, s
        The longest all waits for one request may add up to (default 30 s):
        a ``Retry-After`` that would go beyond it raises at once.
    """

    def __init__(self, url: Optional[str] = None, token: Optional[str] = None, *, timeout: float = 30.0,
                 max_retries: int = 3, max_retry_wait: float = 30.0) -> None:
        if max_retries < 0 or not max_retry_wait >= 0:
            raise ValueError(f"`max_retries` and `max_retry_wait` must be >= 0, got {max_retries!r}, "
                             f"{max_retry_wait!r}")
        self.url = resolve_url(url)
        self.token = resolve_token(token)
        self.timeout = timeout
        self.max_retries = max_retries
        self.max_retry_wait = max_retry_wait

    def __repr__(self) -> str:
        return f"{type(self).__name__}(url={self.url!r})"

    def _headers(self) -> dict[str, str]:
        headers = {"User-Agent": USER_AGENT, "Accept": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        return headers

    def _finish(self, call: Call, response: httpx.Response) -> Any:
        raise_for_status(response, "" if self.token else missing_token_hint())
        return call.parse(response)

    def _retry_delay(self, call: Call, response: httpx.Response, retries: int, waited: float) -> Optional[float]:
        """Seconds to wait before sending ``call`` again after ``response``, or None: answer it as it is.

        Again only after a 429 or 503 with a ``Retry-After``, for an
        idempotent method, at most ``max_retries`` times and while the
        waits (``waited`` so far) stay within ``max_retry_wait``.
        """
        if response.status_code not in RETRY_STATUSES or call.method.upper() not in IDEMPOTENT_METHODS:
            return None
        delay = retry_after(response.headers.get("Retry-After"))
        if delay is None or retries >= self.max_retries or waited + delay > self.max_retry_wait:
            return None
        return delay

    # ------------------------------------------------------------------ endpoints (no I/O)

    def _health(self) -> Call:
        return Call("GET", "/health", _json)

    def _list_environments(self, offset: int, limit: int) -> Call:
        return Call("GET", f"{API_PREFIX}/environments", _page(Environment.from_json),
                    params={"offset": offset, "limit": limit})

    def _get_environment(self, name: str) -> Call:
        return Call("GET", f"{API_PREFIX}/environments/{quote(name, safe='')}", _one(Environment.from_json))

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

    def _compare(self, experiment_ids: Sequence[int], metrics: Optional[Sequence[str]], test: str, family: str,
                 confidence: float) -> Call:
        if isinstance(experiment_ids, (str, bytes)) or isinstance(metrics, (str, bytes)):
            raise TypeError("give `experiment_ids` (and `metrics`) as sequences, e.g. [1, 2, 3] and ['length_m']")
        params: dict[str, Any] = {"experiments": ",".join(str(int(i)) for i in experiment_ids), "test": test,
                                  "family": family, "confidence": confidence}
        if metrics is not None:
            params["metrics"] = ",".join(metrics)
        return Call("GET", f"{API_PREFIX}/comparisons", _one(ComparisonReport.from_json), params=params)

    def _get_run(self, run_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/runs/{int(run_id)}", _one(Run.from_json))

    def _get_poses(self, run_id: int, format: str, robot: Optional[int] = None) -> Call:
        path = f"{API_PREFIX}/runs/{int(run_id)}/poses"
        which = {} if robot is None else {"robot": int(robot)}
        if format == "csv":
            return Call("GET", path, lambda r: r.text, params={"format": "csv", **which})
        if format == "array":
            return Call("GET", path, _poses_array, params={"format": "json", **which})
        raise ValueError(f"`format` must be 'array' or 'csv', got {format!r}")

    def _get_obstacles(self, run_id: int) -> Call:
        return Call("GET", f"{API_PREFIX}/runs/{int(run_id)}/obstacles", _one(ObstacleTracks.from_json))

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

    def _list_controllers(self) -> Call:
        return Call("GET", f"{API_PREFIX}/controllers", lambda body: list(_json(body)["data"]))

    def _list_planners(self) -> Call:
        return Call("GET", f"{API_PREFIX}/planners", lambda body: list(_json(body)["data"]))

    def _plugin_load_errors(self) -> Flow[list[LoadError]]:
        """The planner plug-ins, then the controller plug-ins, the server could not load (none from a server
        whose listings have no ``load_errors``)."""
        out: list[LoadError] = []
        for kind in ("planners", "controllers"):
            body = yield Call("GET", f"{API_PREFIX}/{kind}", _json)
            out += [LoadError.from_dict(e) for e in body.get("load_errors") or []]
        return out

    def _me(self) -> Call:
        return Call("GET", f"{API_PREFIX}/users/me", _one(User.from_json))

    def _list_users(self) -> Call:
        return Call("GET", f"{API_PREFIX}/users", lambda r: _page(User.from_json)(r).data)

    def _create_user(self, name: str, is_admin: bool) -> Call:
        return Call("POST", f"{API_PREFIX}/users", _one(User.from_json), json={"name": name, "is_admin": is_admin})

    # ------------------------------------------------------------------ flows (several requests, no I/O)

    def _ensure_environment(self, environment: Mapping[str, Any] | Environment) -> Flow[tuple[Environment, bool]]:
        """The testbed's environment of this name: created now if absent (``True``), the existing one if it
        has the same size, blocks and plans (``False``); :class:`Conflict` if a different one has the name."""
        body = environment.to_json() if isinstance(environment, Environment) else _plain(environment)
        name = body.get("name") if isinstance(body, Mapping) else None
        if not isinstance(name, str) or not name.strip():
            raise ValueError("an environment needs a `name` (a non-empty string)")
        try:
            have = yield self._get_environment(name)
        except NotFound:
            try:
                return (yield self._create_environment(body)), True
            except Conflict as exc:
                raise Conflict(exc.status, f"{exc.detail}: the name {name!r} is taken by an environment you cannot "
                                           "see; give yours another name", method=exc.method, url=exc.url) from exc
        if not have.same_geometry(body):
            raise Conflict(409, f"the testbed already has a different environment named {name!r} (other size, "
                                "blocks or plans); give yours another name, or use that one",
                           method="GET", url=f"{self.url}{API_PREFIX}/environments/{name}")
        return have, False

    def _quiet(self, call: Call) -> Flow[Any]:
        """The call's result, or None if it fails (for what is only nice to know)."""
        try:
            return (yield call)
        except TwbError:
            return None

    def _wait(self, experiment_id: int, timeout: Optional[float], progress: Optional[bool], interval: float,
              ) -> Flow[Experiment]:
        """Poll the experiment until it finishes, reporting progress; :class:`WaitTimeout` after ``timeout``."""
        waiter = Waiter(experiment_id, timeout, progress, interval)
        try:
            while True:
                exp = yield self._get_experiment(experiment_id)
                for run in waiter.unexplained_builds(exp):
                    waiter.builds[run.id] = yield from self._build_estimate(exp, run, waiter)
                if waiter.update(exp):
                    return exp
                yield Sleep(waiter.sleep_time())
        finally:
            waiter.close()

    def _build_estimate(self, exp: Experiment, run: Run, waiter: "Waiter") -> Flow[BuildEstimate]:
        """How long the gripper takes to build ``exp``'s environment for ``run``: its blocks, the blocks of
        the environment it replaces, the robot's gripper and the time scale (each asked once)."""
        if waiter.health is None:
            waiter.health = (yield from self._quiet(self._health())) or {}
            waiter.robots = {r.robot_id: r for r in (yield from self._quiet(self._list_robots())) or []}
        placed = yield from waiter.block_count(self, exp.environment.removesuffix(" (full)"))
        subfields = (yield from self._quiet(self._list_subfields())) or []
        old = next((s.environment for s in subfields if s.id == run.subfield), None)
        removed = None
        if old is not None and old.removesuffix(" (full)") != exp.environment:
            removed = yield from waiter.block_count(self, old.removesuffix(" (full)"))
        elif run.subfield is not None:
            removed = 0
        robot = waiter.robots.get(run.robot_id or "")
        spb = gripper_seconds_per_block(robot.profile) if robot is not None and robot.profile else None
        if robot is not None and robot.backend == "ideal":
            spb = 0.0
        return BuildEstimate(placed or 0, removed, spb, waiter.health.get("time_scale"),
                             known_scale="time_scale" in waiter.health)


class Waiter:
    """The logic of ``wait()`` without sleeping: deadline, progress, timeout error.

    ``update(experiment)`` reports progress and returns True once the
    experiment is finished; the wait flow polls and sleeps ``interval``
    between updates.  ``progress``: True shows a rich bar on a terminal and
    plain status lines elsewhere; None the bar on a terminal and nothing
    elsewhere; False nothing.
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
        self._reporter = _reporter(f"experiment {self.experiment_id}", progress)
        self.last: Optional[Experiment] = None
        self.builds: dict[int, BuildEstimate] = {}
        self.health: Optional[dict[str, Any]] = None
        self.robots: dict[str, Robot] = {}
        self._blocks: dict[str, Optional[int]] = {}

    def unexplained_builds(self, exp: Experiment) -> list[Run]:
        """Field runs the gripper builds for, whose build time is not estimated yet (none without progress)."""
        if self._reporter is None:
            return []
        return [r for r in exp.runs if r.status == "building" and r.mode == Mode.TWB and r.id not in self.builds]

    def block_count(self, client: BaseClient, name: str) -> Flow[Optional[int]]:
        """Blocks of environment ``name`` (None if it cannot be read), asked once per name."""
        if name not in self._blocks:
            env = yield from client._quiet(client._get_environment(name))
            self._blocks[name] = None if env is None else len(env.blocks)
        return self._blocks[name]

    def update(self, exp: Experiment) -> bool:
        self.last = exp
        if self._reporter is not None:
            self._reporter.update(exp, self.builds)
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
        if self._reporter is not None:
            self._reporter.close()


def _reporter(label: str, progress: Optional[bool]) -> Optional[LineReporter | ProgressBar]:
    """A bar on a terminal, lines elsewhere when ``progress`` is True, nothing when it is False."""
    if progress is False:
        return None
    if sys.stderr.isatty():
        return ProgressBar(label)
    return LineReporter() if progress else None
