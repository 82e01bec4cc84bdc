"""The one Levenberg-Marquardt loop of nik's compiled solvers: the problem and the configuration are its arguments.

Every compiled least-squares iteration of nik is this loop (:func:`_lm_loop`); what differs between them is passed
in, not written again. A problem is a named tuple whose class names its kind (:func:`problem_kind` registers the
kind's two functions; numba picks them by the problem's type when it compiles a caller, so each kind's loop is
compiled with its own functions inlined and cached with the caller):

- ``measure(prob, s, bar) -> (cost, done)``: the rows of the problem at the state ``s.q`` (FK, residual, Jacobian,
  any extra rows or preference, written into the state ``s``), the cost the accept rule compares and whether ``s.q``
  is an answer (the loop stops there); ``bar`` is the cost to beat (``inf`` for a start): a measure may skip rows
  that cannot matter once the others already reach it (and return ``inf``);
- ``propose(prob, s, lam, c) -> (good, big)``: the candidate ``c.q`` from ``s`` with damping ``lam``: the linear
  solver is the problem's (dense Cholesky of one pose, :func:`nik.kernels.lm_step._dense_step`; the band solver of
  a path, :mod:`nik.kernels.trajopt`), then the projection into the limits; ``big`` the step's largest entry;
- ``cfg`` (:class:`LoopCfg`): the stop rule, the damping schedule and the accept rule.

The states ``cur`` and ``cand`` are two named tuples of the same type (the current point and the candidate); a kept
candidate swaps them (no copy). The loop returns the state that holds the answer.

Who configures it how:

- one pose (:func:`nik.kernels.lm._lm_one_bounded`): Marquardt damping (``lam`` times ``down`` / ``up``), stop on
  ``stall_limit`` steps that lower the cost by less than ``stall_rel`` of it, or on an answer; a bounded goal
  also keeps an answer that does not lower the cost (``ACCEPT_DONE``);
- the walk out of ``q_near`` (:func:`nik.kernels.driver.near_prior`): the pose rows with a prior row, ``lam = 0``
  (Gauss-Newton), every good step kept (``ACCEPT_ANY``), stop on a failed step (``lam_stop < 0``), over a fixed
  schedule of prior weights (one call a weight);
- the null-space posture (:func:`nik.kernels.driver.rest_posture`): the prior row ``q + s z`` with ``lam = 1 / s``
  (halved on a kept step, doubled on a rejected one, stop above ``lam_stop``), the cost the preference, stop on a
  tiny step (``tiny``) or a small gain (``conv_rel``);
- a whole path (:func:`nik.kernels.trajopt.trajopt`): the band solver, stop on a small gain (``conv_rel``), on a
  feasible path, or when ``lam`` exceeds ``lam_stop``;
- the collision rows of :mod:`nik.kernels.collision_lm` are extra rows of the pose state (``s.extra = (Jr, r,
  w2)``), taken by the same dense step (:func:`nik.kernels.lm._propose_dense`); their measure adds ``w2 |r|^2`` to
  the pose cost, and skips the rows where the pose rows alone already exceed ``bar``.
"""

from __future__ import annotations

import math
from collections import namedtuple

from numba.extending import overload

from nik.kernels._jit import kernel
from nik.kernels.lm_step import _judge, _stalled

__all__ = ["ACCEPT_ANY", "ACCEPT_DONE", "ACCEPT_LOWER", "NEVER", "LoopCfg", "problem_kind"]

#: Accept rules: a good step whose cost is lower; or also one that is an answer; or every good step.
ACCEPT_LOWER, ACCEPT_DONE, ACCEPT_ANY = 0, 1, 2
#: An iteration count that is never reached.
NEVER = 2**62

