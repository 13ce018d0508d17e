"""The run pipeline: one queued run to its end, and what it uses.

Read it in this order: :mod:`.runner` (the steps and how a run can end),
:mod:`.steps` (each step on the robot), :mod:`.paths` (an experiment's path,
had once), :mod:`.recorder` (what a run stores and publishes),
:mod:`.compute` (planning and metrics as pure functions) and :mod:`.pool`
(the worker processes running them).  The dispatcher (:mod:`server.dispatch`)
starts runs and handles their ends.
"""
