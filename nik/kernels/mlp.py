"""Forward pass of a multilayer perceptron, compiled: ``y = L_k(act(... act(L_1(x))))``.

The weights are taken once (per solver) as one flat contiguous float64 (or float32: then every product and sum is
float32, with the scratch ``work`` and the input in float32 too) array, layer after layer
``W_1 (out, in)`` row by row then ``b_1 (out,)``, ``W_2``, ``b_2``, ...; ``layout: (L, 3)`` int64
gives each layer's ``(out, in, offset of W in flat)`` (:func:`mlp_pack` builds both). The
activation (between layers, not after the last) is a code of :data:`ACTIVATIONS`, the same functions
as torch's defaults (``gelu`` exact with erf, ``elu`` with alpha 1, ``softplus`` with beta 1 and
threshold 20).

Rows ``x: (R, in)`` are pushed through together, so each weight row is read once per layer for all
R rows (a branch network evaluates its 8 branches as 8 rows).
"""

from __future__ import annotations

import math

import numpy as np

from nik.kernels._jit import kernel

__all__ = ["ACTIVATIONS", "mlp_forward", "mlp_pack", "mlp_work"]

#: Activation codes by name (the names of ``nik.models.ACTIVATIONS``).
ACTIVATIONS = {"tanh": 0, "relu": 1, "silu": 2, "gelu": 3, "elu": 4, "softplus": 5}


def mlp_pack(layers) -> tuple[np.ndarray, np.ndarray]:
    """``[(W (out, in), b (out,)), ...]`` (numpy or torch) -> ``(flat float64, layout (L, 3) int64)``."""
    parts, rows, offset, width = [], [], 0, None
    for W, b in layers:
        W = np.asarray(W, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64).reshape(-1)
        if W.ndim != 2 or b.shape[0] != W.shape[0]:
            raise ValueError(f"mlp_pack: layer {len(rows)}: W {W.shape} and b {b.shape} do not match")
        if width is not None and W.shape[1] != width:
            raise ValueError(f"mlp_pack: layer {len(rows)} takes {W.shape[1]} inputs, the one before gives {width}")
        rows.append((W.shape[0], W.shape[1], offset))
        parts += [W.reshape(-1), b]
        offset += W.size + b.size
        width = W.shape[0]
    if not rows:
        raise ValueError("mlp_pack: no layers")
    return np.ascontiguousarray(np.concatenate(parts)), np.array(rows, dtype=np.int64)


def mlp_work(layout: np.ndarray, rows: int) -> np.ndarray:
    """Scratch for :func:`mlp_forward`: ``(2, rows * widest layer)`` float64 (optional: without it the kernel
    allocates its own per call; one kept by the caller must not be shared by two threads at once)."""
    return np.empty((2, rows * int(max(layout[:, 0].max(), layout[:, 1].max()))))


@kernel
def _activate(v, code):
    if code == 0:
        return math.tanh(v)
    if code == 1:
        return v if v > 0.0 else 0.0
    if code == 2:
        return v / (1.0 + math.exp(-v))
    if code == 3:
        return 0.5 * v * (1.0 + math.erf(v * 0.7071067811865476))
    if code == 4:
        return v if v > 0.0 else math.expm1(v)
    return v if v > 20.0 else math.log1p(math.exp(v))


@kernel
def _store(y, dst, r, o, n_out, v, last, activation):
    """The last layer writes ``y[r, o]``; the others the activated value into the next layer's input."""
    if last:
        y[r, o] = v
    else:
        dst[r * n_out + o] = _activate(v, activation)


@kernel(fastmath={"reassoc", "contract"})
def mlp_forward(flat, layout, activation, x, y, work=None):
    """``x: (R, in)`` -> ``y: (R, out)`` (written in place) through the layers of ``flat, layout``.

    ``activation``: a code of :data:`ACTIVATIONS`; ``work``: :func:`mlp_work`, or None (default): scratch
    allocated per call, so that threads may share one network.
    """
    R = x.shape[0]
    L = layout.shape[0]
    if work is None:
        widest = x.shape[1]
        for layer in range(L):
            widest = max(widest, layout[layer, 0], layout[layer, 1])
        scratch = np.empty((2, R * widest), dtype=flat.dtype)
    else:
        scratch = work
    src = scratch[0]
    dst = scratch[1]
    zero = flat[0] - flat[0]  # in the weights' dtype: float32 weights compute in float32 (twice the lanes)
    for r in range(R):
        for i in range(x.shape[1]):
            src[r * x.shape[1] + i] = x[r, i]
    for layer in range(L):
        n_out, n_in, off = layout[layer, 0], layout[layer, 1], layout[layer, 2]
        bias = off + n_out * n_in
        last = layer == L - 1
        for o in range(n_out):
            w = flat[off + o * n_in : off + (o + 1) * n_in]  # views: the inner loops then vectorise
            b = flat[bias + o]
            r = 0
            while r + 4 <= R:  # four rows per pass over the weight row: one load of w per four products
                x0 = src[r * n_in : (r + 1) * n_in]
                x1 = src[(r + 1) * n_in : (r + 2) * n_in]
                x2 = src[(r + 2) * n_in : (r + 3) * n_in]
                x3 = src[(r + 3) * n_in : (r + 4) * n_in]
                a0 = a1 = a2 = a3 = zero
                for i in range(n_in):
                    wi = w[i]
                    a0 += wi * x0[i]
                    a1 += wi * x1[i]
                    a2 += wi * x2[i]
                    a3 += wi * x3[i]
                _store(y, dst, r, o, n_out, a0 + b, last, activation)
                _store(y, dst, r + 1, o, n_out, a1 + b, last, activation)
                _store(y, dst, r + 2, o, n_out, a2 + b, last, activation)
                _store(y, dst, r + 3, o, n_out, a3 + b, last, activation)
                r += 4
            while r < R:
                xr = src[r * n_in : (r + 1) * n_in]
                acc = zero
                for i in range(n_in):
                    acc += w[i] * xr[i]
                _store(y, dst, r, o, n_out, acc + b, last, activation)
                r += 1
        src, dst = dst, src
