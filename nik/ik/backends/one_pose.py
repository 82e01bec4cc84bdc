"""One pose, one kernel call: :meth:`nik.IKSolver.solve` on a single pose with nothing but the tolerances and the seed.

For one pose the kernels take a few microseconds; the general path of the compiled backend
(:meth:`~nik.ik.backends.compiled.CompiledBackend.solve`: the call's plan, the :class:`~nik.ik.backends.base.Job`,
the input checks of :mod:`nik.ik.targets`, six ``torch.from_numpy`` for a tensor pose) spent as long again in Python,
and after other work between calls (a control loop) each of those steps runs in cold caches. Here a call is:

1. the pose as it comes: a ``(4, 4)`` or ``(1, 4, 4)`` float64 or float32 numpy array, or a CPU tensor of those:
   a contiguous float64 tensor read at its address (:func:`nik.kernels.poses.pose_at`: 16 numbers copied, without
   the microseconds of ``Tensor.numpy()``), another through ``Tensor.numpy()``; float32 widened to float64 as the
   general path does;
2. its check by the compiled pose check (:func:`nik.kernels.poses.poses_ok`: finite, orthonormal, bottom row; the
   check of :func:`nik.ik.targets.pose_array`; for a tensor read at its address, in the same kernel call);
3. the plan of the call by the driver kernel (:func:`nik.kernels.driver.solve`), with the arguments it takes from the
   plan and the robot's model gathered once per solver settings, tolerances, seed and dtype (an :class:`Entry`, kept
   on the solver, which drops its entries when a setting changes: ``IKSolver.__setattr__``);
4. the :class:`~nik.ik.result.IKResult`: numpy arrays for a numpy pose; for a tensor pose a
   :class:`~nik.ik.result.TensorResult`. A float64 contiguous tensor pose's call writes into one of the entry's two
   output slots (:class:`_Outs`, made with the entry while torch is warm: one buffer, the kernel's six outputs as its
   numpy views, ``q`` and ``success`` as tensors on it, the pose's copy): the result's ``q`` and ``success`` are the
   slot's tensors, the other four fields tensors made when first read (``torch.from_numpy``), and the slot goes back
   to the entry. A call takes a slot only when nothing but the slot refers to it (:meth:`_Outs.state`: the Python
   reference counts of its objects, the storage's use count; a result, field, view, slice, ``Tensor.numpy()`` array,
   DLPack capsule or storage object held keeps it), and drops one whose tensors are no longer as made (an in-place
   operation of values or shape, ``requires_grad``, a ``grad``): what a caller keeps never changes, a loop that keeps
   only its previous result takes the two slots in turn, and where both are held (results kept, other threads) the
   call's arrays are new and the tensors made when first read (every float32 pose too). Two slots per entry: a loop's
   previous result is still held while its next call runs. Measured (``benchmarks/torch_result.py``, results in
   ``benchmarks/results/cold_pose_w40.md``): each torch call costs microseconds in cold caches (the first of a call
   most), ``torch.from_numpy`` more than the few attribute reads of the slot's check; of the ways to hand the tensors
   back measured before, made on first read was the cheapest (all six made at once cost 1-5 us more, made before
   the kernel call 1-9 us more, ``torch.empty`` outputs written through their ``Tensor.numpy()`` views 27-75 us
   more), and the slots are cheaper still: in loops of one kind of call (``--order blocks``, three runs of 4 rounds),
   the torch pose's extra time over a numpy pose with ``q`` and ``success`` read went from +8.0 to +11.2 us (ur5)
   and +16.9 to +20.8 us (panda) to +1.6 to +3.0 and +6.0 to +9.3 us call after call, from +21.2 to +23.5 and +23.4
   to +28.3 us to +8.4 to +10.0 and +8.4 to +14.3 us after 0.5 ms idle; the slot's check of the tensors' state
   (version, ``requires_grad``, two ``grad``) is about 3-5 us of that cold, the pose's six attribute reads most of
   the rest. The check of the slot put back last (the free one in a loop) is written out in :func:`one_pose`
   (:func:`_take` looks at the others): a Python frame or two fewer, after 0.5 ms idle +6.6 to +10.5 (ur5) and +9.9
   to +12.2 us (panda) became +4.9 to +7.4 and +6.0 to +9.2 us (six alternating runs each; per pair 1.5-3.9 and
   1.7-6.0 us less), call after call +0.2 to +1.3 and +2.0 to +5.5 us (``benchmarks/results/cold_pose_w42.md``).
   What is left is torch's reads, 1-3 us each cold (``benchmarks/torch_reads.py``: the pose's six +7.3 us, the
   slot's five +7.5, both +13.9 after 0.5 ms idle); in the call, without the slot's five the torch pose would be
   +0 to +5 us over numpy, without any -1 to -4 us. Each of the slot's reads guards what a test does and no
   reference count shows (a view, an in-place change of shape, ``requires_grad_``, a ``grad`` on either tensor).
   One call in place of the pose's reads costs as much: ``torch._C._to_dlpack`` +9.0 us, ``Tensor.type()`` +9.6;
   the DLTensor of the DLPack exchange API (``torch._C._dlpack_exchange_api``) read by a numba function with
   ``is_neg()`` still asked (DLPack export does not refuse a negative view) was no faster in the call (+5.8 to +9.8
   against +6.5 to +8.9 us), so the six reads stay.

The answer is the general path's, bit for bit (the same kernel on the same arguments: ``tests/test_one_pose.py``),
the unreachable warning included. Anything else returns None and the general path takes the call: a pose in
another form (quaternion, roll-pitch-yaw) or shape, a pose the check refuses (the general path words the error),
a non-contiguous, read-only or integer array, a tensor off the CPU or of another dtype, ``q_near``, ``bounds``,
``q_rest``, ``world``, ``plan``, ``max_iters`` or ``representation`` given, a collision check active, a network the
kernels do not pack, the torch backend or a refinement other than LM.
"""

