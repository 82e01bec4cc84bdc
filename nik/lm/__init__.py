"""lm: Levenberg-Marquardt inverse kinematics, the default refiner and the swarms' polish.

- :mod:`nik.lm.batched`: batched torch LM (:func:`lm_solve`, :class:`LMCfg`) with restarts only for the
  targets that fail and are within reach;
- :mod:`nik.lm.compiled`: the same algorithm through the compiled kernel of :mod:`nik.kernels.lm`
  (:class:`CompiledLM`), where torch's per-op overhead would dominate: what :meth:`nik.IKSolver.solve` runs on
  the CPU.

A plain numpy implementation of the same algorithm, the tests' independent reference, lives in
``tests/lm_reference.py``.

The room may import kinematics, poses and robots; never swarm, ik, learn or cli (the swarms import it).
"""

from nik.lm.batched import LMCfg, LMRun, lm_run, lm_solve, so3_log
from nik.lm.compiled import CompiledLM

__all__ = ["CompiledLM", "LMCfg", "LMRun", "lm_run", "lm_solve", "so3_log"]
