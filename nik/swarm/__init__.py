"""swarm: batched PSO, SA-PSO, improved PSO and GA, their objectives and driver.

``refine(robot, T_target, method=...)`` is the entry point (finished by the Levenberg-Marquardt polish
of :mod:`nik.lm` when ``polish=True``); the algorithms are also usable directly as a state plus a pure
step function (``pso_init`` / ``pso_step`` and friends) on a :class:`SwarmProblem`.

The room may import kinematics, poses, robots and lm; never ik, learn or cli.
"""

from nik.swarm.bounds import BOUNDARY_STRATEGIES, apply_bounds
from nik.swarm.driver import ALGORITHMS, METHODS, SwarmResult, SwarmRun, default_cfg, refine, run_swarm
from nik.swarm.ga import GACfg, GAState, ga_init, ga_step
from nik.swarm.init import InitCfg, init_particles
from nik.swarm.ipso import IPSOCfg, IPSOState, ipso_init, ipso_step
from nik.swarm.objectives import (
    OBJECTIVES,
    make_objective,
    paper_a_objective,
    paper_d_orientation,
    paper_d_position,
    pose_objective,
)
from nik.swarm.problem import SwarmProblem, make_problem
from nik.swarm.pso import PSOCfg, PSOState, SwarmCfg, pso_init, pso_step
from nik.swarm.sapso import SAPSOCfg, sapso_init, sapso_step

__all__ = [
    "ALGORITHMS",
    "BOUNDARY_STRATEGIES",
    "METHODS",
    "OBJECTIVES",
    "GACfg",
    "GAState",
    "IPSOCfg",
    "IPSOState",
    "InitCfg",
    "PSOCfg",
    "PSOState",
    "SAPSOCfg",
    "SwarmCfg",
    "SwarmProblem",
    "SwarmResult",
    "SwarmRun",
    "apply_bounds",
    "default_cfg",
    "ga_init",
    "ga_step",
    "init_particles",
    "ipso_init",
    "ipso_step",
    "make_objective",
    "make_problem",
    "paper_a_objective",
    "paper_d_orientation",
    "paper_d_position",
    "pose_objective",
    "pso_init",
    "pso_step",
    "refine",
    "run_swarm",
    "sapso_init",
    "sapso_step",
]
