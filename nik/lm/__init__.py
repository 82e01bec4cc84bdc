"""lm: Levenberg-Marquardt inverse kinematics, the default refiner and the swarms' polish.

- :mod:`nik.lm.batched`: batched torch LM (:func:`lm_solve`, :class:`LMCfg`) with restarts only for the
  targets that fail and are within reach;
- :mod:`nik.lm.compiled`: the same algorithm for a few poses through the compiled kernel of
  :mod:`nik.kernels.lm` (:class:`CompiledLM`), where torch's per-op overhead would dominate: what
  :meth:`nik.IKSolver.solve` runs for few poses on the CPU;
- :mod:`nik.lm.single`: the same algorithm for one pose in float64 numpy (:class:`SingleLM`,
  :func:`lm_solve_one`), kept as a second implementation the tests compare with.

The room may import kinematics, poses and robots; never swarm, ik, learn or cli (the swarms import it).
"""

from nik.lm.batched import LMCfg, LMRun, lm_run, lm_solve, so3_log
from nik.lm.compiled import CompiledLM
from nik.lm.single import SingleLM, best_of, lm_solve_one

__all__ = ["CompiledLM", "LMCfg", "LMRun", "SingleLM", "best_of", "lm_run", "lm_solve", "lm_solve_one", "so3_log"]
