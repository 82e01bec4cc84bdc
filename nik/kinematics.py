"""Batched forward kinematics kernels for serial revolute chains.

Every arm nik knows (standard DH, modified DH, product of exponentials, URDF) is
reduced once, at load time, to the same normal form

    T(q) = G_0 @ Rz(q_1 + o_1) @ G_1 @ Rz(q_2 + o_2) @ G_2 ... Rz(q_n + o_n) @ G_n

with constant rigid transforms ``G: (n + 1, 4, 4)`` and joint offsets ``o: (n,)``: a joint
about any axis ``a`` is ``P Rz(q) P^T`` for a fixed rotation ``P`` taking z to ``a``, and the
fixed factors are merged into the neighbouring ``G``. FK is then pure tensor work:
right-multiplying by ``Rz`` mixes two columns (elementwise), and right-multiplying by a
constant ``G_i`` is one plain matrix product over the whole batch. Only the top three rows
``(..., 3, 4)`` are carried. There is no Python work per sample; the Python loop is over
joints only.

``torch.compile`` fuses the whole product into one kernel; :func:`chain_fk` uses the
compiled version when asked and falls back to eager if compilation is unavailable.
"""

from __future__ import annotations

import warnings

import torch

__all__ = ["chain_fk", "chain_fk_eager", "chain_jacobian", "to_homogeneous"]


def to_homogeneous(T34: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 4)`` -> ``(..., 4, 4)`` by appending the row ``[0, 0, 0, 1]``."""
    bottom = torch.zeros(T34.shape[:-2] + (1, 4), dtype=T34.dtype, device=T34.device)
    bottom[..., 0, 3] = 1.0
    return torch.cat([T34, bottom], dim=-2)


def _rotate_columns(T: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """``T @ Rz(theta)`` for ``T: (B, 3, 4)``, with ``c, s: (B, 1)`` the cosine and sine of theta."""
    x, y = T[..., 0], T[..., 1]
    return torch.stack([x * c + y * s, y * c - x * s, T[..., 2], T[..., 3]], dim=-1)


def chain_fk_eager(q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """FK of the normal form, eager.

    Args:
        q: (B, n) joint angles, radians.
        G: (n + 1, 4, 4) constant transforms, same dtype/device as ``q``.
        offsets: (n,) joint offsets, radians.

    Returns:
        (B, 3, 4): the top three rows of ``T(q)``.
    """
    theta = q + offsets
    c, s = torch.cos(theta), torch.sin(theta)
    T = G[0, :3, :].expand(q.shape[0], 3, 4)
    for i in range(q.shape[-1]):
        T = _rotate_columns(T, c[:, i : i + 1], s[:, i : i + 1]) @ G[i + 1]
    return T


_compiled_fk = None
_compile_failed = False


def _get_compiled():
    global _compiled_fk, _compile_failed
    if _compiled_fk is None and not _compile_failed:
        try:
            _compiled_fk = torch.compile(chain_fk_eager, dynamic=True)
        except Exception as err:  # pragma: no cover - depends on the platform's compiler
            _compile_failed = True
            warnings.warn(f"torch.compile unavailable ({err}); nik FK falls back to eager", stacklevel=3)
    return _compiled_fk


def chain_fk(q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor, *, compiled: bool = False) -> torch.Tensor:
    """FK of the normal form for ``q: (B, n)`` -> ``(B, 3, 4)``; see :func:`chain_fk_eager`.

    ``compiled=True`` runs a ``torch.compile``'d kernel (the first call per dtype/device
    compiles, which takes seconds); if compilation fails at run time nik warns once and
    stays eager from then on.
    """
    global _compile_failed
    if compiled and not _compile_failed:
        fn = _get_compiled()
        if fn is not None:
            try:
                return fn(q, G, offsets)
            except Exception as err:  # pragma: no cover - depends on the platform's compiler
                _compile_failed = True
                warnings.warn(f"compiled FK failed ({type(err).__name__}: {err}); falling back to eager", stacklevel=2)
    return chain_fk_eager(q, G, offsets)


def chain_jacobian(q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """FK and geometric Jacobian of the normal form, in closed form.

    Joint ``i`` turns about the z axis of the frame ``F_i = G_0 Rz(.) G_1 ... G_{i-1}``
    (before its own ``Rz``), so its Jacobian column is ``[z_i x (p - p_i); z_i]`` in the
    base frame.

    Args:
        q: (B, n) joint angles, radians.

    Returns:
        ``T: (B, 3, 4)`` and ``J: (B, 6, n)``, rows (linear velocity xyz, angular velocity xyz).
    """
    theta = q + offsets
    c, s = torch.cos(theta), torch.sin(theta)
    T = G[0, :3, :].expand(q.shape[0], 3, 4)
    axes, points = [], []
    for i in range(q.shape[-1]):
        axes.append(T[..., 2])
        points.append(T[..., 3])
        T = _rotate_columns(T, c[:, i : i + 1], s[:, i : i + 1]) @ G[i + 1]
    z = torch.stack(axes, dim=-1)  # (B, 3, n)
    p = torch.stack(points, dim=-1)  # (B, 3, n)
    lin = torch.linalg.cross(z, T[..., 3:4] - p, dim=-2)
    return T, torch.cat([lin, z], dim=-2)
