"""The two backends of the one pipeline of :mod:`nik.ik.stages`: where a stage's work is computed.

A stage (guess, refine, near, more hypotheses, fallback, final check) is written once against the small interface
below; a backend implements it:

- :class:`~nik.ik.backends.compiled.CompiledBackend` (``"compiled"``): numpy arrays and the numba kernels of
  :mod:`nik.kernels` (LM, closed forms, the network's forward pass for a few poses, FK ranking of its hypotheses);
  a pose costs tens of microseconds, its Python around the kernels a few;
- :class:`~nik.ik.backends.torch.TorchBackend` (``"torch"``): torch tensors on any device (the GPU), the batched
  LM of :mod:`nik.lm`, the swarms, the batched closed form.

:func:`choose` picks the backend of a call: the compiled one for CPU targets with ``refine="lm"`` (the swarms run on
torch), except a closed-form arm's batches above :data:`CLOSED_FORM_CROSSOVER` (where the batched torch closed form
was measured faster per pose); torch otherwise. Whatever the backend, the answers satisfy the same contract (joints
inside the limits, errors measured by FK, honest ``success`` and ``reachable``), the same seed gives the same answer,
and ``IKResult.source`` names the guess that served.

Backend interface (``be``; arrays are numpy on the compiled backend, tensors on torch):

- ``be.job(solver, T_target, q_near, representation, tol_pos, tol_rot, seed, max_iters) -> Job``: validated
  targets (:mod:`nik.ik.targets`), reach flags, the unreachable warning;
- ``be.network(solver, job) -> (hyp (B, K, dof) ranked best first, pos (B,), rot (B,))``;
- ``be.closed_form(solver, job, idx, q_near) -> (q, pos, rot)``;
- ``be.uniform_guess(solver, job) -> q``: the best of 64 uniform configurations (a raw guess for ``refine="none"``);
- ``be.refine(solver, job, idx, q0, restarts) -> Refined``: the solver's refiner (LM; on torch also a swarm) from
  ``q0`` (None: uniform starts);
- ``be.lm_starts(solver, job, idx, starts (b, K, dof)) -> Refined``: LM from several starts per target;
- ``be.result(solver, job, answers, source) -> IKResult`` (tensors);
- array helpers: ``nonzero``, ``arange``, ``copy``, ``put``, ``norm``, ``where``.
"""

from __future__ import annotations

from nik.ik.backends.base import Job, Refined

__all__ = ["CLOSED_FORM_CROSSOVER", "Job", "Refined", "choose", "compiled_backend", "torch_backend"]

#: Largest CPU batch a closed-form arm solves on the compiled backend. ``benchmarks/crossover.py`` (one thread):
#: the compiled path was 34-59x faster for one pose, 2.1-2.2x at 1,024 targets, 0.83x (ur5) / 3.3x (kuka_kr) at
#: 4,096 and 1.06x / 1.38x at 10,000: the crossover lies between 1,024 and 4,096 targets. LM arms have none: the
#: compiled backend takes every CPU batch (its cost per pose does not grow with the batch).
CLOSED_FORM_CROSSOVER = 2_048

_COMPILED = None
_TORCH = None


def compiled_backend():
    """The compiled backend (one per process; it holds no per-call state)."""
    global _COMPILED
    if _COMPILED is None:
        from nik.ik.backends.compiled import CompiledBackend

        _COMPILED = CompiledBackend()
    return _COMPILED


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
    if forced == "auto" and (solver.closed_form or solver.fallback == "analytic"):
        if compiled_backend().state(solver).closed is None:
            return torch_backend()
        if solver.closed_form and _rows(T_target) > CLOSED_FORM_CROSSOVER:
            return torch_backend()
    return compiled_backend()


def _rows(T_target) -> int:
    """The number of poses in ``T_target`` by its shape (1 for one pose); 0 when it has none."""
    shape = getattr(T_target, "shape", None)
    if shape is None:
        try:
            import numpy as np

            shape = np.shape(T_target)
        except (TypeError, ValueError):
            return 0
    if len(shape) >= 2 and tuple(shape[-2:]) == (4, 4):
        return 1 if len(shape) == 2 else int(shape[0])
    return 1 if len(shape) == 1 else (int(shape[0]) if shape else 0)
