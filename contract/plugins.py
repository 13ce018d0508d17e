"""Plug-ins of every kind (planners, controllers): one base interface, one loader, load errors as data.

A plug-in is an object an installed distribution declares in its kind's
entry-point group (``teleworkbench.planners``, ``teleworkbench.controllers``),
or one registered in-process (:meth:`PluginRegistry.register`).  As nav2's
plug-ins, each has a lifecycle: the loader creates it (a class is
instantiated), calls its :meth:`Plugin.configure` (when it has one), and the
kind checks and wraps it (``adapt``); :meth:`Plugin.cleanup` is called when the
registry drops it.  Its parameters are declared once, as
:class:`~contract.parameters.Param` s.

Whatever goes wrong while loading one plug-in — its module does not import,
its constructor or ``configure`` raises, it lacks the kind's interface, it
takes a built-in's name — is kept as a :class:`LoadError` (name, kind,
source, error type, message): the listings (``GET /api/v1/planners``, ``GET
/api/v1/controllers``), ``twb plugins list`` and the SDK show it as such, and
selecting the plug-in raises the kind's error carrying it (``load_error``).
One broken plug-in never takes the others, or the testbed, down.
"""

from __future__ import annotations

import importlib
from dataclasses import asdict, dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Callable, Collection, Generic, Mapping, Optional, Sequence, TypeVar

from .parameters import Param

__all__ = ["RESTART_HINT", "LoadError", "Plugin", "PluginRegistry", "PluginStatus"]

T = TypeVar("T")

#: what a plug-in that fails to load needs most often: a process started before it was installed
RESTART_HINT = ("if you installed it while the testbed was running, restart the testbed (stop `twb up` or "
                "`twb server` and start it again) so that its processes see the new package")


class Plugin:
    """The base interface of every plug-in kind (:class:`planners.base.Planner`,
    :class:`contract.controller_specs.Controller`): ``name``, a one-line ``description``, its declared
    ``parameters`` (None: any values, unchecked) and the lifecycle :meth:`configure` / :meth:`cleanup`."""

    name: str = ""
    description: str = ""
    parameters: Optional[Sequence[Param]] = ()

    def configure(self) -> None:
        """Called once by the loader, after construction and before first use: acquire what the plug-in
        needs (files, tables, caches).  Raise to refuse loading; the error is kept as a :class:`LoadError`."""

    def cleanup(self) -> None:
        """Called once when the registry drops the plug-in: release what :meth:`configure` acquired."""


