"""The compiled path of the distances (:mod:`nik.kernels.collision`): the arrays it takes, and batched calls.

:func:`kernel_arguments` gives, for a robot, its model and a world, the tuple that follows ``q`` in every kernel
of :mod:`nik.kernels.collision` (``G, joints`` first): the two named groups ``(arm, scene)``
(:class:`nik.kernels.collision.ArmSpheres`, :class:`nik.kernels.collision.Scene`), what the LM pipeline passes per
call. The world's arrays come from :meth:`nik.collision.World.packed` (rebuilt only after a change), so a changed
world costs nothing here.
"""

from __future__ import annotations

import numpy as np

from nik.kernels.collision import ArmSpheres, Scene

__all__ = ["blocked_targets", "collision_names_compiled", "kernel_arguments", "signed_distances_compiled"]

_EMPTY = (np.zeros((0, 4)), np.zeros((0, 15)), np.zeros((0, 7)))


def kernel_arguments(robot, model, world=None, *, self_collision: bool = True):
    """``(G, joints), (arm, scene)``: the model arrays before ``q`` and the collision groups after it,
    ``arm = ArmSpheres(spheres, sphere_frame, body_start, pairs, self_on, link_grid, grids, grid_values)`` and
    ``scene = Scene(spheres, boxes, capsules)`` (:mod:`nik.kernels.collision`)."""
    G, joints = robot.chain_arrays()
    arm = ArmSpheres(*model.arrays(), bool(self_collision), *model.grid_arrays())
    return (G, joints), (arm, Scene(*(world.packed() if world is not None else _EMPTY)))


def signed_distances_compiled(robot, q, world=None, *, model=None, self_collision: bool = True) -> np.ndarray:
    """``(B, P + L)`` rows of :func:`nik.collision.signed_distances` for ``q: (B, dof)`` (numpy), compiled."""
    from nik.collision.model import collision_model
    from nik.kernels.collision import collision_distances_batch

    model = collision_model(robot) if model is None else model
    Q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, robot.dof))
    (G, joints), rest = kernel_arguments(robot, model, world, self_collision=self_collision)
    D = np.empty((len(Q), len(model.pairs) + len(model.links)))
    collision_distances_batch(G, joints, Q, *rest, D)
    return D


def blocked_targets(
    robot,
    model,
    world,
    T,
    tol_pos: float,
    tol_rot: float,
    *,
    self_collision: bool = True,
    samples: int = 180,
    depth: int = 4,
) -> np.ndarray:
    """``(B,)`` bool for targets ``T: (B, 4, 4)``: no configuration reaching ``T[b]`` within ``tol_pos`` (m) and
    ``tol_rot`` (rad) is free, proven by the rows the pose fixes (:func:`nik.kernels.collision.blocked_poses`:
    the tool's links against the base and the world, then the links of the first joint and of the last one swept
    over its range on ``samples`` values, each value's piece of the range halved up to ``depth`` times where its
    row is too close to call). The slack is ``tol_pos + tol_rot * lever`` (a rotation by ``a`` moves a point at
    ``l`` by at most ``a * l``), with two levers: for the tool's links' fixed rows, the farthest a sphere centre on
    the last frame lies from the tool point (only those spheres move with the pose); for the sweeps, the farthest on
    the last two frames (the last joint's links turn about its axis, bounded by their distance to that frame's
    origin plus the tool's). The fixed rows are judged first with the first, smaller slack (measured on the
    built-in panda's scene, seed 2: one more target of the 1,000 proven, that otherwise spent the restart budget).
    The halving (``depth`` 4: pieces down to 1/16 of a step) proves a swept link that collides at every value by
    less than one step's motion (measured on the same scene: one more target on seed 2); ``depth=0`` is the plain
    sweep."""
    from nik.kernels.collision import blocked_poses

    if depth < 0:
        raise ValueError(f"blocked_targets: depth must be >= 0 (halvings of a step), got {depth}")
    (G, joints), rest = kernel_arguments(robot, model, world, self_collision=self_collision)
    hand, lever = _levers(robot, model, G, rest[0])
    Tn = np.ascontiguousarray(np.asarray(T, dtype=np.float64).reshape(-1, 4, 4))
    out = np.empty(len(Tn), dtype=np.bool_)
    blocked_poses(G, joints, Tn, *rest, float(tol_pos + tol_rot * hand), 0, 0, out)  # the fixed rows alone
    rest_idx = np.flatnonzero(~out)
    if rest_idx.size and samples >= 2:  # the sweeps, on the targets the fixed rows leave
        more = np.empty(rest_idx.size, dtype=np.bool_)
        Tr = np.ascontiguousarray(Tn[rest_idx])
        blocked_poses(G, joints, Tr, *rest, float(tol_pos + tol_rot * lever), int(samples), int(depth), more)
        out[rest_idx] = more
    return out


def _levers(robot, model, G, arm) -> tuple[float, float]:
    """``(hand, sweep)`` levers of :func:`blocked_targets` (metres; its docstring), kept on the robot per model (they
    depend on the chain and the spheres only)."""
    from nik.kernels.collision import hand_lever

    memo = robot.__dict__.setdefault("_blocked_levers", {})
    got = memo.get(id(model))
    if got is not None and got[0] is model:
        return got[1]
    spheres, frames, n = arm.spheres, arm.sphere_frame, G.shape[0] - 1
    tool = G[n][:3, 3]
    hand = float(hand_lever(G, spheres, frames))
    levers = [hand]
    if n >= 2:  # frame n - 1 turns about the tool's last joint: bounded by its distance to that frame's origin
        inv = np.linalg.inv(G[n - 1])
        wrist = spheres[frames == n - 1, :3] @ inv[:3, :3].T + inv[:3, 3]
        levers += list(np.linalg.norm(wrist, axis=1) + np.linalg.norm(tool))
    memo[id(model)] = (model, (hand, float(max(levers))))
    return hand, float(max(levers))


def collision_names_compiled(robot, q, world=None, *, model=None, self_collision: bool = True) -> list:
    """:func:`nik.collision.collision_names` for ``q: (B, dof)`` (numpy) on the compiled kernels
    (:func:`nik.kernels.collision.overlaps_batch`): per configuration the sorted names of what overlaps, or None."""
    from nik.collision.model import collision_model
    from nik.kernels.collision import overlaps_batch

    model = collision_model(robot) if model is None else model
    Q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, robot.dof))
    (G, joints), rest = kernel_arguments(robot, model, world, self_collision=self_collision)
    counts = [len(a) for a in rest[1]]
    pair_hit = np.empty((len(Q), len(model.pairs)), dtype=np.bool_)
    world_hit = np.empty((len(Q), len(model.links), sum(counts)), dtype=np.bool_)
    overlaps_batch(G, joints, Q, *rest, pair_hit, world_hit)
    kinds = ("sphere", "box", "capsule")  # World.packed()'s order, named as nik.collision.check.OBSTACLE_KINDS
    obstacles = [f"{kind} {k}" for kind, c in zip(kinds, counts, strict=True) for k in range(c)]
    names = []
    for b in range(len(Q)):
        hits = [
            f"{model.links[model.pairs[p][0]]}|{model.links[model.pairs[p][1]]}" for p in np.flatnonzero(pair_hit[b])
        ]
        hits += [f"{model.links[link]}|{obstacles[o]}" for link, o in zip(*np.nonzero(world_hit[b]), strict=True)]
        names.append(sorted(set(hits)) or None)
    return names
