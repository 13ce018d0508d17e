"""The field as the server knows it: registered robots, the four sub-fields, what is built where.

:class:`FieldState` is owned by the event loop: every method that changes it
runs there (API handlers that touch it are ``async``).  Worker threads read
only :meth:`FieldState.known` and :meth:`FieldState.origin_of`, which use
snapshots replaced as a whole on every change.  The scheduler
(:mod:`server.scheduler`) decides on the same ``robots`` and ``subfields``
dictionaries.  Changes are mirrored to the store and published as live
events (``robot``, ``subfield``).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any, Callable, Optional

from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm import Session, sessionmaker

from contract.auth import control_key as derive_key
from contract.frames import FIELD_SIZE, SUBFIELD_SIZE

from .broker import EventBroker
from .core.security import Principal
from .errors import Forbidden
from .models import utcnow
from .scheduler import SUBFIELD_ORIGINS, RobotSlot, SubfieldSlot
from .schemas import RobotPublic, RobotRegister, SubfieldPublic
from .status import RobotStatus, SubfieldState
from .store import field as store

__all__ = ["FieldState", "agent_answers"]

log = logging.getLogger("twb.server")


class FieldState:
    """Robots (``robot_id`` → :class:`RobotSlot`), sub-fields 1–4 and the environment built by each robot."""

    def __init__(self, sessions: sessionmaker[Session], broker: EventBroker) -> None:
        self._sessions = sessions
        self._broker = broker
        self.robots: dict[str, RobotSlot] = {}
        self.subfields: dict[int, SubfieldSlot] = {k: SubfieldSlot(k) for k in range(1, 5)}
        #: environment key built by each robot's gripper (None or absent: nothing)
        self.built: dict[str, Optional[str]] = {}
        #: robots that may have moving obstacles set (T,T,M): the next build sets or clears them
        self.moving: set[str] = set()
        #: each robot's control key, sent as T,T,A (None: the robot's port is open)
        self.keys: dict[str, Optional[str]] = {}
        #: why each offline robot is offline
        self.offline_reason: dict[str, str] = {}
        # snapshots replaced as a whole, for worker threads: frames, and the token that registered each robot
        self._origins: dict[str, tuple[float, float]] = {}
        self._tokens: dict[str, Optional[int]] = {}
        #: the owner of the run on each sub-field (for who may see which run is there)
        self.subfield_owner: dict[int, Optional[int]] = {}
        #: the owner of each sub-field's last run since the start (who may see which run drove there last)
        self.last_owner: dict[int, Optional[int]] = {}
        #: called with a field robot that joined or answers again: where it stands is to be looked up
        #: (``(robot_id, host, port, control key)``; :class:`server.locate.Locator`)
        self.on_join: Optional[Callable[[str, str, int, Optional[str]], None]] = None

    # ------------------------------------------------------------------ any thread

    def known(self, robot_id: str) -> bool:
        """Whether ``robot_id`` is registered (safe from any thread)."""
        return robot_id in self._origins

    def origin_of(self, robot_id: str) -> tuple[float, float]:
        """Origin (m) of the robot's frame in the field (safe from any thread)."""
        return self._origins.get(robot_id, (0.0, 0.0))

    def may_track(self, robot_id: str, who: Principal) -> bool:
        """Whether ``who`` may post tracker poses of ``robot_id``: the token that registered it, or an admin
        (safe from any thread)."""
        return who.is_admin or (robot_id in self._tokens and self._tokens[robot_id] == who.token_id)

    # ------------------------------------------------------------------ loop

    async def load(self) -> None:
        """Robots known from earlier starts, offline until they register again or answer a probe."""

        def rows() -> list[Any]:
            with self._sessions() as s:
                return store.load_robots(s)

        for r, token_hash in await asyncio.to_thread(rows):
            slot = RobotSlot(r.robot_id, r.host, r.port, r.backend, r.profile, r.platform, tuple(r.origin),
                             tuple(r.area), healthy=False)
            self._install(slot, r.token_id, derive_key(token_hash, r.robot_id) if token_hash else None)
            self.offline_reason[r.robot_id] = "known from an earlier start; waiting for it to answer"

    def _install(self, slot: RobotSlot, token_id: Optional[int], key: Optional[str]) -> None:
        old = self.robots.get(slot.robot_id)
        if old is not None:
            slot.run_id = old.run_id
        self.robots[slot.robot_id] = slot
        self.keys[slot.robot_id] = key
        self._origins = {**self._origins, slot.robot_id: slot.origin}
        self._tokens = {**self._tokens, slot.robot_id: token_id}

    async def register(self, body: RobotRegister, *, by: Optional[Principal] = None,
                       control_key: Optional[str] = None) -> RobotSlot:
        """Add or refresh a robot (a (re)started agent: nothing is built on it).

        ``by``: the token registering it over the API (None: a robot of this
        process, with ``control_key``).  A robot registered before may be
        registered again only by the same token or an admin
        (:class:`~server.errors.Forbidden`); its control key derives from the
        registering token (:mod:`contract.auth`).
        """
        rid = body.robot_id
        if by is not None and not by.is_admin and rid in self._tokens and self._tokens[rid] != by.token_id:
            raise Forbidden(f"robot {rid!r} was registered with another token; only that token or an admin "
                            "may register it again")
        key = control_key if by is None else (derive_key(by.token_hash, rid) if by.token_hash else None)
        token_id = by.token_id if by is not None else None

        def save() -> None:
            with self._sessions.begin() as s:
                store.save_robot(s, body, token_id=token_id)

        await asyncio.to_thread(save)
        slot = RobotSlot(rid, body.host, body.port, body.backend, body.profile, body.platform,
                         (float(body.origin[0]), float(body.origin[1])), (float(body.area[0]), float(body.area[1])))
        self._install(slot, token_id, key)
        self.built.pop(rid, None)
        self.offline_reason.pop(rid, None)
        self._broker.publish({"type": "robot", "robot_id": rid})
        self._joined(slot)
        return slot

    def _joined(self, slot: RobotSlot) -> None:
        if self.on_join is not None and slot.pool == "field" and not slot.engine:
            self.on_join(slot.robot_id, slot.host, slot.port, self.keys.get(slot.robot_id))

    def add_engine_slots(self, engine: str, n: int) -> list[RobotSlot]:
        """``n`` simulation slots of a compute engine (``{engine}-1`` ...): whole-field ideal robots that are
        Ray tasks, not agents; kept in memory only (they come and go with the engine)."""
        slots = [RobotSlot(f"{engine}-{i}", engine, 0, "ideal", origin=(0.0, 0.0), area=FIELD_SIZE, engine=engine)
                 for i in range(1, n + 1)]
        for slot in slots:
            self._install(slot, None, None)
            self._broker.publish({"type": "robot", "robot_id": slot.robot_id})
        return slots

    def set_offline(self, robot_id: str, reason: str) -> None:
        """A run failed for this robot's fault (``reason``): no runs for it until it answers again."""
        self.robots[robot_id].healthy = False
        self.offline_reason[robot_id] = reason
        self._broker.publish({"type": "robot", "robot_id": robot_id})

    def set_online(self, robot_id: str) -> None:
        """An offline robot answers again (its world is as it left it, unknown to us: rebuild)."""
        self.robots[robot_id].healthy = True
        self.built.pop(robot_id, None)
        self.moving.add(robot_id)  # its world is unknown
        self.offline_reason.pop(robot_id, None)
        self._broker.publish({"type": "robot", "robot_id": robot_id})
        self._joined(self.robots[robot_id])

    async def probe_offline(self) -> list[str]:
        """Try the idle offline robots; the ones that answer are back online (returned)."""
        back = []
        for r in [r for r in self.robots.values() if not r.healthy and r.run_id is None and not r.engine]:
            if await agent_answers(r.host, r.port):
                log.info("robot %s answers again", r.robot_id)
                self.set_online(r.robot_id)
                back.append(r.robot_id)
        return back

    def field_robot(self, subfield: int) -> Optional[RobotSlot]:
        """The robot standing on sub-field ``subfield`` (1–4), if one is registered."""
        for r in self.robots.values():
            if r.subfield == subfield:
                return r
        return None

    def claim(self, subfields: tuple[int, ...], owner_id: int) -> None:
        """The run starting on ``subfields`` is ``owner_id``'s (who may see which run is where)."""
        for k in subfields:
            self.subfield_owner[k] = owner_id

    async def set_subfield(self, k: int, *, owner_id: Optional[int] = None, **fields: Any) -> None:
        """Change sub-field ``k`` (``state``, ``environment``, ``run_id`` of the user ``owner_id``):
        publish it and mirror it to the store."""
        slot = self.subfields[k]
        for key, v in fields.items():
            setattr(slot, key, v)
        if "run_id" in fields:
            self.subfield_owner[k] = owner_id if slot.run_id is not None else None
            if slot.run_id is not None:
                slot.last_run_id, self.last_owner[k] = slot.run_id, owner_id
        robot = self.field_robot(k)
        state, environment, run_id = str(slot.state), slot.environment, slot.run_id
        robot_id = robot.robot_id if robot else None
        self._broker.publish({"type": "subfield", "owner_id": self.subfield_owner.get(k),
                              "last_owner_id": self.last_owner.get(k),
                              "subfield": self.subfield_view(k).model_dump(mode="json")})

        def save() -> None:
            with self._sessions.begin() as s:
                store.save_subfield(s, k, state=state, environment=environment, run_id=run_id, robot_id=robot_id)

        try:
            await asyncio.to_thread(save)
        except DBAPIError as exc:  # a mirror only: the state itself lives here, and the next change writes it
            log.warning("sub-field %d: its state was not mirrored to the store: %s", k, exc.orig)

    # ------------------------------------------------------------------ views

    def subfield_view(self, k: int) -> SubfieldPublic:
        slot = self.subfields[k]
        robot = self.field_robot(k)
        state = slot.state if slot.run_id is not None or slot.state == SubfieldState.BUILDING else SubfieldState.IDLE
        if robot is None:
            state = SubfieldState.OFFLINE
        return SubfieldPublic(id=k, state=state, environment=slot.environment,
                              robot_id=robot.robot_id if robot else None, run_id=slot.run_id,
                              last_run_id=slot.last_run_id,
                              origin=list(SUBFIELD_ORIGINS[k]), size=list(SUBFIELD_SIZE))

    def subfield_views(self) -> list[SubfieldPublic]:
        return [self.subfield_view(k) for k in sorted(self.subfields)]

    def robot_view(self, slot: RobotSlot, last_pose: Optional[list[float]] = None) -> RobotPublic:
        """The robot as the API shows it; ``last_pose`` its last tracked pose ``[t, x, y, theta]`` (field frame)."""
        status = RobotStatus.OFFLINE if not slot.healthy else (
            RobotStatus.BUSY if slot.run_id is not None else RobotStatus.IDLE)
        return RobotPublic(robot_id=slot.robot_id, host=slot.host, port=slot.port, platform=slot.platform,
                           backend=slot.backend, profile=slot.profile, origin=list(slot.origin),
                           area=list(slot.area), subfield=slot.subfield, pool=slot.pool, status=status,
                           status_reason=self.offline_reason.get(slot.robot_id) if not slot.healthy else None,
                           last_seen=utcnow(), last_pose=last_pose)

    def robot_views(self, last_pose: Callable[[str], Optional[list[float]]]) -> list[RobotPublic]:
        """Every robot, field robots first; ``last_pose(robot_id)`` gives each one's last tracked pose."""
        return [self.robot_view(r, last_pose(r.robot_id))
                for r in sorted(self.robots.values(), key=lambda r: (r.pool, r.robot_id))]


async def agent_answers(host: str, port: int, timeout_s: float = 2.0) -> bool:
    """Whether a robot agent greets on host:port."""
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
    except (OSError, asyncio.TimeoutError, UnicodeError, ValueError):
        return False
    try:
        line = await asyncio.wait_for(reader.readline(), timeout_s)
        return line.startswith(b"HELLO,")
    except (OSError, asyncio.TimeoutError):
        return False
    finally:
        writer.close()
