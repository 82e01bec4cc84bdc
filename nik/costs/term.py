"""What every cost term is: a residual of the joints, its Jacobian, a weight, a name and an honest check.

A term maps joints ``q: (B, dof)`` (torch, any float dtype and device) to a residual ``r: (B, m)``; the
problem minimises ``sum_terms |weight * r|^2`` (the weight multiplies the residual, PyRoki's convention), and the
answer is judged by each term's :meth:`Term.check` ``(B,) bool``: a **constraint** (``hard = True``: the pose, the
bounds, the joint limits, collisions, a user's term with a finite ``tol``) must pass it for ``success``; a
**preference** (``hard = False``: a rest posture, the smoothness of a path) always passes and only pulls the answer.

Row ``b`` of ``r`` depends on row ``b`` of ``q`` only (per target), so the Jacobian is ``(B, m, dof)``:
:func:`autograd_jacobian` gets it from torch's reverse mode, one backward pass per residual entry (``m`` passes;
the terms with a compiled kernel give theirs instead where it is exact). Path terms (:mod:`nik.costs.smoothness`)
act on a whole path ``(N, dof)`` at once and say so with ``path = True``.
"""

from __future__ import annotations

import torch

__all__ = ["Term", "autograd_jacobian", "checked_residual"]


def checked_residual(r, q: torch.Tensor, name: str) -> torch.Tensor:
    """``r`` when it is a ``(B, m)`` floating tensor (B the rows of ``q: (B, dof)``, ``m >= 1``) with no NaN; a
    one-line ``ValueError`` naming the term ``name`` otherwise (a ``(B,)`` residual is taken as ``(B, 1)``)."""
    if not isinstance(r, torch.Tensor):
        raise ValueError(f"cost term {name!r}: the residual must be a torch tensor (B, m), got {type(r).__name__}")
    if r.dim() == 1 and r.shape[0] == q.shape[0]:
        r = r[:, None]
    if r.dim() != 2 or r.shape[0] != q.shape[0] or r.shape[1] < 1:
        raise ValueError(f"cost term {name!r}: the residual has shape {tuple(r.shape)}, expected (B, m) with "
                         f"B = {q.shape[0]} (one row per configuration of q: {tuple(q.shape)})")  # fmt: skip
    if not r.is_floating_point():
        raise ValueError(f"cost term {name!r}: the residual must be floating point, got {r.dtype}")
    bad = torch.isnan(r).any(-1)
    if bool(bad.any()):
        b = int(bad.nonzero()[0, 0])
        raise ValueError(f"cost term {name!r}: the residual is NaN at row {b} (q = {q[b].tolist()})")
    return r


def autograd_jacobian(fn, q: torch.Tensor, name: str = "term") -> tuple[torch.Tensor, torch.Tensor]:
    """``(r (B, m), J (B, m, dof))`` of ``fn: q (B, dof) -> (B, m)`` by torch's reverse mode (one backward pass
    per entry of the residual; row ``b`` of ``r`` must depend on row ``b`` of ``q`` only). Both detached; the
    entries of ``J`` that ``fn`` does not reach are 0, a NaN in ``J`` a one-line ``ValueError``."""
    x = q.detach().clone().requires_grad_(True)
    with torch.enable_grad():
        r = checked_residual(fn(x), q, name)
        m = r.shape[1]
        cols = []
        for i in range(m):
            if not r.requires_grad:
                cols.append(torch.zeros_like(x))
                continue
            (g,) = torch.autograd.grad(r[:, i].sum(), x, retain_graph=i < m - 1, allow_unused=True)
            cols.append(torch.zeros_like(x) if g is None else g)
    J = torch.stack(cols, dim=1)
    if bool(torch.isnan(J).any()):
        raise ValueError(f"cost term {name!r}: the residual's Jacobian (autograd) has NaN entries")
    return r.detach(), J.detach()


class Term:
    """The base of every term (a subclass is a small dataclass with ``name`` and ``weight`` fields).

    Subclasses give :meth:`residual` (the differentiable torch twin) and :meth:`check`; :meth:`evaluate` defaults
    to :func:`autograd_jacobian` of :meth:`residual`, and terms with an exact Jacobian of their own override it.
    ``hard``: the check counts for success (module docstring); ``path``: the term acts on a whole path.
    """

    name: str = "term"
    weight: float = 1.0
    hard: bool = True
    path: bool = False

    def residual(self, q: torch.Tensor) -> torch.Tensor:  # pragma: no cover - every term gives its own
        """``(B, m)`` residual of ``q: (B, dof)``, unweighted, differentiable."""
        raise NotImplementedError

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r (B, m), J (B, m, dof))``, unweighted and detached: what the LM of :mod:`nik.lm.problem` asks for."""
        return autograd_jacobian(self.residual, q, self.name)

    def jacobian(self, q: torch.Tensor) -> torch.Tensor:
        """``(B, m, dof)``: the Jacobian of :meth:`residual` (the one the LM uses, :meth:`evaluate`)."""
        return self.evaluate(q)[1]

    def check(self, q: torch.Tensor) -> torch.Tensor:
        """``(B,)`` bool: the answer ``q: (B, dof)`` meets this term (always True for a preference)."""
        return torch.ones(q.shape[0], dtype=torch.bool, device=q.device)

    def why(self) -> str:
        """What a failed :meth:`check` means, in a few words (for ``res.unmet`` and the warning)."""
        return f"{self.name} not met"
