"""``Client`` and ``AsyncClient``: the I/O over the shared :class:`~client_sdk._base.BaseClient`.

Both have the same methods with the same arguments and results; the async
ones are coroutines.  Each method only sends the :class:`~client_sdk._base.Call`
its twin in the base class describes.
"""

from __future__ import annotations

import asyncio
import os
import time
from pathlib import Path
from typing import Any, Literal, Mapping, Optional, Sequence, TypeVar, overload

import httpx
import numpy as np

from contract.plugins import LoadError

from ._base import API_PREFIX, BaseClient, Call, Flow, Sleep, program_body, raise_for_status, translate_errors
from ._config import missing_token_hint
from ._export import ExportFormat, export_target
from ._exceptions import TwbError
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

__all__ = ["AsyncClient", "Client"]

Pose = Sequence[float] | np.ndarray
PosesFormat = Literal["array", "csv"]
T = TypeVar("T")


class Client(BaseClient):
    """Synchronous client of the Teleworkbench REST API.

    >>> from client_sdk import Client
    >>> with Client() as twb:                                    # doctest: +SKIP
    ...     exp = twb.submit("room", start=[0.3, 0.3, 0], goal=[1.5, 1.5, 1.57], planner="fm2")
    ...     exp = twb.wait(exp.id, timeout=300)
    ...     print(twb.get_metrics(exp.id).aggregates["twb"].metrics["length_m"].mean)

    Parameters
    ----------
    url, token, timeout, max_retries, max_retry_wait
        See :class:`~client_sdk._base.BaseClient` (``$TWB_URL``, ``$TWB_TOKEN``,
        the token file of ``twb up``; a GET answered 429 or 503 with
        ``Retry-After`` is sent again after that many seconds, 3 times and 30 s
        at most by default).
    transport : httpx.BaseTransport, optional
        Injected transport, e.g. ``httpx.MockTransport`` in tests or
        ``httpx.HTTPTransport(retries=3)``.
    """

    def __init__(self, url: Optional[str] = None, token: Optional[str] = None, *, timeout: float = 30.0,
                 transport: Optional[httpx.BaseTransport] = None, max_retries: int = 3,
                 max_retry_wait: float = 30.0) -> None:
        super().__init__(url, token, timeout=timeout, max_retries=max_retries, max_retry_wait=max_retry_wait)
        self._http = httpx.Client(base_url=self.url, headers=self._headers(), timeout=timeout, transport=transport)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def _send(self, call: Call) -> Any:
        """Send ``call``, again after a ``Retry-After`` while :meth:`_retry_delay` says so; its result."""
        retries, waited = 0, 0.0
        while True:
            with translate_errors(self.url):
                response = self._http.request(call.method, call.path, params=call.params, json=call.json)
            delay = self._retry_delay(call, response, retries, waited)
            if delay is None:
                return self._finish(call, response)
            time.sleep(delay)
            retries, waited = retries + 1, waited + delay

    def _run(self, flow: Flow[T]) -> T:
        """Drive a flow: send its calls, sleep its pauses, throw errors back into it."""
        step, value = flow.send, None
        try:
            while True:
                try:
                    item = step(value)
                except StopIteration as stop:
                    return stop.value
                try:
                    if isinstance(item, Sleep):
                        step, value = flow.send, time.sleep(item.seconds)
                    else:
                        step, value = flow.send, self._send(item)
                except TwbError as exc:
                    step, value = flow.throw, exc
        finally:
            flow.close()

    # ------------------------------------------------------------------ testbed

    def health(self) -> dict[str, Any]:
        """``GET /health`` (no token needed): status and version; with a valid token also the queue and fleet counts."""
        return self._send(self._health())

    def list_subfields(self) -> list[Subfield]:
        """The four sub-fields: state, environment built, robot, current run."""
        return self._send(self._list_subfields())

    def list_robots(self) -> list[Robot]:
        """Registered robots: field robots and the simulation pool."""
        return self._send(self._list_robots())

    # ------------------------------------------------------------------ users

    def me(self) -> User:
        """The user the token belongs to."""
        return self._send(self._me())

    def list_users(self) -> list[User]:
        """All users (admin token)."""
        return self._send(self._list_users())

    def create_user(self, name: str, *, is_admin: bool = False) -> User:
        """Create a user (admin token); the result carries its token, shown once."""
        return self._send(self._create_user(name, is_admin))

    # ------------------------------------------------------------------ environments

    def list_environments(self, *, offset: int = 0, limit: int = 100) -> Page[Environment]:
        """Built-in environments and your own."""
        return self._send(self._list_environments(offset, limit))

    def get_environment(self, name: str) -> Environment:
        """One environment by name (:class:`NotFound` if unknown)."""
        return self._send(self._get_environment(name))

    def create_environment(self, environment: Mapping[str, Any] | Environment) -> Environment:
        """Add an environment file (docs/design.md, "Environment file"); :class:`Conflict` if the name is taken."""
        return self._send(self._create_environment(environment))

    def ensure_environment(self, environment: Mapping[str, Any] | Environment) -> tuple[Environment, bool]:
        """Make sure the testbed has this environment: ``(environment, created)``.

        Creates it when its name is unknown (``created`` True); uses the
        testbed's when that has the same size, blocks and plans (False);
        :class:`Conflict` when a different environment has the name.
        """
        return self._run(self._ensure_environment(environment))

    # ------------------------------------------------------------------ uploaded programs

    def upload_program(self, program: str | os.PathLike[str] | bytes, *, name: Optional[str] = None,
                       kind: Optional[str] = None, interpreter: Optional[str] = None,
                       args: Sequence[str] = (), stochastic: bool = False) -> Program:
        """Upload a planner program (docs/uploads.md); returns it with its ``id`` for ``submit(program=)``.

        ``program`` is a file (``name`` defaults to its name; ``kind`` to
        ``python`` for ``.py``, else ``executable``) or its bytes (give
        ``name``).  ``interpreter`` runs an executable with ``sh``, ``bash``
        or ``python3``; ``args`` may name inputs such as ``{robot_port}``.
        ``stochastic``: its path depends on the seed it gets (``TWB_SEED``),
        so it runs once per repetition with that repetition's planner seed
        (else once per experiment, its path and time reused by every run).
        :class:`Forbidden` when the testbed has uploads disabled,
        :class:`TooLarge` over its size limit.
        """
        return self._send(self._upload_program(program_body(program, name, kind, interpreter, args, stochastic)))

    def list_programs(self, *, offset: int = 0, limit: int = 50) -> Page[Program]:
        """Your uploaded programs, newest first."""
        return self._send(self._list_programs(offset, limit))

    def get_program(self, program_id: int) -> Program:
        """One of your programs (:class:`NotFound` for anybody else's)."""
        return self._send(self._get_program(program_id))

    def sandbox_info(self) -> dict[str, Any]:
        """Whether uploads are enabled, the interpreters, limits and isolation of the testbed's sandbox."""
        return self._send(self._sandbox_info())

    def list_controllers(self) -> list[dict[str, Any]]:
        """The robots' path-tracking controllers: name, description, source, whether compiled, and parameters
        (name, type, unit, default, range; SI units)."""
        return self._send(self._list_controllers())

    def list_planners(self) -> list[dict[str, Any]]:
        """The testbed's planners: name, description, defaults, parameters (name, type, unit, default, range;
        None: any) and whether it plans multi-robot jobs only (``fleet_only``)."""
        return self._send(self._list_planners())

    def plugin_load_errors(self) -> list[LoadError]:
        """The plug-ins (planners, then controllers) the testbed's server could not load, each a
        :class:`contract.plugins.LoadError` (``name``, ``kind``, ``source``, ``error_type``, ``message``,
        ``distribution``)."""
        return self._run(self._plugin_load_errors())

    # ------------------------------------------------------------------ experiments

    def submit(self, environment: str | Mapping[str, Any], start: Optional[Pose] = None, goal: Optional[Pose] = None,
               planner: Optional[str] = None, *, path: Optional[Sequence[Pose] | np.ndarray] = None,
               planner_params: Optional[Mapping[str, Any]] = None, modes: Optional[Sequence[str]] = None,
               repetitions: Optional[int] = None, seed: Optional[int] = None,
               planner_seed: Optional[int] = None,
               field: Optional[str] = None, program: Optional[int] = None,
               jitter: Optional[Mapping[str, float]] = None,
               profile_overrides: Optional[Mapping[str, float]] = None, controller: Optional[str] = None,
               controller_params: Optional[Mapping[str, float]] = None,
               controller_program: Optional[int] = None,
               robots: Optional[Sequence[Mapping[str, Any]]] = None, label: Optional[str] = None,
               problem: Optional[str] = None) -> Experiment:
        """Queue a job; returns the new experiment (status ``queued``).

        ``environment`` is a name, or a whole job mapping (as in a JSON job
        file) that the keyword arguments then override.  Poses are
        ``[x, y]`` or ``[x, y, theta]`` (m, rad); give ``planner`` (default
        ``fmm`` on the server), an explicit ``path`` or an uploaded
        ``program``'s id (:meth:`upload_program`).  Omitted fields take
        the server's defaults (modes sim and twb, 1 repetition, seed 0,
        ``field="sub"``).  ``seed`` seeds every run's noise (its own per
        mode and repetition); ``planner_seed`` (default ``seed``) each
        repetition's planner seed, which a randomised planner (PRM) plans
        that repetition with: both modes of a repetition drive the same plan.  ``jitter`` (``{"xy_m", "theta_rad"}``, standard
        deviations) starts every run a seeded little way off the start;
        ``profile_overrides`` (``{"tracker_noise_xy_m": 0.003}``, SI units)
        gives the job's field runs other field parameters of the robot
        profile (docs/fidelity.md, "Noise studies").
        ``controller`` chooses the robots' path-tracking controller (default
        ``schema``; :meth:`list_controllers`) and ``controller_params`` its
        parameters (SI units, as their names say); ``controller_program``, an
        uploaded program's id, drives the robots along the planned path
        itself instead (docs/controllers.md, "Your own controller program").
        ``robots`` makes it a multi-robot job instead of ``start``/``goal``:
        2 to 16 ``{"start", "goal", "path"?}`` in one world on one clock;
        ``planner="prioritized"`` or ``"lacam"`` plans them together, any other planner each
        robot alone, an uploaded ``program`` sends each robot's path on its own
        robot port (docs/server.md, "Multi-robot jobs"; docs/uploads.md).
        ``label`` names the job's configuration and ``problem`` its problem
        in comparisons (:meth:`compare`; default: derived by the server, e.g.
        ``fm2(saturation=0.1)`` and ``room A``).
        :class:`ValidationError` carries the server's reason when the job
        cannot run.
        """
        job = environment if isinstance(environment, Mapping) else None
        fields = dict(environment=None if job else environment, start=start, goal=goal, planner=planner, path=path,
                      planner_params=planner_params, modes=modes, repetitions=repetitions, seed=seed,
                      planner_seed=planner_seed, field=field,
                      program=program, jitter=jitter, profile_overrides=profile_overrides, controller=controller,
                      controller_params=controller_params, controller_program=controller_program, robots=robots,
                      label=label, problem=problem)
        return self._send(self._submit(job, fields))

    def list_experiments(self, *, status: Optional[str] = None, offset: int = 0,
                         limit: int = 50) -> Page[ExperimentSummary]:
        """Your experiments, newest first; ``status`` filters (e.g. ``"running"``)."""
        return self._send(self._list_experiments(status, offset, limit))

    def get_experiment(self, experiment_id: int) -> Experiment:
        """Status, planned path and runs (with metrics) of one experiment."""
        return self._send(self._get_experiment(experiment_id))

    def cancel(self, experiment_id: int) -> Experiment:
        """Cancel queued runs and stop running ones; :class:`Conflict` if already finished."""
        return self._send(self._cancel(experiment_id))

    def cancel_many(self, experiment_ids: Sequence[int]) -> CancelResult:
        """Cancel up to 1000 experiments in one request; the result says which were and why not the others."""
        return self._send(self._cancel_many(experiment_ids))

    def get_metrics(self, experiment_id: int) -> ExperimentMetrics:
        """Metrics per run, mean/std per mode, and the direct sim-vs-twb comparison per repetition."""
        return self._send(self._get_metrics(experiment_id))

    def compare(self, experiment_ids: Sequence[int], *, metrics: Optional[Sequence[str]] = None, test: str = "t",
                family: str = "metric", confidence: float = 0.95) -> ComparisonReport:
        """Compare the configurations of these experiments (``GET /api/v1/comparisons``): per problem and, with
        three or more problems, over the problems; the same numbers as a study's comparisons.csv.

        Each experiment is its ``label`` (the configuration) on its ``problem``; configurations come in the
        order of ``experiment_ids``.  ``metrics`` (default: a study's), ``test`` (``"t"`` or ``"rank"``),
        ``family`` (Holm's: ``"metric"`` or ``"all"``) and ``confidence`` as in
        :func:`client_sdk.study.compare`.  The result's ``rows`` are :class:`ComparisonRow` s (the pooled
        ones first, ``problem`` empty), its ``outcomes`` how each configuration's runs ended.
        :class:`NotFound` when one of the experiments is not yours, :class:`ValidationError` for bad
        arguments (fewer than 2 experiments, an unknown metric, ...).
        """
        return self._send(self._compare(experiment_ids, metrics, test, family, confidence))

    def wait(self, experiment_id: int, *, timeout: Optional[float] = None, progress: Optional[bool] = None,
             interval: float = 0.25) -> Experiment:
        """Poll until the experiment finishes and return it.

        ``progress=True`` reports on stderr: a rich progress bar on a terminal,
        plain status lines elsewhere (logs, CI: every 10 s and on every change
        of status or finished runs; a queued job's estimated start; while the
        gripper builds, the blocks and an estimate of the build time).  The
        default (None) shows the bar on a terminal and nothing elsewhere;
        False nothing.  Raises :class:`WaitTimeout` (a ``TimeoutError``)
        after ``timeout`` seconds; the experiment keeps running.
        """
        return self._run(self._wait(experiment_id, timeout, progress, interval))

    # ------------------------------------------------------------------ runs

    def get_run(self, run_id: int) -> Run:
        """One run with its metrics."""
        return self._send(self._get_run(run_id))

    @overload
    def get_poses(self, run_id: int, format: Literal["array"] = "array", *, robot: Optional[int] = None) -> np.ndarray: ...
    @overload
    def get_poses(self, run_id: int, format: Literal["csv"], *, robot: Optional[int] = None) -> str: ...

    def get_poses(self, run_id: int, format: PosesFormat = "array", *, robot: Optional[int] = None) -> np.ndarray | str:
        """Logged poses of a run: an ``(N, 4)`` array of t, x, y, theta (s, m, m, rad), or CSV text.

        A multi-robot run's rows carry the robot's index as a fifth column (``(N, 5)``, robot by robot);
        ``robot=k`` keeps robot k's."""
        return self._send(self._get_poses(run_id, format, robot))

    def get_obstacles(self, run_id: int) -> ObstacleTracks:
        """Where the run's moving obstacles were: a field run's obstacle robots as the tracker saw them
        (``exact`` False), else their exact tracks over the run; per obstacle ``(T, 4)`` t, x, y, theta
        (s, m, m, rad)."""
        return self._send(self._get_obstacles(run_id))

    def get_messages(self, run_id: int, *, offset: int = 0, limit: int = 1000) -> Page[Message]:
        """Protocol lines exchanged with the robot during a run, with experiment time."""
        return self._send(self._get_messages(run_id, offset, limit))

    # ------------------------------------------------------------------ exports

    def export(self, run_id: Optional[int] = None, *, experiment_id: Optional[int] = None,
               format: ExportFormat = "mcap", out: Optional[str | os.PathLike[str]] = None) -> Path:
        """Download a run (or every run of an experiment) as an MCAP file or a ROS 2 bag; returns where it is.

        ``format="mcap"``: one file with Foxglove's well-known schemas (default
        ``run-<id>.mcap``); ``"rosbag2"``: a ROS 2 bag directory (default
        ``run-<id>``; an ``out`` ending in ``.zip`` keeps it zipped).  Times
        are experiment seconds on each run's clock, poses in the ``map``
        frame (m, rad); topics in docs/exports.md.  The download streams to
        disk.  :class:`NotFound` for an unknown run, :class:`ApiError` 501 when
        the testbed lacks the ``export`` extra (its message says how to
        install it), :class:`FileExistsError` when ``out`` exists.
        """
        target = export_target(API_PREFIX, run_id, experiment_id, format, out)
        try:
            with translate_errors(self.url), self._http.stream("GET", target.path, params=target.params,
                                                               timeout=max(self.timeout, 300.0)) as response:
                if response.status_code >= 400:
                    response.read()
                    raise_for_status(response, "" if self.token else missing_token_hint())
                with open(target.part, "wb") as f:
                    for chunk in response.iter_bytes():
                        f.write(chunk)
        except BaseException:
            target.part.unlink(missing_ok=True)
            raise
        return target.finish()