from __future__ import annotations

import sys
import warnings
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from nik.ik import model as _models
from nik.ik.backends.compiled import as_float32
from nik.ik.collide import has_attached
from nik.ik.result import IKResult, TensorResult

__all__ = ["Entry", "entry", "one_pose"]

_F64, _F32 = np.dtype(np.float64), np.dtype(np.float32)
_T64, _T32 = torch.float64, torch.float32
_POSES_OK = None  # nik.kernels.poses.poses_ok, set with the first entry (import nik loads no numba)
_POSE_AT = None  # nik.kernels.poses.pose_at
_SOLVE = None  # nik.kernels.driver.solve
_ORTHONORMAL_TOL = 0.0
_POOL = True  # False: every tensor pose's result made on first read (benchmarks compare the two)


@dataclass(frozen=True)
class Entry:
    """What a one-pose call takes from the solver's settings, its tolerances, seed and the answer's dtype: the
    plan's ``model``; the driver's four argument tuples ``a0..a3``
    (:meth:`~nik.ik.backends.compiled.CompiledBackend.driver_args`); the guess's ``source``; whether the network
    takes the targets in the arm's frame (``arm_frame``); whether the answer is float32 (``f32``, with the asked
    tolerances ``tol_pos, tol_rot``); whether an attached collision model must be looked for per call
    (``look_attached``); the model generation it was made in."""

    model: Any
    a0: tuple
    a1: tuple
    a2: tuple
    a3: tuple
    source: str
    arm_frame: bool
    f32: bool
    tol_pos: float
    tol_rot: float
    look_attached: bool
    generation: int
    outs: list = field(default_factory=list, compare=False)


_LATER = object()  # entry(): not yet (the driver not compiled); not kept


def entry(solver, tol_pos, tol_rot, seed, f32: bool):
    """The :class:`Entry` of ``solver`` for these tolerances, seed and answer dtype, None where the one-pose path
    does not apply (module docstring), ``_LATER`` while the driver has nothing compiled (not kept). Raises the
    one-line ``ValueError`` of a bad tolerance."""
    global _POSES_OK, _POSE_AT, _SOLVE, _ORTHONORMAL_TOL
    from nik.ik.backends import compiled_backend
    from nik.ik.targets import check_tolerances

    check_tolerances(tol_pos, tol_rot)
    if solver.backend == "torch" or solver.refine != "lm" or solver.world is not None or solver.self_collision:
        return None
    if _SOLVE is None:
        from nik.kernels import driver, poses
        from nik.poses import ORTHONORMAL_TOL

        _POSES_OK, _POSE_AT, _SOLVE, _ORTHONORMAL_TOL = poses.poses_ok, poses.pose_at, driver.solve, ORTHONORMAL_TOL
    if not _SOLVE.signatures and solver.backend != "compiled" and compiled_backend().defer:
        from nik.kernels import background

        if background.cold(_SOLVE):  # nothing compiled on this machine: the general path answers from torch while
            return _LATER  # the driver compiles (nik.kernels.background); asked again on the next call
    generation = _models.generation
    plan = solver.plan(backend="compiled", tol_pos=tol_pos, tol_rot=tol_rot, seed=seed, poses=1)
    model = _models.model_of(solver.robot, plan.lm_cfg)
    packed = None
    if plan.source == "network":
        packed = model.packed(plan.net)
        if packed is None:
            return None
    dtype = torch.float32 if f32 else torch.float64
    a0, a1, a2, a3 = compiled_backend().driver_args(plan, model, dtype, packed)
    outs = [] if f32 else [_Outs(model.dof) for _ in range(SLOTS)]
    return Entry(
        model, a0, a1, a2, a3, plan.source, packed is not None and plan.net_in_arm_frame, f32, plan.tol_pos,
        plan.tol_rot, solver.self_collision is None, generation, outs,
    )  # fmt: skip


