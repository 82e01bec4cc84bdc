"""A user's own term: any residual of the joints, written in torch.

``nik.costs.custom(fn, weight=1.0, name="above_plane", jacobian=None, tol=1e-6)``: ``fn`` maps joints
``q: (B, dof)`` (a torch tensor in the call's dtype and device) to a residual ``(B, m)`` (a ``(B,)`` one counts as
``(B, 1)``); row ``b`` may depend on ``q[b]`` only. The Jacobian ``(B, m, dof)`` is ``jacobian(q)`` where given,
else torch's autograd of ``fn`` (one backward pass per entry of the residual). Success needs ``|r| <= tol``
per configuration (the Euclidean norm of the unweighted residual, in its own units); ``tol=math.inf`` makes the
term a preference that only pulls. A one-sided constraint is a hinge: keep a point above the plane ``z = h``
with ``(h - z).clamp(min=0)``.

Bad output is refused in one line naming the term: not a tensor, a wrong shape, NaN in the residual or in the
Jacobian (``inf`` is allowed in the residual: the check then fails and the LM cannot improve it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nik.costs.term import Term, autograd_jacobian, checked_residual

__all__ = ["CustomTerm", "custom"]


@dataclass(eq=False)
class CustomTerm(Term):
    """A user's residual ``fn`` with an optional ``jacobian_fn`` (module docstring)."""

    fn: object
    weight: float = 1.0
    name: str = "custom"
    jacobian_fn: object = None
    tol: float = 1e-6

    @property
    def hard(self) -> bool:  # a finite tolerance: a constraint
        return math.isfinite(self.tol)

    def residual(self, q: torch.Tensor) -> torch.Tensor:
        return checked_residual(self.fn(q), q, self.name)

    def evaluate(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.jacobian_fn is None:
            return autograd_jacobian(self.fn, q, self.name)
        with torch.no_grad():
            r = self.residual(q)
            J = self.jacobian_fn(q)
        want = (q.shape[0], r.shape[1], q.shape[1])
        if not isinstance(J, torch.Tensor) or tuple(J.shape) != want:
            got = tuple(J.shape) if isinstance(J, torch.Tensor) else type(J).__name__
            raise ValueError(f"cost term {self.name!r}: jacobian returned {got}, expected (B, m, dof) = {want}")
        if bool(torch.isnan(J).any()):
            raise ValueError(f"cost term {self.name!r}: the Jacobian has NaN entries")
        return r.detach(), J.detach().to(r)

    def check(self, q: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return torch.linalg.vector_norm(self.residual(q), dim=-1) <= self.tol

    def why(self) -> str:
        return f"{self.name}: residual above {self.tol:g}"


def custom(fn, weight: float = 1.0, name: str | None = None, jacobian=None, tol: float = 1e-6) -> CustomTerm:
    """A term of the user's residual ``fn: q (B, dof) -> (B, m)`` (module docstring); ``name`` defaults to the
    function's name, ``weight`` multiplies the residual, ``jacobian: q -> (B, m, dof)`` or None (autograd)."""
    if not callable(fn):
        raise ValueError(f"costs.custom: fn must be callable q (B, dof) -> (B, m), got {type(fn).__name__}")
    if jacobian is not None and not callable(jacobian):
        raise ValueError(f"costs.custom: jacobian must be callable q -> (B, m, dof) or None, got {jacobian!r:.40}")
    if not (isinstance(weight, int | float) and math.isfinite(weight) and weight > 0):
        raise ValueError(f"costs.custom: weight must be a number > 0, got {weight!r}")
    if not (isinstance(tol, int | float) and tol >= 0):  # NaN fails too
        raise ValueError(f"costs.custom: tol must be a number >= 0 (math.inf: a preference), got {tol!r}")
    name = name or getattr(fn, "__name__", "custom")
    name = "custom" if name == "<lambda>" else name
    return CustomTerm(fn, float(weight), str(name), jacobian, float(tol))
