"""The robot agent's TCP host: N robots of the simulation engine behind the wire protocol.

:class:`AgentHost` (:mod:`.agent_host`) runs the engine's loop and one TCP server per robot;
:mod:`.connection` frames one client's lines, :mod:`.robot` turns them into calls on the engine,
:mod:`.sinks` and :mod:`.server_link` carry the tracker's poses out.
"""

from .agent_host import AgentHost, EventListener, start_agents

__all__ = ["AgentHost", "EventListener", "start_agents"]