#: The loop's configuration: ``limit`` iterations at most; damping from ``lam0``, times ``down`` after a kept step
#: (not below ``lo``), times ``up`` after a rejected one (not above ``hi``), stop after a rejected step that leaves it
#: above ``lam_stop``; stop after ``stall_limit`` steps in a row that lower the cost by less than ``stall_rel`` of it
#: (:func:`nik.kernels.lm_step._stalled`), and after a kept step that lowers it by less than ``conv_rel`` of it or
#: whose largest entry is below ``tiny`` (``-inf``, 0: never); ``accept``: ``ACCEPT_*``.
LoopCfg = namedtuple(
    "LoopCfg", ["limit", "lam0", "down", "up", "lo", "hi", "lam_stop", "stall_rel", "stall_limit", "conv_rel", "tiny",
                "accept"]
)  # fmt: skip


_KINDS: dict = {}  # problem class -> (measure, propose)


def problem_kind(cls, measure, propose) -> None:
    """Register the problem class ``cls`` (a named tuple) with its compiled ``measure`` and ``propose`` (module
    docstring): :func:`_lm_loop` on a problem of that class calls them."""
    _KINDS[cls] = (measure, propose)


def _measure(prob, s, bar):
    """The measure of ``prob``'s kind (compiled code only: :func:`problem_kind`)."""
    raise NotImplementedError("nik.kernels.lm_loop._measure runs in compiled code only")


def _propose(prob, s, lam, c):
    """The proposal of ``prob``'s kind (compiled code only: :func:`problem_kind`)."""
    raise NotImplementedError("nik.kernels.lm_loop._propose runs in compiled code only")


def _kind(prob):
    """The registered functions of the numba type ``prob`` (a named tuple of a registered class)."""
    cls = getattr(prob, "instance_class", None)
    if cls not in _KINDS:
        raise TypeError(f"nik.kernels.lm_loop: {prob} is not a registered problem kind (problem_kind)")
    return _KINDS[cls]


@overload(_measure, jit_options={"nogil": True})
def _measure_of(prob, s, bar):
    fn = _kind(prob)[0]

    def impl(prob, s, bar):
        return fn(prob, s, bar)

    return impl


@overload(_propose, jit_options={"nogil": True})
def _propose_of(prob, s, lam, c):
    fn = _kind(prob)[1]

    def impl(prob, s, lam, c):
        return fn(prob, s, lam, c)

    return impl


@kernel
def _loop_cfg(limit, lam0, damping, lam_stop, stall, conv, accept):
    """A :class:`LoopCfg` with its fields typed alike for every caller: ``damping = (down, up, lo, hi)``,
    ``stall = (stall_rel, stall_limit)``, ``conv = (conv_rel, tiny)``."""
    down, up, lo, hi = damping
    return LoopCfg(
        int(limit), float(lam0), float(down), float(up), float(lo), float(hi), float(lam_stop), float(stall[0]),
        int(stall[1]), float(conv[0]), float(conv[1]), int(accept),
    )  # fmt: skip


@kernel
def _lm_loop(prob, cfg, cur, cand, E, done):
    """Levenberg-Marquardt on ``prob`` from the state ``cur`` (measured: cost ``E``, ``done``), candidates in
    ``cand`` (module docstring). Returns ``(iterations, cost, done, state, other)``: the steps tried, the state that
    holds the answer and the other one (``cur`` and ``cand``, perhaps swapped)."""
    lam = cfg.lam0
    stall = 0
    it = 0
    while it < cfg.limit and not done:
        good, big = _propose(prob, cur, lam, cand)
        it += 1
        Ec = math.inf
        donec = False
        if good:
            Ec, donec = _measure(prob, cand, E)
        ok = (donec and cfg.accept == ACCEPT_DONE) or cfg.accept == ACCEPT_ANY
        kept, lam = _judge(good, E, Ec, ok, lam, cfg.down, cfg.up, cfg.lo, cfg.hi)
        stall = _stalled(kept, E, Ec, stall, cfg.stall_rel)
        if kept:
            converged = E - Ec < cfg.conv_rel * E or big < cfg.tiny
            cur, cand = cand, cur
            E, done = Ec, donec
            if converged:
                break
        elif lam > cfg.lam_stop:
            break
        if stall >= cfg.stall_limit:
            break
    return it, E, done, cur, cand
