"""The run pipeline: one queued run to its end, and what it uses.

Read it in this order: :mod:`.runner` (the steps and how a run can end),
:mod:`.steps` (each step on the robot), :mod:`.paths` (an experiment's path,
had once), :mod:`.recorder` (what a run stores and publishes),
:mod:`robot_agent.engine.jobs` (planning, simulation and metrics as pure
functions, named for the pools by :mod:`robot_agent.engine.tasks`) and
:mod:`.pool` (the worker processes running them; :mod:`.ray_pool` on Ray).
What a run is handed is in :mod:`.context`.  The dispatcher (:mod:`server.dispatch`)
starts runs and handles their ends.
"""