@dataclass(frozen=True)
class LoadError:
    """Why one plug-in did not load: its ``name`` and ``kind`` (``planner``, ``controller``), ``source``
    (``module:object``), the exception's type name (``error_type``) and ``message``, and the distribution
    declaring it (``"name version"``, empty when unknown)."""

    name: str
    kind: str
    source: str
    error_type: str
    message: str
    distribution: str = ""

    def __str__(self) -> str:
        return (f"plug-in {self.kind} {self.name!r} ({self.source}) failed to load: {self.message} "
                f"[{self.error_type}] ({RESTART_HINT})")

    def to_dict(self) -> dict[str, str]:
        """JSON form (the listings' ``load_errors``)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "LoadError":
        """The inverse of :meth:`to_dict` (keys it does not know are ignored)."""
        return cls(**{k: str(data.get(k, "")) for k in ("name", "kind", "source", "error_type", "message",
                                                        "distribution")})


@dataclass(frozen=True)
class PluginStatus:
    """One declared plug-in, loaded now (or tried): ``name``, ``kind``, ``target`` (``module:object``), the
    distribution declaring it and, if it does not load, the :class:`LoadError`."""

    name: str
    kind: str
    target: str
    distribution: str
    error: Optional[LoadError] = None

    @property
    def loaded(self) -> bool:
        """Whether it loads."""
        return self.error is None


class PluginRegistry(Generic[T]):
    """The plug-ins of one ``kind``: its entry-point ``group`` and those registered in this process.

    ``adapt(name, obj, source)`` checks a created and configured object (from ``source``: ``module:object``,
    or ``registered <name>``) against the kind's interface and returns what the kind uses (raise
    ``TypeError`` otherwise); ``refuse(message)`` makes the kind's error for an
    unknown or broken plug-in.  Names in ``reserved`` (the built-ins) cannot be taken.  Plug-ins load on
    first use and stay loaded; one that fails is tried again on the next use (it may have been installed
    since).
    """

    def __init__(self, kind: str, group: str, *, adapt: Callable[[str, Any, str], T],
                 refuse: Callable[[str], Exception], reserved: Collection[str] = ()) -> None:
        self.kind, self.group = kind, group
        self._adapt, self._refuse, self._reserved = adapt, refuse, frozenset(reserved)
        self._loaded: dict[str, tuple[T, Any]] = {}  # name -> (what the kind uses, the configured object)

    def entry_points(self) -> dict[str, EntryPoint]:
        """The group's entry points by name, built-in names left out."""
        return {ep.name: ep for ep in entry_points(group=self.group) if ep.name not in self._reserved}

    def names(self) -> list[str]:
        """Every plug-in name, loaded or not (sorted)."""
        return sorted(set(self.entry_points()) | set(self._loaded))

    def loaded(self, name: str) -> Optional[T]:
        """The plug-in ``name`` if it is loaded already (registered, or used before), else None."""
        got = self._loaded.get(name)
        return got[0] if got is not None else None

    def get(self, name: str) -> Optional[T]:
        """The plug-in ``name`` (loaded now if need be), or None if none has that name; the kind's error
        (``refuse``, with the :class:`LoadError` as ``load_error``) if it fails to load."""
        if name in self._loaded:
            return self._loaded[name][0]
        ep = self.entry_points().get(name)
        if ep is None:
            return None
        loaded = self._load(name, ep.value, ep.load, _distribution(ep))
        if isinstance(loaded, LoadError):
            exc = self._refuse(str(loaded))
            exc.load_error = loaded  # type: ignore[attr-defined]
            raise exc
        return loaded

    def register(self, name: str, obj: Any) -> T:
        """Create, configure and adapt ``obj`` under ``name`` for this process (tests, notebooks); its errors
        propagate.  ``ValueError`` for a built-in's name; a plug-in registered before is cleaned up."""
        if name in self._reserved:
            raise ValueError(f"{name!r} is a built-in {self.kind} and cannot be replaced")
        self.unregister(name)
        made, configured = _create(obj)
        try:
            adapted = self._adapt(name, made, f"registered {name}")
        except BaseException:
            if configured:
                _cleanup_quietly(made)
            raise
        self._loaded[name] = (adapted, made)
        return adapted

    def unregister(self, name: str) -> None:
        """Drop the plug-in ``name`` (its ``cleanup`` is called); nothing if it is not loaded."""
        got = self._loaded.pop(name, None)
        if got is not None and callable(getattr(got[1], "cleanup", None)):
            got[1].cleanup()

    def report(self) -> list[PluginStatus]:
        """Every plug-in the group declares, loaded now (or tried), by name; one with a built-in's name is
        refused.  What ``twb plugins list`` shows."""
        out = []
        for ep in sorted(entry_points(group=self.group), key=lambda e: e.name):
            dist = _distribution(ep)
            if ep.name in self._reserved:
                error: Optional[LoadError] = LoadError(ep.name, self.kind, ep.value, "ValueError",
                                                       f"a built-in {self.kind} is called {ep.name!r}", dist)
            elif ep.name in self._loaded:
                error = None
            else:
                loaded = self._load(ep.name, ep.value, ep.load, dist)
                error = loaded if isinstance(loaded, LoadError) else None
            out.append(PluginStatus(ep.name, self.kind, ep.value, dist, error))
        return out

    def load_errors(self) -> list[LoadError]:
        """The :class:`LoadError` of every declared plug-in that does not load (all are tried now)."""
        return [s.error for s in self.report() if s.error is not None]

    def _load(self, name: str, source: str, load: Callable[[], Any], distribution: str) -> T | LoadError:
        """Import, create, configure and adapt one plug-in: what the kind uses, or the :class:`LoadError`."""
        importlib.invalidate_caches()  # a package installed after this process started is found
        made, configured = None, False
        try:
            made, configured = _create(load())
            adapted = self._adapt(name, made, source)
        except Exception as exc:  # a broken plug-in must not take the testbed down
            if configured:
                _cleanup_quietly(made)
            return LoadError(name, self.kind, source, type(exc).__name__, str(exc) or repr(exc), distribution)
        self._loaded[name] = (adapted, made)
        return adapted


def _create(obj: Any) -> tuple[Any, bool]:
    """``obj`` created (a class is instantiated) and configured; (it, whether ``configure`` ran)."""
    if isinstance(obj, type):
        obj = obj()
    configure = getattr(obj, "configure", None)
    if not callable(configure):
        return obj, False
    configure()
    return obj, True


def _cleanup_quietly(obj: Any) -> None:
    """Best-effort ``cleanup`` of a plug-in that failed after ``configure``: the first error is the one kept."""
    cleanup = getattr(obj, "cleanup", None)
    if not callable(cleanup):
        return
    try:
        cleanup()
    except Exception:  # noqa: BLE001 - the load error already says what went wrong
        pass


def _distribution(ep: EntryPoint) -> str:
    """``"name version"`` of the distribution declaring ``ep`` (empty when unknown)."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return ""
    return f"{dist.metadata['Name']} {dist.version}"
