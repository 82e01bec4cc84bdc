"""Closed-form inverse kinematics.

- :func:`family` names the closed form that fits a 6R arm, read from its joint axes whatever the
  definition: ``"spherical_wrist"`` (axes 4, 5, 6 meet, axes 2 and 3 parallel: PUMA, KUKA KR, ABB,
  Fanuc), ``"three_parallel"`` (axes 2, 3, 4 parallel, 5 and 6 meet: the Universal Robots family) or None.
- :func:`solve` returns all 8 solutions of either family, batched, with a validity mask
  (Paden-Kahan subproblems in the frames of the normal form; :mod:`nik.analytic.kernels`).
- :func:`puma560_ik` is paper B's closed form of PUMA-560-type arms (quaternion or matrix wrist);
  :func:`puma560_params` recovers that geometry from any robot's FK normal form or says why the
  robot does not fit, :func:`is_puma_like` says whether it does.

The room may import kinematics, poses, robots and data (the branch labels that order :func:`solve`'s
solutions); never lm, swarm, ik, learn or cli.
"""

from nik.analytic.geometry import FAMILIES, family
from nik.analytic.puma560 import PumaGeometry, is_puma_like, puma560_ik, puma560_params
from nik.analytic.solve import solve

__all__ = ["FAMILIES", "PumaGeometry", "family", "is_puma_like", "puma560_ik", "puma560_params", "solve"]
