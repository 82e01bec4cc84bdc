"""paths: sequences of poses: one continuous joint trajectory through a Cartesian path, and its timing.

- :mod:`nik.paths.solve`: :func:`~nik.paths.solve.solve_path` (what :meth:`nik.IKSolver.solve_path` runs):
  candidates per waypoint from the pose pipeline's stages (:mod:`nik.ik`), the choice over the whole path, loops;
- :mod:`nik.paths.kernels`: its compiled loops (the dynamic programme over candidates, LM chains along a path);
- :mod:`nik.paths.trajopt`: the whole-trajectory optimisation (a banded LM over the waypoints);
- :mod:`nik.paths.timing`: time-optimal timing within joint speed and acceleration limits (toppra).

The room sits above :mod:`nik.ik` (it reads the pose pipeline's model, plan, checks and result) and below
:mod:`nik.solver`, which composes both. Nothing is imported here: ``import nik.paths`` stays light.
"""
