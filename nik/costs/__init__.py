"""costs: every constraint and preference of an IK problem as a term, one module per term.

A term (:class:`nik.costs.term.Term`) is a residual of the joints ``q: (B, dof) -> (B, m)`` written once in torch
(differentiable: the reference and the GPU path), its Jacobian (autograd, or exact where a compiled kernel gives
it), a ``weight``, a ``name`` and an honest ``check(q) -> (B,) bool`` of the answer. The terms:

======================  ================================================  ============================================
term                    residual                                          compiled kernel beside it
======================  ================================================  ============================================
:func:`pose`            TRAC-IK's tool-frame error                        :func:`nik.kernels.lm.bounded_residuals`
:func:`bounded_pose`    its dead zone per tool axis (``bounds=``)         :func:`nik.kernels.lm.bounded_residuals`
:func:`limits`          excess beyond the joint ranges (a box for an LM)  the compiled LM's box
:func:`posture`         ``q - q_rest`` (a preference)                     the null-space step of ``q_rest=``
:func:`manipulability`  ``1 / (w + 1e-6)``, Yoshikawa's w (a preference)  :mod:`nik.kernels.manipulability`
:func:`collision`       ``max(0, margin - d)``, self and world            ``nik.kernels.collision.collision_residual``
:func:`mesh_collision`  the same on the meshes (coal; a hard constraint)  coal, :mod:`nik.collision.mesh_distance`
:func:`smoothness`      path velocity, acceleration (a preference)        --
:func:`step_cap`        a path's steps beyond ``max_step``                --
:func:`custom`          the user's ``fn(q)``                              --
======================  ================================================  ============================================

A problem is a list of terms; :func:`nik.lm.problem.solve_problem` solves it (damped least squares over the
stacked weighted residuals, the limits as a box), and :meth:`nik.IKSolver.solve` / ``solve_all`` /
``solve_path`` take ``costs=[...]`` to add a user's terms to the call's own (:mod:`nik.ik.costs`).
A new term is one module here and one line in :data:`TERMS`.

The room sits between collision and lm: it imports kernels (lazily), kinematics / poses, robots and collision.
"""

from nik.costs.collision import collision
from nik.costs.custom import custom
from nik.costs.limits import limits
from nik.costs.manipulability import manipulability
from nik.costs.mesh import mesh_collision
from nik.costs.pose import bounded_pose, pose
from nik.costs.posture import posture
from nik.costs.smoothness import smoothness, step_cap
from nik.costs.term import Term

#: The built-in terms by name (a new term: its module, and one line here).
TERMS = {
    "pose": pose,
    "bounded_pose": bounded_pose,
    "limits": limits,
    "posture": posture,
    "manipulability": manipulability,
    "collision": collision,
    "mesh_collision": mesh_collision,
    "smoothness": smoothness,
    "step_cap": step_cap,
    "custom": custom,
}

__all__ = ["TERMS", "Term", "bounded_pose", "collision", "custom", "limits", "manipulability", "mesh_collision", "pose",
           "posture", "smoothness", "step_cap"]  # fmt: skip
