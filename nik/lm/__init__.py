"""lm: Levenberg-Marquardt inverse kinematics, the default refiner and the swarms' polish.

- :mod:`nik.lm.loop`: the one torch LM loop (:func:`lm_loop`, settings :class:`LMCfg`: stop rule, damping
  schedule, linear solver, acceptance) that every torch solver below and in the pipeline runs;
- :mod:`nik.lm.batched`: batched torch LM (:func:`lm_solve`, :class:`LMCfg`) with restarts only for the
  targets that fail and are within reach;
- :mod:`nik.lm.compiled`: the same algorithm through the compiled kernel of :mod:`nik.kernels.lm`
  (:class:`CompiledLM`), where torch's per-op overhead would dominate: what :meth:`nik.IKSolver.solve` runs on
  the CPU;
- :mod:`nik.lm.problem`: LM over a problem of cost terms (:mod:`nik.costs`: the pose, bounds, limits, posture,
  collisions, a path's smoothness, a user's own), one pose, a batch or a whole path (``costs=`` of the solver).

A plain numpy implementation of the same algorithm, the tests' independent reference, lives in
``tests/lm_reference.py``.

The room may import kinematics, poses, robots, collision and costs; never swarm, ik, learn or cli (the swarms
import it).
"""

from nik.lm.batched import Chain, LMCfg, LMRun, lm_run, lm_solve, so3_log
from nik.lm.compiled import CompiledLM
from nik.lm.loop import Box, Eval, Restarts, lm_loop
from nik.lm.problem import PathProblem, Problem, ProblemCfg, solve_problem

__all__ = ["Box", "Chain", "CompiledLM", "Eval", "LMCfg", "LMRun", "PathProblem", "Problem", "ProblemCfg", "Restarts",
           "lm_loop", "lm_run", "lm_solve", "so3_log", "solve_problem"]  # fmt: skip