class AsyncClient(BaseClient):
    """Asynchronous twin of :class:`Client`: the same methods, as coroutines.

    >>> async with AsyncClient() as twb:                         # doctest: +SKIP
    ...     exp = await twb.submit("blocks", start=[0.15, 0.15], goal=[1.65, 1.65], planner="prm")
    ...     exp = await twb.wait(exp.id)
    """

    def __init__(self, url: Optional[str] = None, token: Optional[str] = None, *, timeout: float = 30.0,
                 transport: Optional[httpx.AsyncBaseTransport] = None, max_retries: int = 3,
                 max_retry_wait: float = 30.0) -> None:
        super().__init__(url, token, timeout=timeout, max_retries=max_retries, max_retry_wait=max_retry_wait)
        self._http = httpx.AsyncClient(base_url=self.url, headers=self._headers(), timeout=timeout,
                                       transport=transport)

    async def __aenter__(self) -> "AsyncClient":
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connection pool."""
        await self._http.aclose()

    async def _send(self, call: Call) -> Any:
        """See :meth:`Client._send` (sleeping with asyncio)."""
        retries, waited = 0, 0.0
        while True:
            with translate_errors(self.url):
                response = await self._http.request(call.method, call.path, params=call.params, json=call.json)
            delay = self._retry_delay(call, response, retries, waited)
            if delay is None:
                return self._finish(call, response)
            await asyncio.sleep(delay)
            retries, waited = retries + 1, waited + delay

    async def _run(self, flow: Flow[T]) -> T:
        """See :meth:`Client._run` (sleeping with asyncio)."""
        step, value = flow.send, None
        try:
            while True:
                try:
                    item = step(value)
                except StopIteration as stop:
                    return stop.value
                try:
                    if isinstance(item, Sleep):
                        step, value = flow.send, await asyncio.sleep(item.seconds)
                    else:
                        step, value = flow.send, await self._send(item)
                except TwbError as exc:
                    step, value = flow.throw, exc
        finally:
            flow.close()

    async def health(self) -> dict[str, Any]:
        """See :meth:`Client.health`."""
        return await self._send(self._health())

    async def list_subfields(self) -> list[Subfield]:
        """See :meth:`Client.list_subfields`."""
        return await self._send(self._list_subfields())

    async def me(self) -> User:
        """The user the token belongs to."""
        return await self._send(self._me())

    async def list_users(self) -> list[User]:
        """All users (admin token)."""
        return await self._send(self._list_users())

    async def create_user(self, name: str, *, is_admin: bool = False) -> User:
        """Create a user (admin token); the result carries its token, shown once."""
        return await self._send(self._create_user(name, is_admin))

    async def list_robots(self) -> list[Robot]:
        """See :meth:`Client.list_robots`."""
        return await self._send(self._list_robots())

    async def list_environments(self, *, offset: int = 0, limit: int = 100) -> Page[Environment]:
        """See :meth:`Client.list_environments`."""
        return await self._send(self._list_environments(offset, limit))

    async def get_environment(self, name: str) -> Environment:
        """See :meth:`Client.get_environment`."""
        return await self._send(self._get_environment(name))

    async def create_environment(self, environment: Mapping[str, Any] | Environment) -> Environment:
        """See :meth:`Client.create_environment`."""
        return await self._send(self._create_environment(environment))

    async def ensure_environment(self, environment: Mapping[str, Any] | Environment) -> tuple[Environment, bool]:
        """See :meth:`Client.ensure_environment`."""
        return await self._run(self._ensure_environment(environment))

    async def submit(self, environment: str | Mapping[str, Any], start: Optional[Pose] = None,
                     goal: Optional[Pose] = None, planner: Optional[str] = None, *,
                     path: Optional[Sequence[Pose] | np.ndarray] = None,
                     planner_params: Optional[Mapping[str, Any]] = None, modes: Optional[Sequence[str]] = None,
                     repetitions: Optional[int] = None, seed: Optional[int] = None,
                     planner_seed: Optional[int] = None,
                     field: Optional[str] = None, program: Optional[int] = None,
                     jitter: Optional[Mapping[str, float]] = None,
                     profile_overrides: Optional[Mapping[str, float]] = None, controller: Optional[str] = None,
                     controller_params: Optional[Mapping[str, float]] = None,
                     controller_program: Optional[int] = None,
                     robots: Optional[Sequence[Mapping[str, Any]]] = None, label: Optional[str] = None,
                     problem: Optional[str] = None) -> Experiment:
        """See :meth:`Client.submit`."""
        job = environment if isinstance(environment, Mapping) else None
        fields = dict(environment=None if job else environment, start=start, goal=goal, planner=planner, path=path,
                      planner_params=planner_params, modes=modes, repetitions=repetitions, seed=seed,
                      planner_seed=planner_seed, field=field,
                      program=program, jitter=jitter, profile_overrides=profile_overrides, controller=controller,
                      controller_params=controller_params, controller_program=controller_program, robots=robots,
                      label=label, problem=problem)
        return await self._send(self._submit(job, fields))

    async def upload_program(self, program: str | os.PathLike[str] | bytes, *, name: Optional[str] = None,
                             kind: Optional[str] = None, interpreter: Optional[str] = None,
                             args: Sequence[str] = (), stochastic: bool = False) -> Program:
        """See :meth:`Client.upload_program`."""
        return await self._send(self._upload_program(program_body(program, name, kind, interpreter, args,
                                                                  stochastic)))

    async def list_programs(self, *, offset: int = 0, limit: int = 50) -> Page[Program]:
        """See :meth:`Client.list_programs`."""
        return await self._send(self._list_programs(offset, limit))

    async def get_program(self, program_id: int) -> Program:
        """See :meth:`Client.get_program`."""
        return await self._send(self._get_program(program_id))

    async def sandbox_info(self) -> dict[str, Any]:
        """See :meth:`Client.sandbox_info`."""
        return await self._send(self._sandbox_info())

    async def list_controllers(self) -> list[dict[str, Any]]:
        """See :meth:`Client.list_controllers`."""
        return await self._send(self._list_controllers())

    async def list_planners(self) -> list[dict[str, Any]]:
        """See :meth:`Client.list_planners`."""
        return await self._send(self._list_planners())

    async def plugin_load_errors(self) -> list[LoadError]:
        """See :meth:`Client.plugin_load_errors`."""
        return await self._run(self._plugin_load_errors())

    async def list_experiments(self, *, status: Optional[str] = None, offset: int = 0,
                               limit: int = 50) -> Page[ExperimentSummary]:
        """See :meth:`Client.list_experiments`."""
        return await self._send(self._list_experiments(status, offset, limit))

    async def get_experiment(self, experiment_id: int) -> Experiment:
        """See :meth:`Client.get_experiment`."""
        return await self._send(self._get_experiment(experiment_id))

    async def cancel(self, experiment_id: int) -> Experiment:
        """See :meth:`Client.cancel`."""
        return await self._send(self._cancel(experiment_id))

    async def cancel_many(self, experiment_ids: Sequence[int]) -> CancelResult:
        """See :meth:`Client.cancel_many`."""
        return await self._send(self._cancel_many(experiment_ids))

    async def get_metrics(self, experiment_id: int) -> ExperimentMetrics:
        """See :meth:`Client.get_metrics`."""
        return await self._send(self._get_metrics(experiment_id))

    async def compare(self, experiment_ids: Sequence[int], *, metrics: Optional[Sequence[str]] = None,
                      test: str = "t", family: str = "metric", confidence: float = 0.95) -> ComparisonReport:
        """See :meth:`Client.compare`."""
        return await self._send(self._compare(experiment_ids, metrics, test, family, confidence))

    async def wait(self, experiment_id: int, *, timeout: Optional[float] = None, progress: Optional[bool] = None,
                   interval: float = 0.25) -> Experiment:
        """See :meth:`Client.wait`."""
        return await self._run(self._wait(experiment_id, timeout, progress, interval))

    async def get_run(self, run_id: int) -> Run:
        """See :meth:`Client.get_run`."""
        return await self._send(self._get_run(run_id))

    async def get_poses(self, run_id: int, format: PosesFormat = "array", *,
                        robot: Optional[int] = None) -> np.ndarray | str:
        """See :meth:`Client.get_poses`."""
        return await self._send(self._get_poses(run_id, format, robot))

    async def get_obstacles(self, run_id: int) -> ObstacleTracks:
        """See :meth:`Client.get_obstacles`."""
        return await self._send(self._get_obstacles(run_id))

    async def export(self, run_id: Optional[int] = None, *, experiment_id: Optional[int] = None,
                     format: ExportFormat = "mcap", out: Optional[str | os.PathLike[str]] = None) -> Path:
        """See :meth:`Client.export` (each chunk goes to disk in a worker thread: the event loop never waits on
        the disk)."""
        target = export_target(API_PREFIX, run_id, experiment_id, format, out)
        try:
            with translate_errors(self.url):
                async with self._http.stream("GET", target.path, params=target.params,
                                             timeout=max(self.timeout, 300.0)) as response:
                    if response.status_code >= 400:
                        await response.aread()
                        raise_for_status(response, "" if self.token else missing_token_hint())
                    with open(target.part, "wb") as f:
                        async for chunk in response.aiter_bytes():
                            await asyncio.to_thread(f.write, chunk)
        except BaseException:
            target.part.unlink(missing_ok=True)
            raise
        return await asyncio.to_thread(target.finish)

    async def get_messages(self, run_id: int, *, offset: int = 0, limit: int = 1000) -> Page[Message]:
        """See :meth:`Client.get_messages`."""
        return await self._send(self._get_messages(run_id, offset, limit))
