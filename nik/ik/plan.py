"""One plan per call: everything a backend needs to know about *how* to solve, resolved once from the solver and the
call (:meth:`nik.IKSolver.plan`) and handed to the backend (never the solver itself).

A :class:`Plan` is data. The torch backend interprets it with a Python loop over the stages of
:mod:`nik.ik.stages`; the compiled backend with the same stages over its kernels. Both honour every field
(``tests/test_solver.py`` changes each one and sees the answer change on both). A plan may be changed with
:func:`dataclasses.replace` and passed back to :meth:`nik.IKSolver.solve` (``plan=``).

**Which guess serves** (:func:`choose_network`, written only here):

1. a network *given* to the solver (``checkpoint=PATH``, or ``solver.net = net``) or *installed* by the user
   (``nik networks install`` / ``nik train --install``: the user folder, :mod:`nik.nets.registry`) serves on every
   backend, except that on the compiled backend an installed single-pose network serves instead of an installed
   main one (``nik train --install`` installs one with it where the main network does not pay for single poses);
2. else, with ``checkpoint="auto"``, the network shipped with nik for the arm: on the compiled backend (the CPU) its
   small single-pose network where it has one (about a twentieth of the main network's multiply-adds for about one
   more LM iteration: docs/learned.md), on torch the main one;
3. an arm with a closed form and ``analytic=True`` keeps the closed form as its guess unless a network was given
   (``checkpoint="auto"`` loads none for it); else the refiner starts from uniform configurations (``multistart``);
4. a given or installed network that does not earn its place (:mod:`nik.ik.judge`: on seeded probe poses its best
   hypothesis is a better start than the best of 16 uniform configurations less than half the time; judged once per
   network and robot) gives way to the guess of 3 in the plans that refine and have a fallback (one warning per
   network); ``refine="none"`` and ``fallback="none"`` keep it (they ask what the network delivers);
5. on the compiled backend (the CPU) the network that would serve, shipped ones included, serves a call type only
   where it pays there (:func:`nik.ik.judge.use`: a call of one pose, or of more, each timed with and without it on
   seeded probes, or read from the record its file carries); where it does not, the guess of 3 serves that call type
   (no warning: :attr:`nik.IKSolver.network_use` says what serves and why). ``IKSolver.network_use = {...}`` sets the
   choice by hand.

**Tolerances.** ``tol_pos, tol_rot`` are the asked ones (success is measured against them). Float32 targets are
refined to :data:`FLOAT32_MARGIN` times them on *both* backends (compiled: in float64, then rounded to float32; torch:
in float32), so that rounding the answer cannot carry it out of tolerance; float64 targets to the asked tolerance.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

from nik.lm.batched import LMCfg

__all__ = [
    "FLOAT32_MARGIN",
    "Plan",
    "check_use",
    "choose_network",
    "in_arm_frame",
    "network_use",
    "resolve_fallback",
    "with_goal",
]

#: Float32 targets are refined to this fraction of the asked tolerance (both backends; module docstring).
FLOAT32_MARGIN = 0.5


@dataclass(frozen=True, eq=False)
class Plan:
    """How one call is solved (module docstring). Immutable; compared and hashed by identity (a backend keeps what
    it derives from a plan per plan).

    Attributes:
        source: the guess that serves: ``network``, ``analytic`` or ``multistart``.
        net: the network that guesses (``source == "network"``), else None; ``net_in_arm_frame``: the network was
            trained for the arm without the robot's base/tool frames (:attr:`nik.Robot.arm_hash`): it is given the
            targets mapped into the arm's frame, ``base^-1 @ T @ tool^-1``, and its hypotheses are ranked by the
            robot's own FK.
        refine: ``lm`` | ``none`` | ``pso`` | ``sapso`` | ``ipso`` | ``ga``; swarm_cfg, polish: a swarm's config and
            its LM polish (torch only).
        lm_cfg: the LM settings (:class:`nik.lm.LMCfg`): iterations, damping, restart budget.
        max_iters: iteration cap of the refinement from the guess (None: ``lm_cfg.iters`` or the swarm's).
        restarts: LM restarts failing targets within reach from uniform starts (the budget of ``lm_cfg``).
        hypotheses: targets still failing get LM from the network's other hypotheses, in turn.
        near: with ``q_near`` (no closed form), a second refinement from ``q_near`` itself.
        fallback: ``analytic`` | ``multistart`` | ``none``: the second chance for targets still failing.
        tol_pos, tol_rot: the asked tolerances, metres and radians; float32_margin: float32 targets are refined
            to this fraction of them.
        seed: seeds every random choice.
        bounds: the tolerant goal (:class:`nik.ik.bounds.Bounds`, parsed once by :func:`with_goal`), or None for the
            classic tolerances; then the goal stages of :mod:`nik.ik.goals` solve the call on either backend.
        q_rest: a preferred posture (``"mid"``, ``(dof,)`` or ``(B, dof)`` radians) or None; rest_weight: the share
            of the way to it each null-space step asks (:mod:`nik.ik.goals`).
        manipulability: the weight of :func:`nik.costs.manipulability` given via ``costs=`` (0: none): the
            null-space step raises Yoshikawa's measure, the closed form's branch of the highest one is chosen
            (:mod:`nik.ik.goals`).
    """

    source: str
    net: Any = None
    net_in_arm_frame: bool = False
    refine: str = "lm"
    lm_cfg: LMCfg | None = None
    max_iters: int | None = None
    restarts: bool = True
    hypotheses: bool = True
    near: bool = True
    fallback: str = "none"
    tol_pos: float = 1e-4
    tol_rot: float = 1.745e-3
    float32_margin: float = FLOAT32_MARGIN
    seed: int = 0
    swarm_cfg: Any = None
    polish: bool = True
    bounds: Any = None
    q_rest: Any = None
    rest_weight: float = 0.1
    manipulability: float = 0.0

    def stage_tolerances(self, float32: bool) -> tuple[float, float]:
        """``(tol_pos, tol_rot)`` the stages refine to: the asked ones, times :attr:`float32_margin` for float32."""
        m = self.float32_margin if float32 else 1.0
        return self.tol_pos * m, self.tol_rot * m


def choose_network(
    main, single_pose, given: bool, backend: str, robot=None, refine="none", fallback="none", *, call="batch",
    asked=None, solver_type=None,
):  # fmt: skip
    """The network that guesses (module docstring, "Which guess serves"): ``main`` (the solver's network), or on the
    compiled backend the ``single_pose`` network where the solver holds one. Where the plan refines and has a
    fallback (``refine``, ``fallback``: the solver's settings), a given or installed network that does not earn its
    place on ``robot`` (:func:`nik.ik.judge.earns`: its best hypothesis no better a start than uniform ones) gives
    way: None
    (the closed form or uniform starts serve); on the compiled backend a network gives way for a ``call`` type
    (``"pose"`` | ``"batch"``) where it does not pay (:func:`nik.ik.judge.use`, timed with solvers of
    ``solver_type``: :class:`nik.IKSolver`; None: not timed, the wins alone), unless ``asked``
    (``{"pose": bool, "batch": bool}``) decides."""
    return _choose(main, single_pose, given, backend, robot, (refine, fallback), call, asked, solver_type)[0]


def _choose(main, single_pose, given, backend, robot, settings, call, asked, solver_type) -> tuple:
    """``(network or None, final)``: :func:`choose_network`; ``final`` False where the decision is provisional (the
    kernels still compiling: :func:`nik.ik.judge.use`), so that the plan is not kept."""
    net = main
    if main is not None and single_pose is not None and backend == "compiled":
        net = single_pose
    if net is None or robot is None or "none" in settings:
        return net, True
    if asked is not None:
        return (net if asked[call] else None), True
    from nik.ik.judge import earns, use

    arm_frame = in_arm_frame(robot, net)
    if given and not earns(net, robot, arm_frame):
        return None, True
    if backend != "compiled" or solver_type is None:
        return net, True
    u = use(net, robot, solver_type, arm_frame)
    return (net if u.serves(call) else None), u.how != "provisional"


def network_use(solver) -> dict:
    """:attr:`nik.IKSolver.network_use`: the :class:`nik.ik.judge.Use` of the network that serves ``solver``'s calls
    on the CPU, as a dict; ``how`` says where the decision comes from."""
    from nik.ik.judge import Use, use

    s = solver
    net = s._net
    if net is not None and s._net_one is not None:
        net = s._net_one
    if net is None:
        return Use(False, False, how="no network").as_dict()
    if s._use_asked is not None:
        return Use(bool(s._use_asked["pose"]), bool(s._use_asked["batch"]), how="asked").as_dict()
    if "none" in (s.refine, s.fallback):
        return Use(True, True, how=f"asked (refine={s.refine!r}, fallback={s.fallback!r})").as_dict()
    return use(net, s.robot, type(s), in_arm_frame(s.robot, net)).as_dict()  # a loser on wins: how == "wins"


def check_use(value) -> dict | None:
    """``IKSolver.network_use = value`` checked: None, or ``{"pose": bool, "batch": bool}`` (a ``ValueError`` of one
    line otherwise)."""
    if value is None:
        return None
    if (
        not isinstance(value, dict)
        or set(value) - {"pose", "batch"}
        or not all(isinstance(value.get(k), bool) for k in ("pose", "batch"))
    ):
        raise ValueError(f"network_use: expected None or {{'pose': bool, 'batch': bool}}, got {value!r}")
    return {"pose": value["pose"], "batch": value["batch"]}


_ARM_FRAME: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def in_arm_frame(robot, net) -> bool:
    """Whether ``net`` was made for the bare arm of ``robot`` (:attr:`nik.Robot.arm`: the robot without its base/tool
    frames), so that it guesses in the arm's frame (kept per network and robot)."""
    made_for = getattr(net, "robot", None)
    if net is None or made_for is None or robot.arm is robot:
        return False
    try:
        per_net = _ARM_FRAME.setdefault(net, weakref.WeakKeyDictionary())
    except TypeError:  # not weak-referenceable: decide each time
        per_net = {}
    found = per_net.get(robot)
    if found is None:
        found = per_net[robot] = made_for.definition_hash == robot.arm_hash != robot.definition_hash
    return found


def with_goal(plan: Plan, bounds=None, q_rest=None, rest_weight: float = 0.1, *, batch: int | None = None) -> Plan:
    """``plan`` with the call's tolerant goal (parsed and checked here, once: :func:`nik.ik.bounds.parse_bounds`, its
    shorthands made of the plan's tolerances) and preferred posture; ``plan`` itself when neither is given.
    Raises ``ValueError`` (one line) on bad bounds or a bad ``rest_weight``."""
    from dataclasses import replace

    from nik.ik.bounds import parse_bounds

    goal = parse_bounds(bounds, batch=batch, tol_pos=plan.tol_pos, tol_rot=plan.tol_rot)
    if goal is None and q_rest is None:
        return plan
    if not 0.0 < float(rest_weight) <= 1.0:
        raise ValueError(f"rest_weight: expected a share in (0, 1], got {rest_weight!r}")
    return replace(plan, bounds=goal, q_rest=q_rest, rest_weight=float(rest_weight))


#: Values of ``IKSolver(refine=...)``.
REFINE_METHODS = ("none", "pso", "sapso", "ipso", "ga", "lm")


def solver_plan(solver, backend: str, tol_pos: float, tol_rot: float, seed: int, max_iters, call="batch") -> Plan:
    """The plan of one :meth:`nik.IKSolver.plan` call (``call``: ``"pose"`` for a call of one pose, ``"batch"``):
    resolved once per settings and call arguments (a plan is immutable) and kept on the solver (at most 65 kept)."""
    s = solver
    asked = s._use_asked
    key = (backend, tol_pos, tol_rot, seed, max_iters, s._net, s._given, s.fallback, s.refine, id(s.swarm_cfg),
           s.polish, s.closed_form, call, None if asked is None else tuple(asked.values()))  # fmt: skip
    plan = solver._plans.get(key)
    if plan is None:  # resolved once per settings and call arguments (a plan is immutable)
        net, final = _choose(s._net, s._net_one, s._given, backend, s.robot, (s.refine, s.fallback), call, asked,
                             type(s))  # fmt: skip
        src = "network" if net is not None else "analytic" if solver.closed_form else "multistart"
        lm_cfg = solver.swarm_cfg if isinstance(solver.swarm_cfg, LMCfg) else None
        plan = Plan(
            src, net, in_arm_frame(solver.robot, net), solver.refine, lm_cfg, max_iters,
            restarts=src == "multistart" or solver.fallback == "multistart", near=not solver.closed_form,
            fallback=solver.fallback, tol_pos=float(tol_pos), tol_rot=float(tol_rot), seed=int(seed),
            swarm_cfg=solver.swarm_cfg, polish=solver.polish,
        )  # fmt: skip
        if final:
            solver._plans = {} if len(solver._plans) > 64 else solver._plans
            solver._plans[key] = plan
    return plan


def check_settings(backend: str, refine: str) -> None:
    """``IKSolver(backend=..., refine=...)`` checked: one-line ``ValueError`` for an unknown value, and for the
    compiled backend with a refinement other than LM (its only refiner)."""
    if backend not in ("auto", "compiled", "torch"):
        raise ValueError(f"IKSolver: backend must be auto, compiled or torch, got {backend!r}")
    if backend == "compiled" and refine != "lm":
        raise ValueError(f"IKSolver: the compiled backend refines by LM only (refine='lm'), got refine={refine!r}")
    if refine not in REFINE_METHODS:
        raise ValueError(f"IKSolver: refine must be one of {list(REFINE_METHODS)}, got {refine!r}")


def resolve_fallback(fallback, closed_form: bool, name: str) -> str:
    """``IKSolver(fallback=...)`` as the plan's ``analytic | multistart | none``: True is ``"auto"``, False ``"none"``;
    ``"auto"`` is analytic on an arm with a closed form (``closed_form``), else multistart. Raises ``ValueError`` on
    an unknown value and on ``"analytic"`` for an arm (``name``) without a closed form."""
    fallback = {True: "auto", False: "none"}.get(fallback, fallback)
    if fallback not in ("auto", "analytic", "multistart", "none"):
        raise ValueError(f"IKSolver: fallback must be auto, analytic, multistart or none, got {fallback!r}")
    if fallback == "analytic" and not closed_form:
        raise ValueError(f"IKSolver: fallback='analytic' needs an arm with a closed form; {name} is not")
    if fallback == "auto":
        fallback = "analytic" if closed_form else "multistart"
    return fallback
