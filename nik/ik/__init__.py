"""ik: the inverse-kinematics pipeline of poses, guess -> refine -> more hypotheses -> fallback -> final check.

:class:`nik.IKSolver` (:mod:`nik.solver`, a room above this one and :mod:`nik.paths`) holds one robot's
configuration and composes these stages for poses and the paths' stages for sequences.

- :mod:`nik.ik.stages`: the stages, one small function each, ``stage(solver, job, answers) -> answers``, written
  once for both backends;
- :mod:`nik.ik.backends`: where a stage's work is computed: compiled numba kernels on numpy (CPU) or torch (GPU,
  the swarms);
- :mod:`nik.ik.guesses`: guess providers ``(robot, T, ...) -> q`` (network, closed form, multistart) and
  de-duplication;
- :mod:`nik.ik.refiners`: refiners ``(robot, T, q0) -> RefineResult`` (LM, the swarms);
- :mod:`nik.ik.samples`: several solutions per pose, every network head polished on its own (IKFlow's use);
- :mod:`nik.ik.targets`: target poses in any accepted form -> ``(B, 4, 4)``, the input checks of both backends;
  :mod:`nik.ik.result`: :class:`IKResult`;

The room composes the rooms below it (robots, nets, analytic, collision, lm, swarm); paths, the solver, learn,
evaluation and cli import it.
"""

from nik.ik.guesses import dedupe
from nik.ik.plan import REFINE_METHODS
from nik.ik.refiners import RefineResult, lm_refine, swarm_refine
from nik.ik.result import IKResult, PathReport
from nik.ik.targets import QUAT_NORM_TOL, as_poses, check_tolerances
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT

__all__ = [
    "DEFAULT_TOL_POS",
    "DEFAULT_TOL_ROT",
    "QUAT_NORM_TOL",
    "REFINE_METHODS",
    "IKResult",
    "PathReport",
    "RefineResult",
    "as_poses",
    "check_tolerances",
    "dedupe",
    "lm_refine",
    "swarm_refine",
]
