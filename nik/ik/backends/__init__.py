"""The two backends of the one pipeline of :mod:`nik.ik.stages`: where a stage's work is computed.

A stage (guess, refine, near, more hypotheses, fallback, final check) is written once against the small interface
below; a backend implements it:

- :class:`~nik.ik.backends.compiled.CompiledBackend` (``"compiled"``): numpy arrays and the numba kernels of
  :mod:`nik.kernels` (LM, closed forms, the network's forward pass for a few poses, FK ranking of its hypotheses);
  a pose costs tens of microseconds, its Python around the kernels a few;
- :class:`~nik.ik.backends.torch.TorchBackend` (``"torch"``): torch tensors on any device (the GPU), the batched
  LM of :mod:`nik.lm`, the swarms, the batched closed form.

:func:`choose` picks the backend of a call: the compiled one for CPU targets with ``refine="lm"``, whatever the batch
size (its cost per pose does not grow with the batch, so a large batch never costs more per pose than the same
batch in chunks); torch otherwise (targets on a GPU, the swarms, ``refine="none"``). Whatever the backend, the
answers satisfy the same contract (joints
inside the limits, errors measured by FK, honest ``success`` and ``reachable``), the same seed gives the same answer,
and ``IKResult.source`` names the guess that served.

Backend interface (``be``; arrays are numpy on the compiled backend, tensors on torch; ``plan``: the call's
:class:`~nik.ik.plan.Plan`, never the solver):

- ``be.solve(robot, plan, T_target, q_near, representation) -> IKResult``: one call: the torch backend validates and
  runs the stages in a Python loop (:func:`nik.ik.stages.run`), the compiled one validates and runs them all in one
  kernel call (:mod:`nik.kernels.driver`); a single pose with nothing but tolerances and seed does not come here:
  :func:`nik.ik.backends.one_pose.one_pose` gives it the same kernel call with the arguments kept per solver
  settings, the same answer for a fraction of the Python;
- ``be.job(robot, plan, T_target, q_near, representation) -> Job``: validated targets (:mod:`nik.ik.targets`),
  reach flags, the unreachable warning;
- ``be.network(plan, job) -> (hyp (B, K, dof) ranked best first, pos (B,), rot (B,), checked)``: ``checked`` is
  ``(ok (B,), failing)`` where the backend measured them against the job's tolerances already, else None;
- ``be.closed_form(plan, job, idx, q_near) -> (q, pos, rot)``;
- ``be.uniform_guess(plan, job) -> q``: the best of 64 uniform configurations (a raw guess for ``refine="none"``);
- ``be.refine(plan, job, idx, q0, restarts, local=False) -> Refined``: the plan's refiner (LM; on torch also a
  swarm) from ``q0`` (None: uniform starts); ``local``: no joint wraps (LM; the near stage);
- ``be.lm(plan, job, idx, q0, restarts) -> Refined``: LM whatever the refine method (the multistart fallback);
- ``be.lm_starts(plan, job, idx, starts (b, K, dof)) -> Refined``: LM from several starts per target in turn;
- ``be.merge(answers, job, idx, refined, strict)``: answers take the refined rows that are better, in place;
- ``be.result(job, answers, source) -> IKResult`` (numpy arrays for numpy input, else tensors);
- array helpers: ``nonzero``, ``rows``, ``arange(n, like)``, ``copy``, ``put``, ``norm``, ``zeros_long(n, like)``,
  ``turns_toward(job, q)`` (the wrapping joints of ``q`` moved by whole turns towards ``job.q_near``)
  (``like``: an array whose device the result takes).
"""

from __future__ import annotations

from nik.ik.backends.base import Job, Refined

__all__ = ["Job", "Refined", "choose", "compiled_backend", "torch_backend"]

_COMPILED = {}
_TORCH = None


def compiled_backend(*, defer: bool | None = None):
    """The compiled backend (one per process and ``defer``; it holds no per-call state). ``defer``: on a kernel cache
    that lacks the call's compiled solve, answer from torch while it compiles in the background
    (:mod:`nik.kernels.background`); None: unless ``NIK_COMPILE=wait``."""
    found = _COMPILED.get(defer)
    if found is not None:
        return found
    if defer is None:  # NIK_COMPILE read once, on the first call
        from nik.kernels.background import defer_allowed

        _COMPILED[None] = compiled_backend(defer=defer_allowed())
        return _COMPILED[None]
    from nik.ik.backends.compiled import CompiledBackend

    found = _COMPILED[defer] = CompiledBackend(defer=defer)
    return found


def torch_backend():
    """The torch backend (one per process)."""
    global _TORCH
    if _TORCH is None:
        from nik.ik.backends.torch import TorchBackend

        _TORCH = TorchBackend()
    return _TORCH


def choose(solver, T_target):
    """The backend for ``solver.solve(T_target)`` (module docstring); ``solver.backend`` other than ``"auto"``
    forces one (the compiled one refuses targets that are not on the CPU)."""
    import torch

    forced = solver.backend
    if forced == "torch" or (forced == "auto" and solver.refine != "lm"):
        return torch_backend()
    if isinstance(T_target, torch.Tensor) and T_target.device.type != "cpu":
        if forced == "compiled":
            raise ValueError(f"IKSolver(backend='compiled'): targets on {T_target.device}, expected the CPU")
        return torch_backend()
    return compiled_backend(defer=False) if forced == "compiled" else compiled_backend()