SLOTS = 2  # output slots kept per entry: a loop's previous result is still held while the next call runs
_USES = torch._C._storage_Use_Count
_new = object.__new__
_refs = sys.getrefcount
_weakrefs = weakref.getweakrefcount


class _Outs:
    """One output slot of a tensor pose's call: the kernel's six outputs as numpy views of one buffer ``buf``
    (``arrays``: ``q: (1, dof)``, ``pos_err, rot_err: (1,)`` float64, ``success: (1,)`` bool, ``iterations: (1,)``
    int64, ``reachable: (1,)`` bool), ``q`` and ``success`` also as tensors on the buffer (``torch.from_numpy``),
    and the pose's copy ``T: (1, 4, 4)``; made with the entry (torch warm), taken by a call only while :meth:`state`
    is 0."""

    __slots__ = ("buf", "base", "q", "ok", "arrays", "T", "st", "cd", "objs", "weak", "refs", "uses")

    def __init__(self, dof: int):
        n = 8 * dof
        self.buf = np.empty(n + 32, dtype=np.uint8)
        self.base = torch.from_numpy(self.buf)  # its storage holds buf: one reference fewer once torch lets go of it
        self.q, self.ok = self.base[:n].view(torch.float64).view(1, dof), self.base[n + 24 : n + 25].view(torch.bool)
        b = self.buf
        self.arrays = (
            b[:n].view(np.float64).reshape(1, dof), b[n : n + 8].view(np.float64), b[n + 8 : n + 16].view(np.float64),
            b[n + 24 : n + 25].view(np.bool_), b[n + 16 : n + 24].view(np.int64), b[n + 25 : n + 26].view(np.bool_),
        )  # fmt: skip
        del b
        self.T = np.empty((1, 4, 4))
        self.st = self.base.untyped_storage()  # the storage's Python object: torch hands out this one while it lives
        self.cd = self.st._cdata
        self.objs = (self.q, self.ok, self.base, self.st, self.buf, self.arrays, *self.arrays)
        self.weak = (self.q, self.ok, self.base, self.st)
        self.refs, self.uses = self.counts(), _USES(self.cd)

    def __reduce__(self):
        """A copy (``copy``, ``pickle`` of a solver) is a new slot: ``cd`` is an address in this process."""
        return _Outs, (self.q.shape[1],)

    def counts(self) -> tuple:
        """The Python reference counts of the slot's objects (the slot's own while nothing else holds them) and the
        weak references to its tensors and storage (none while nothing else holds one)."""
        return *map(_refs, self.objs), *map(_weakrefs, self.weak)

    def state(self) -> int:
        """0 (free) when nothing but the slot refers to its objects or memory: no Python reference, weak or not (a
        result, a field or a tensor made of a field on first read, ``_arrays``; a holder of a tensor from C++, such as
        a DLPack capsule taken, holds its Python object too), no other tensor on the storage (a view, a slice,
        ``detach()``, ``.data``, ``Tensor.numpy()``), the storage's memory still the buffer's (not moved by
        ``share_memory_()``: buf's count drops); 1 (held) otherwise; 2 (changed: never to be used again) when the
        tensors are no longer as made: a version above 0 (an in-place operation of values or shape on either: they
        share one version counter), ``requires_grad`` or a ``grad``. Not looked for: Python attributes set on a
        dropped result's tensor by hand, and raw addresses (``data_ptr()``) kept past the tensor's life.
        :func:`one_pose` writes this check out for the slot it looks at first (keep the two alike)."""
        if (*map(_refs, self.objs), *map(_weakrefs, self.weak)) != self.refs or _USES(self.cd) != self.uses:
            return 1  # the first test is counts(), written out: a call fewer (1-4 us less after 0.5 ms idle)
        q = self.q
        return 0 if q._version == 0 and not q.requires_grad and q.grad is None and self.ok.grad is None else 2


