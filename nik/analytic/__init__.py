"""Closed-form inverse kinematics.

:func:`puma560_ik` solves every PUMA-560-type arm (a shoulder offset, parallel joints 2 and 3,
a spherical wrist) in closed form: all 8 solutions, batched, with a validity mask. The built-in
``puma560`` and ``kuka_kr`` (and ``rebot_v_6r``) have that geometry; :func:`puma560_params`
recovers it from any robot's FK normal form or says why the robot does not fit.

The room may import kinematics, poses and robots; never lm, swarm, ik, learn or cli.
"""

from nik.analytic.puma560 import PumaGeometry, is_puma_like, puma560_ik, puma560_params

__all__ = ["PumaGeometry", "is_puma_like", "puma560_ik", "puma560_params"]
