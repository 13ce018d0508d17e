"""The simulation engine: emulated robots in a world, stepped in compiled code, with no socket and no clock.

Its function-call API (what the server's worker pool, Ray, the benchmarks and the tests call):

- :func:`.headless.simulate_run` — one robot's run; :func:`.fleet.simulate_fleet` — several in one world;
- :mod:`.jobs` — a run's CPU work as plain-data jobs: plan, simulate, measure (the pool's tasks);
- :mod:`.tasks` — picklable references to those jobs, resolved where they run, so that the server
  names them without loading numba.

Underneath: :mod:`.sim` (the core the TCP host steps), :mod:`.stepper` (the compiled loop),
:mod:`.backends` (ideal and emulated-field physics), :mod:`.world`, :mod:`.movers`, the compiled
scalar functions (:mod:`.follower`, :mod:`.controllers`, :mod:`.physics`, :mod:`.contact`,
:mod:`.kinematics`, :mod:`.noise`) and :mod:`.calibration`.  Importing this package loads nothing.
"""
