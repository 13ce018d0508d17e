"""Lockstep: the robot's clock waits for a closed-loop controller's answer to every pose it is sent.

A connection that drives a robot in velocity mode (``T,T,V``) and is subscribed to its ``PO`` lines
with the ``lockstep`` clock (``T,T,O,1,lockstep``, or ``T,T,O,1`` on a host whose default is
lockstep) is that robot's *lockstep controller*.  The model (docs/protocol.md, "Lockstep"), after
CARLA's synchronous mode, where the simulator advances only when its client has acted on a frame:

- **One pose at a time.**  A ``PO`` line sent at experiment time ``d`` (when it is sent: the
  tracker's measurement time plus its latency, or the end of the control step that logged it) is
  *awaited*: the host's clock does not run the control step ``ceil(d / dt)`` (the one that starts at
  ``d``, or the first after it) until the controller's answer, its next ``T,T,V`` (or a ``T,T,S``), has
  come: every line of the controller then acts in the same control step, whenever it arrives.  Poses that become due while the controller computes are not sent to it;
  it gets the newest when it is free again, as a subscriber with a queue of one (ROS's
  ``queue_size=1``).  Other connections subscribed to the robot get every line, as before.
- **Compute time is latency.**  The answer states the controller's compute time ``c`` (``T,T,V,v,w,c``,
  ms; 0 when not stated).  It is ready at ``d + c`` (``d``: the pose's delivery, or when the controller
  became free if that was later) and applies from the first control step that starts at or after
  then: a compute time rounded up to control periods (none stated: the step that starts at ``d``,
  one control period after the pose was measured in simulation).  Until then
  the robot drives on with the previous command, and the controller is busy (no new pose).
- **A controller that does not answer** within ``wait_s`` wall seconds is *lapsed*: the clock runs
  on without it (its watchdog then stops the robot after 0.5 s of experiment time, as a real robot's
  would), and it is sent poses freely until it answers again, from when it is in lockstep anew.

So a run's poses depend on its seed, its controller's answers and their stated compute times, not on
when the answers arrive in wall time: the same at every time scale and on any host.  This module only
keeps the books (plain Python, no I/O); :class:`robot_agent.host.agent_host.AgentHost` drives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Lockstep", "Pending"]

_EPS = 1e-9


@dataclass
class Pending:
    """An answer waiting for its control step: drive robot with ``v``, ``w`` (m/s, rad/s) from ``step``."""

    step: int
    v: float
    w: float


@dataclass
class Lockstep:
    """The lockstep books of ``n`` robots whose control steps last ``dt`` seconds."""

    n: int
    dt: float
    wait_s: float = 3.0
    #: the control step the clock may not run before the awaited answer comes (-1: no pose awaits one)
    hold: list[int] = field(default_factory=list)
    #: the awaited pose's delivery time (s of experiment time) and the wall time (monotonic s) it was sent
    delivered: list[float] = field(default_factory=list)
    sent: list[float] = field(default_factory=list)
    #: the step from which the controller takes a new pose again (its last answer applies then)
    free_at: list[int] = field(default_factory=list)
    #: answers waiting for their step, per robot
    pending: dict[int, Pending] = field(default_factory=dict)
    #: the newest pose line that came due while the controller computed: (its due time, the line)
    withheld: dict[int, tuple[float, str]] = field(default_factory=dict)
    #: robots whose controller did not answer within ``wait_s``: free-running until it answers again
    lapsed: set[int] = field(default_factory=set)
    #: per robot: answers, and those whose stated compute time delayed them beyond the first possible step
    answers: list[int] = field(default_factory=list)
    delayed: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        n = self.n
        self.hold, self.delivered, self.sent = [-1] * n, [0.0] * n, [0.0] * n
        self.free_at, self.answers, self.delayed = [0] * n, [0] * n, [0] * n

    def busy(self, i: int, step: int) -> bool:
        """Whether robot ``i``'s controller still computes at control step ``step`` (it gets no new pose)."""
        return self.hold[i] >= 0 or self.free_at[i] > step

    def deliver(self, i: int, t: float, wall: float) -> None:
        """A pose was sent to robot ``i``'s controller at experiment time ``t``: its answer is awaited."""
        self.hold[i] = math.ceil(t / self.dt - _EPS)
        self.delivered[i], self.sent[i] = t, wall

    def answer(self, i: int, compute_s: float) -> int:
        """The controller of robot ``i`` answered the awaited pose, stating ``compute_s``: the control step its
        command applies from (the controller is busy until then)."""
        first = self.hold[i]
        step = max(first, math.ceil((self.delivered[i] + compute_s) / self.dt - _EPS))
        self.hold[i] = -1
        self.free_at[i] = step
        self.answers[i] += 1
        self.delayed[i] += step > first
        return step

    def limit(self) -> int | None:
        """The first control step the clock may not run yet (an awaited answer's), or None."""
        held = [h for h in self.hold if h >= 0]
        return min(held) if held else None

    def oldest_awaited(self) -> int | None:
        """The robot whose awaited answer was sent first, or None."""
        held = [i for i, h in enumerate(self.hold) if h >= 0]
        return min(held, key=lambda i: self.sent[i]) if held else None

    def lapse(self, i: int) -> None:
        """Robot ``i``'s controller did not answer in time: the clock goes on without it."""
        self.hold[i] = -1
        self.pending.pop(i, None)
        self.withheld.pop(i, None)
        self.lapsed.add(i)

    def active(self, i: int) -> bool:
        """Whether robot ``i`` has any lockstep state."""
        return self.hold[i] >= 0 or i in self.pending or i in self.withheld or i in self.lapsed

    def clear(self, i: int) -> None:
        """Robot ``i`` has no lockstep controller (any more): forget its state."""
        self.hold[i] = -1
        self.free_at[i] = 0
        self.pending.pop(i, None)
        self.withheld.pop(i, None)
        self.lapsed.discard(i)
