"""Batched evaluation of a population of networks that share one architecture.

A population is a matrix ``W: (NP, P)`` of flattened weight vectors, in the order of
``torch.nn.utils.parameters_to_vector(net.parameters())`` (``W_1, b_1, W_2, b_2, ...``). One
forward pass for all of them is a chain of batched matrix products (``(NP, N, in) @ (NP, in, out)``),
so a DE generation is a handful of large tensor operations, never a loop over individuals.
Samples are processed in chunks so that peak memory stays bounded: ``max_elements`` caps the
largest activation tensor ``NP x chunk x width``, and for the pose loss ``max_fk`` caps the FK
batch ``NP x chunk`` (220 networks on 10,000 samples would be 2.2 million FK evaluations at once).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch.nn.utils import parameters_to_vector, vector_to_parameters

from nik.learn.losses import joint_mse, pose_loss

__all__ = [
    "flat_params",
    "set_flat_params",
    "unflatten",
    "population_raw",
    "population_fitness",
    "sample_chunk",
    "init_population",
]


def flat_params(net: torch.nn.Module) -> torch.Tensor:
    """``(P,)`` copy of the net's weights and biases."""
    return parameters_to_vector(net.parameters()).detach().clone()


@torch.no_grad()
def set_flat_params(net: torch.nn.Module, w: torch.Tensor) -> None:
    """Write the flat vector ``w: (P,)`` into the net's parameters (in place)."""
    p = next(net.parameters())
    vector_to_parameters(w.detach().to(p.device, p.dtype), net.parameters())


def unflatten(net, W: torch.Tensor) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """``W: (NP, P)`` -> per layer ``(weight (NP, out, in), bias (NP, out))`` views."""
    layers, k = [], 0
    for out, inp in net.layer_shapes():
        w = W[:, k : k + out * inp].reshape(-1, out, inp)
        k += out * inp
        b = W[:, k : k + out]
        k += out
        layers.append((w, b))
    if k != W.shape[1]:
        raise ValueError(f"population vectors have {W.shape[1]} entries, the network has {k} parameters")
    return layers


def population_raw(net, W: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Raw outputs of every network. ``W: (NP, P)``, ``x: (N, D)`` standardised inputs -> ``(NP, N, out)``."""
    layers = unflatten(net, W)
    h = x
    for i, (w, b) in enumerate(layers):
        # (N, in) or (NP, N, in) @ (NP, in, out) -> (NP, N, out)
        h = torch.baddbmm(b[:, None, :], h.expand(W.shape[0], *h.shape[-2:]), w.transpose(1, 2))
        if i < len(layers) - 1:
            h = net.act(h)
    return h


def sample_chunk(
    net, n_pop: int, in_dim: int, *, loss: str = "joint", max_elements: int = 2**21, max_fk: int = 2**18
) -> int:
    """Samples per chunk of :func:`population_fitness` for ``n_pop`` networks on ``in_dim`` inputs:
    the largest chunk whose widest activation ``n_pop x chunk x width`` stays within ``max_elements``
    (and, for a pose loss, whose FK batch ``n_pop x chunk`` stays within ``max_fk``)."""
    width = max(max(net.hidden, default=1), net.out_dim, in_dim)
    chunk = max(1, max_elements // (n_pop * width))
    if loss != "joint":
        chunk = min(chunk, max(1, max_fk // n_pop))
    return chunk


@torch.no_grad()
def population_fitness(
    net,
    W: torch.Tensor,
    x: torch.Tensor,
    *,
    y_target: torch.Tensor | None = None,
    T_target: torch.Tensor | None = None,
    loss: str = "joint",
    rot_weight: float = 1.0,
    pose_weight: float = 1.0,
    max_elements: int = 2**21,
    max_fk: int = 2**18,
    chunk: int | None = None,
    between_chunks: Callable[[], None] | None = None,
) -> torch.Tensor:
    """Loss of every network of the population on the same samples.

    Args:
        net: an :class:`nik.nets.IKNet` (its architecture and buffers; its own weights are unused).
        W: (NP, P) flattened weights.
        x: (N, D) standardised inputs (``net.features(T_target)``).
        y_target: (N, out) encoded joint targets (``net.encode(q)``), for ``loss`` joint/both.
        T_target: (N, 4, 4) poses, for ``loss`` pose/both.
        loss: ``joint`` (paper C eq. 4), ``pose`` (through FK), or ``both`` (joint + pose_weight * pose).
        max_elements: cap on ``NP * chunk * widest layer`` (memory bound).
        max_fk: cap on ``NP * chunk`` FK evaluations at once (pose loss).
        chunk: samples per chunk (default: :func:`sample_chunk` of this ``NP``). The chunk decides the
            order of the sums over samples; each network's fitness is otherwise computed on its own,
            so a slice of the population evaluated with the whole population's chunk gives the same
            bits as the whole (how DE splits a population across processes).
        between_chunks: called before each chunk (a clock check that may raise to abandon the evaluation).

    Returns:
        (NP,) fitness, the mean over the N samples exactly as the single-network loss computes it.
    """
    if loss not in ("joint", "pose", "both"):
        raise ValueError(f"unknown loss {loss!r}; expected joint, pose or both")
    n_pop, n = W.shape[0], x.shape[0]
    if chunk is None:
        chunk = sample_chunk(net, n_pop, x.shape[1], loss=loss, max_elements=max_elements, max_fk=max_fk)
    total = torch.zeros(n_pop, dtype=W.dtype, device=W.device)
    for i in range(0, n, chunk):
        if between_chunks is not None:
            between_chunks()
        xs = x[i : i + chunk]
        y = population_raw(net, W, xs)
        part = torch.zeros_like(total)
        if loss in ("joint", "both"):
            part = part + joint_mse(y, y_target[i : i + chunk])
        if loss in ("pose", "both"):
            pl = pose_loss(
                net.decode(y), T_target[i : i + chunk], net.robot, length_scale=net.length_scale, rot_weight=rot_weight
            )
            part = part + (pose_weight if loss == "both" else 1.0) * pl
        total += part * xs.shape[0]
    return total / n


@torch.no_grad()
def init_population(
    net,
    n: int,
    *,
    generator: torch.Generator | None = None,
    between_chunks: Callable[[], None] | None = None,
) -> torch.Tensor:
    """``(n, P)`` initial weights, each individual drawn like PyTorch's default ``nn.Linear`` init:
    ``U(-1/sqrt(fan_in), 1/sqrt(fan_in))`` for weights and biases of each layer.

    ``between_chunks``: called before each block of about a million draws (a clock check that may raise to
    abandon the draw); the blocks consume the generator in the same order, so the values do not depend on it."""
    p = next(net.parameters())
    device = generator.device if generator is not None else torch.device("cpu")
    width = sum(out * inp + out for out, inp in net.layer_shapes())
    pop = torch.empty(n, width, dtype=p.dtype, device=p.device)
    k = 0
    for out, inp in net.layer_shapes():
        bound, cols = 1.0 / inp**0.5, out * inp + out
        rows = n if between_chunks is None else max(1, 2**20 // cols)
        for i in range(0, n, rows):
            if between_chunks is not None:
                between_chunks()
            m = min(rows, n - i)
            u = torch.rand(m, cols, generator=generator, device=device, dtype=torch.float64)
            pop[i : i + m, k : k + cols] = u.mul_(2).sub_(1).mul_(bound)  # (2u - 1) bound, in place: same values
        k += cols
    return pop
