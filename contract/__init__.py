"""The Teleworkbench's contract: what the server, the robot agents, the SDK and users' programs agree on.

It imports nothing else of the project (numpy only), so every other package may import it and the
SDK installs with it alone.  Its modules:

- :mod:`.protocol` — the robot wire protocol v1: the one codec (docs/protocol.md);
- :mod:`.frames` — the field, its sub-fields and where a host's robots live (m);
- :mod:`.auth` — the control keys of robot ports;
- :mod:`.robot_profile`, :mod:`.params`, :mod:`.overrides` — robot profiles as data, typed, and
  the field parameters a job may override;
- :mod:`.parameters` — the parameters a planner or controller declares (:class:`~.parameters.Param`), checked;
- :mod:`.plugins` — plug-ins of every kind: the base interface, the loader, load errors as data;
- :mod:`.controller_specs` — which path-tracking controllers a robot runs, and their parameters.

The layers above it: docs/design.md, "Layers".
"""
