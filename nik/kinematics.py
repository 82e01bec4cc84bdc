"""Batched forward kinematics kernels for serial chains of revolute and prismatic joints.

Every arm nik knows (standard DH, modified DH, product of exponentials, URDF) is
reduced once, at load time, to the same normal form

    T(q) = G_0 @ J_1 @ G_1 @ J_2 @ G_2 ... J_n @ G_n,   J_i = Rz(q_i + o_i)  (revolute)
                                                          J_i = Tz(q_i + o_i)  (prismatic)

with constant rigid transforms ``G: (n + 1, 4, 4)``, joint offsets ``o: (n,)`` and a mask
``prismatic: (n,) bool`` (``None``: all revolute): a joint about or along any axis ``a`` is
``P Rz(q) P^T`` or ``P Tz(q) P^T`` for a fixed rotation ``P`` taking z to ``a``, and the fixed
factors are merged into the neighbouring ``G``. FK is then pure tensor work: right-multiplying
by ``Rz`` mixes two columns (elementwise), by ``Tz(d)`` adds ``d`` times column 2 to column 3,
and right-multiplying by a constant ``G_i`` is one plain matrix product over the whole batch. Only the top three rows
``(..., 3, 4)`` are carried. There is no Python work per sample; the Python loop is over
joints only.

Two implementations of that product:

- :func:`chain_fk_eager`, generic: a column rotation and one small matrix product per joint;
- :func:`generate_fk_source`, specialised: for one robot, straight-line code over the twelve
  entries of ``T`` with the constants of ``G`` written in, so that products by the zeros and
  ones of DH tables disappear. It runs eagerly, and ``torch.compile`` fuses it into one loop
  over the batch (:class:`FKKernel` with ``compiled=True``), with a plain eager fallback.

The ground floor: this module imports nothing from nik.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

__all__ = [
    "FKKernel",
    "chain_fk",
    "chain_fk_eager",
    "chain_jacobian",
    "chain_joint_frames",
    "generate_fk_source",
    "prismatic_list",
    "to_homogeneous",
]


def to_homogeneous(T34: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 4)`` -> ``(..., 4, 4)`` by appending the row ``[0, 0, 0, 1]``."""
    bottom = torch.zeros(T34.shape[:-2] + (1, 4), dtype=T34.dtype, device=T34.device)
    bottom[..., 0, 3] = 1.0
    return torch.cat([T34, bottom], dim=-2)