def _take(outs: list) -> _Outs | None:
    """A free slot of ``outs``, taken out of the list (``list.pop``: a slot is in one thread's hands at a time), or
    None; a held slot goes back to the list's front, a changed one is dropped."""
    for _ in range(len(outs)):
        try:
            slot = outs.pop()
        except IndexError:  # other threads hold the rest
            return None
        held = slot.state()
        if not held:
            return slot
        if held == 1:
            outs.insert(0, slot)
    return None


def one_pose(solver, T_target, tol_pos, tol_rot, seed) -> IKResult | None:
    """``solver.solve(T_target, tol_pos, tol_rot, seed)`` for one pose in one kernel call, or None where the general
    path must take the call (module docstring)."""
    kind = type(T_target)
    if kind is torch.Tensor:
        dt = T_target.dtype
        f32 = dt is _T32
        if not (f32 or dt is _T64) or not T_target.is_cpu:
            return None
    elif kind is np.ndarray:
        f32 = False
    else:
        return None
    shape = T_target.shape
    if shape != (4, 4) and shape != (1, 4, 4):
        return None
    key = (tol_pos, tol_rot, seed, f32)
    cache = solver._one
    try:
        e = cache.get(key, False)
    except TypeError:  # an unhashable tolerance (a numpy array of one number): the general path
        return None
    if e is False or e is not None and e.generation != _models.generation:
        if len(cache) >= 64:  # tolerances or seeds given as new objects each call (tensors hash by identity)
            cache.clear()
        e = entry(solver, tol_pos, tol_rot, seed, f32)
        if e is _LATER:
            return None
        cache[key] = e
    if e is None:
        return None
    slot = None
    if kind is torch.Tensor:
        if not f32 and T_target.is_contiguous() and not T_target.is_neg():
            if _POOL:  # _take written out for the slot put back last, free in a loop (1.5-6 us less after idle)
                outs = e.outs
                try:
                    slot = outs.pop()
                except IndexError:  # other threads hold the slots
                    slot = None
                else:
                    if (*map(_refs, slot.objs), *map(_weakrefs, slot.weak)) != slot.refs or _USES(slot.cd) != slot.uses:
                        outs.insert(0, slot)  # held: the others looked at
                        slot = _take(outs)
                    else:
                        sq = slot.q
                        if sq._version or sq.requires_grad or sq.grad is not None or slot.ok.grad is not None:
                            slot = _take(outs)  # changed: dropped
            a = np.empty((1, 4, 4)) if slot is None else slot.T  # read at its address: no Tensor.numpy()
            if not _POSE_AT(T_target.data_ptr(), _ORTHONORMAL_TOL, a):
                if slot is not None:
                    e.outs.append(slot)
                return None
        else:
            a = T_target.detach().numpy().reshape(1, 4, 4).astype(np.float64)
            if not _POSES_OK(a, _ORTHONORMAL_TOL):
                return None
    else:
        a = T_target if len(shape) == 3 else T_target[None]
        dt = a.dtype
        if dt is not _F64 and dt != _F64:
            if dt != _F32:
                return None
            a = a.astype(np.float64)
        elif not a.flags.carray:  # C-contiguous, aligned, writeable: the one kernel version there is
            return None
        if not _POSES_OK(a, _ORTHONORMAL_TOL):
            return None
    model = e.model
    if e.look_attached and has_attached(model.robot):
        if slot is not None:
            e.outs.append(slot)
        return None
    if slot is None:
        q, pos, rot = np.empty((1, model.dof)), np.empty(1), np.empty(1)
        ok, it, reach = np.empty(1, dtype=np.bool_), np.empty(1, dtype=np.int64), np.empty(1, dtype=np.bool_)
    else:
        q, pos, rot, ok, it, reach = slot.arrays
    Tin = model.arm_targets(a) if e.arm_frame else a
    if not _SOLVE(*e.a0, a, *e.a1, Tin, *e.a2, q, False, *e.a3, q, pos, rot, ok, it, reach):
        warnings.warn(model.unreachable_message(a, reach), UserWarning, stacklevel=3)
    if f32:
        q, pos, rot, ok = as_float32(model, a, q, e.tol_pos, e.tol_rot)
    if slot is not None:
        res = _new(TensorResult)
        res.__dict__ = {"_arrays": slot.arrays, "source": e.source, "q": slot.q, "success": slot.ok}
        e.outs.insert(0, slot)
        return res
    if kind is torch.Tensor:
        return TensorResult.of(q, pos, rot, ok, it, reach, e.source)
    return IKResult(q, pos, rot, ok, it, e.source, reachable=reach)