def _rotate_columns(T: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """``T @ Rz(theta)`` for ``T: (B, 3, 4)``, with ``c, s: (B, 1)`` the cosine and sine of theta."""
    x, y = T[..., 0], T[..., 1]
    return torch.stack([x * c + y * s, y * c - x * s, T[..., 2], T[..., 3]], dim=-1)


def _translate_column(T: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """``T @ Tz(d)`` for ``T: (B, 3, 4)``, with ``d: (B, 1)``: column 3 gains ``d`` times column 2."""
    return torch.stack([T[..., 0], T[..., 1], T[..., 2], T[..., 3] + T[..., 2] * d], dim=-1)


def prismatic_list(prismatic, n: int) -> list[bool]:
    """``prismatic`` (``None``, a sequence or a ``(n,)`` bool tensor) as a list of ``n`` Python booleans."""
    if prismatic is None:
        return [False] * n
    flags = [bool(v) for v in (prismatic.tolist() if hasattr(prismatic, "tolist") else prismatic)]
    if len(flags) != n:
        raise ValueError(f"prismatic: expected {n} flags (one per joint), got {len(flags)}")
    return flags


def _joint_steps(q: torch.Tensor, offsets: torch.Tensor, prismatic):
    """Per joint ``i``: a function ``T -> T @ J_i`` (see the module docstring)."""
    flags = prismatic_list(prismatic, q.shape[-1])
    theta = q + offsets
    if not any(flags):
        c, s = torch.cos(theta), torch.sin(theta)
        return [lambda T, i=i: _rotate_columns(T, c[:, i : i + 1], s[:, i : i + 1]) for i in range(q.shape[-1])]
    mask = torch.as_tensor(flags, device=q.device)
    angle = torch.where(mask, torch.zeros_like(theta), theta)  # no cos/sin of a length
    c, s = torch.cos(angle), torch.sin(angle)
    return [
        (lambda T, i=i: _translate_column(T, theta[:, i : i + 1]))
        if flags[i]
        else (lambda T, i=i: _rotate_columns(T, c[:, i : i + 1], s[:, i : i + 1]))
        for i in range(q.shape[-1])
    ]


def chain_fk_eager(q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor, *, prismatic=None) -> torch.Tensor:
    """FK of the normal form, eager.

    Args:
        q: (B, n) joint values: radians (revolute), metres (prismatic).
        G: (n + 1, 4, 4) constant transforms, same dtype/device as ``q``.
        offsets: (n,) joint offsets, radians or metres.
        prismatic: (n,) bool, True where joint ``i`` translates along z (``Tz``); None: all revolute.

    Returns:
        (B, 3, 4): the top three rows of ``T(q)``.
    """
    T = G[0, :3, :].expand(q.shape[0], 3, 4)
    for i, step in enumerate(_joint_steps(q, offsets, prismatic)):
        T = step(T) @ G[i + 1]
    return T


_compiled_chain_fk = None


def chain_fk(
    q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor, *, compiled: bool = False, prismatic=None
) -> torch.Tensor:
    """Generic FK of the normal form for ``q: (B, n)`` -> ``(B, 3, 4)`` (see :func:`chain_fk_eager`).

    ``compiled=True`` runs it through ``torch.compile`` (falls back to eager on failure). For one
    fixed robot, :class:`FKKernel` (what :meth:`nik.Robot.fk` uses) is faster.
    """
    global _compiled_chain_fk
    if compiled:
        try:
            if _compiled_chain_fk is None:
                _compiled_chain_fk = torch.compile(chain_fk_eager, dynamic=True)
            return _compiled_chain_fk(q, G, offsets, prismatic=prismatic)
        except Exception as err:  # pragma: no cover - depends on the platform's compiler
            warnings.warn(f"compiled FK failed ({type(err).__name__}: {err}); using eager FK", stacklevel=2)
    return chain_fk_eager(q, G, offsets, prismatic=prismatic)


def _term(coef: float, var: str) -> str:
    if coef == 1.0:
        return f"+ {var}"
    if coef == -1.0:
        return f"- {var}"
    return f"+ {var} * {coef!r}" if coef > 0 else f"- {var} * {-coef!r}"


def generate_fk_source(G, offsets, *, name: str = "fk_kernel", prismatic=None, per_joint: bool = False) -> str:
    """Python source of a function ``name(q: (B, n)) -> (B, 4, 4)`` computing the normal-form FK.

    ``per_joint=True``: the function takes instead a sequence of ``n`` tensors, joint ``i``'s values, of any
    shapes that broadcast together, and returns the 12 entries ``T[r, c]`` (r < 3, row-major) in the broadcast
    shape (a Python float where an entry is constant). Products of the first joints are then computed on
    their own (smaller) shapes, and no 4x4 matrix is assembled.

    Each entry of ``T`` is tracked as a linear combination ``{variable: coefficient}`` of
    tensors, plus a constant; multiplying by a constant ``G_i`` only changes coefficients,
    and a new tensor variable is emitted only where two or more terms meet. Zero entries of
    ``G`` contribute nothing. A prismatic joint (``prismatic: (n,) bool``, None: all revolute)
    adds ``d_i`` times column 2 to column 3, with ``d_i = q_i + o_i``; for an all-revolute arm
    the source does not depend on ``prismatic``. The result equals :func:`chain_fk_eager` up to
    rounding.
    """
    G = np.asarray(G, dtype=float)
    n = G.shape[0] - 1
    flags = prismatic_list(prismatic, n)
    offsets = [float(o) for o in offsets]
    lines = [
        f"def {name}(q):",
        # joints as rows (n, B): every per-joint slice and every output row is contiguous, which lets
        # the eager ops and the compiled loop use SIMD (about 2x faster than (B, n) slices here)
        f"    theta = q.t() + q.new_tensor({offsets!r})[:, None]",
        "    c = torch.cos(theta)",
        "    s = torch.sin(theta)",
    ]
    if per_joint:
        lines = [f"def {name}(q):"] + [
            f"    theta{i} = q[{i}]" + (f" + {offsets[i]!r}" if offsets[i] != 0.0 else "") for i in range(n)
        ]
    counter = 0

    def emit(expr: dict) -> dict:
        nonlocal counter
        const = expr.get("", 0.0)
        terms = [(v, cf) for v, cf in expr.items() if v and cf != 0.0]
        if not terms or (len(terms) == 1 and const == 0.0):
            return {v: cf for v, cf in terms} or {"": const}
        counter += 1
        body = " ".join(_term(cf, v) for v, cf in terms) + (f" + {const!r}" if const != 0.0 else "")
        body = body[2:] if body.startswith("+ ") else "-" + body[2:]
        lines.append(f"    v{counter} = {body}")
        return {f"v{counter}": 1.0}

    def scaled(expr: dict, factor: str, sign: float) -> dict:
        return {(factor if v == "" else f"{v} * {factor}"): sign * cf for v, cf in expr.items() if cf != 0.0}

    def added(a: dict, b: dict) -> dict:
        out = dict(a)
        for v, cf in b.items():
            out[v] = out.get(v, 0.0) + cf
        return out

    T = [[{"": float(G[0, r, k])} for k in range(4)] for r in range(3)]
    for i in range(n):
        rotated = []
        if flags[i]:
            lines.append(f"    d{i} = theta{i}" if per_joint else f"    d{i} = theta[{i}]")
            for r in range(3):
                col3 = emit(added(T[r][3], scaled(T[r][2], f"d{i}", 1.0)))
                rotated.append([T[r][0], T[r][1], T[r][2], col3])
        else:
            if per_joint:
                lines += [f"    c{i} = torch.cos(theta{i})", f"    s{i} = torch.sin(theta{i})"]
            else:
                lines += [f"    c{i} = c[{i}]", f"    s{i} = s[{i}]"]
            for r in range(3):
                x, y = T[r][0], T[r][1]
                col0 = emit(added(scaled(x, f"c{i}", 1.0), scaled(y, f"s{i}", 1.0)))
                col1 = emit(added(scaled(y, f"c{i}", 1.0), scaled(x, f"s{i}", -1.0)))
                rotated.append([col0, col1, T[r][2], T[r][3]])
        Gi = G[i + 1]
        T = []
        for r in range(3):
            row = []
            for col in range(4):
                acc: dict = {}
                for k in range(4):
                    g = float(Gi[k, col]) if k < 3 else float(col == 3)
                    if g != 0.0:
                        acc = added(acc, {v: cf * g for v, cf in rotated[r][k].items()})
                row.append(acc)
            T.append(row)
    outputs = []
    for r in range(3):
        for k in range(4):
            expr = emit(T[r][k])
            ((v, cf),) = expr.items() if len(expr) == 1 else ((None, None),)
            if v == "":
                outputs.append(repr(cf) if per_joint else f"q.new_full(q.shape[:1], {cf!r})")
            elif cf == 1.0:
                outputs.append(v)
            elif cf == -1.0:
                outputs.append(f"(-{v})")
            else:
                outputs.append(f"({v} * {cf!r})")
    if per_joint:
        return "\n".join(lines + [f"    return [{', '.join(outputs)}]"])
    lines += [
        "    z = q.new_zeros(q.shape[:1])",
        "    o = q.new_ones(q.shape[:1])",
        f"    return torch.stack([{', '.join(outputs)}, z, z, z, o], dim=0).t().contiguous().reshape(-1, 4, 4)",
    ]
    return "\n".join(lines)


class FKKernel:
    """The specialised FK of one robot (:func:`generate_fk_source`), eager and compiled.

    ``kernel(q: (B, n), compiled=False) -> (B, 4, 4)``; ``prismatic: (n,) bool`` or None (all
    revolute). The compiled version is built on first use (seconds) with
    ``torch.compile(dynamic=True)``; if compiling or running it fails, a warning is given once and
    the eager version is used from then on.
    """

    def __init__(self, G, offsets, *, prismatic=None):
        self.source = generate_fk_source(G, offsets, prismatic=prismatic)
        namespace: dict = {"torch": torch}
        exec(compile(self.source, "<nik generated fk>", "exec"), namespace)
        self.eager = namespace["fk_kernel"]
        self._compiled = None
        self._compile_failed = False

    def __call__(self, q: torch.Tensor, *, compiled: bool = False) -> torch.Tensor:
        if compiled and not self._compile_failed:
            try:
                if self._compiled is None:
                    self._compiled = torch.compile(self.eager, dynamic=True)
                return self._compiled(q)
            except Exception as err:  # pragma: no cover - depends on the platform's compiler
                self._compile_failed = True
                warnings.warn(f"compiled FK failed ({type(err).__name__}: {err}); using eager FK", stacklevel=2)
        return self.eager(q)


def chain_joint_frames(
    q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor, *, prismatic=None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """FK plus, for every joint, its axis and a point on it, in the base frame.

    Joint ``i`` turns about (revolute) or slides along (prismatic) the z axis of the frame
    ``F_i = G_0 J_1 G_1 ... G_{i-1}`` (before its own ``J_i``): the axis is that frame's z column
    and the point its origin.

    Args:
        q: (B, n) joint values: radians (revolute), metres (prismatic).
        prismatic: (n,) bool or None (all revolute); see :func:`chain_fk_eager`.

    Returns:
        ``T: (B, 3, 4)``, ``axes: (B, 3, n)`` unit vectors and ``points: (B, 3, n)`` metres.
    """
    T = G[0, :3, :].expand(q.shape[0], 3, 4)
    axes, points = [], []
    for i, step in enumerate(_joint_steps(q, offsets, prismatic)):
        axes.append(T[..., 2])
        points.append(T[..., 3])
        T = step(T) @ G[i + 1]
    return T, torch.stack(axes, dim=-1), torch.stack(points, dim=-1)


def chain_jacobian(
    q: torch.Tensor, G: torch.Tensor, offsets: torch.Tensor, *, prismatic=None
) -> tuple[torch.Tensor, torch.Tensor]:
    """FK and geometric Jacobian of the normal form, in closed form.

    A revolute joint ``i``'s column is ``[z_i x (p - p_i); z_i]``, a prismatic one's ``[z_i; 0]``,
    with ``z_i``, ``p_i`` from :func:`chain_joint_frames`.

    Args:
        q: (B, n) joint values: radians (revolute), metres (prismatic).
        prismatic: (n,) bool or None (all revolute); see :func:`chain_fk_eager`.

    Returns:
        ``T: (B, 3, 4)`` and ``J: (B, 6, n)``, rows (linear velocity xyz, angular velocity xyz).
    """
    T, z, p = chain_joint_frames(q, G, offsets, prismatic=prismatic)
    lin = torch.linalg.cross(z, T[..., 3:4] - p, dim=-2)
    flags = prismatic_list(prismatic, q.shape[-1])
    if any(flags):
        mask = torch.as_tensor(flags, device=q.device)
        lin = torch.where(mask, z, lin)
        z = torch.where(mask, torch.zeros_like(z), z)
    return T, torch.cat([lin, z], dim=-2)
