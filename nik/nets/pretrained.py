"""Trained multi-solution networks for an arm: the shipped ones and the user's, found by definition hash.

A network is a pair ``NAME.safetensors`` + ``NAME.json`` (:mod:`nik.nets.pair`: the weights, read without
pickle, and plain data: the robot's name, definition hash and definition, the architecture, the SHA-256 of
the weights, how it was trained and its recorded validation error with the seed and size of the validation
set that reproduces it, :func:`validation_error`). Which pair an arm gets is :mod:`nik.nets.registry`'s
business (the user folder, then the shipped one, by hash).

:func:`load_pretrained` (also ``nik.models.load_pretrained``) is the public entry point; ``python -m
nik.nets.export`` writes a pair from a training checkpoint. The shipped files live in ``nik/nets/weights/``.
"""

from __future__ import annotations

from pathlib import Path

import torch

from nik.errors import CheckpointError
from nik.nets.multi import hypothesis_pose_error
from nik.nets.pair import load_pair, pair_paths, read_pair_meta, save_pair
from nik.nets.registry import SHIPPED_DIR, SINGLE_POSE, find_network, index, role_of
from nik.robots import Robot, load_robot
from nik.tolerances import score

__all__ = [
    "PRETRAINED_DIR",
    "VALIDATION",
    "available",
    "load",
    "load_pretrained",
    "pretrained_robots",
    "read_meta",
    "save",
    "validation_error",
]

#: Folder of the shipped files (inside the package).
PRETRAINED_DIR = SHIPPED_DIR
#: Default validation set of a shipped network: ``n`` uniform joint vectors inside the limits from ``seed``.
VALIDATION = {"seed": 12345, "n": 2000}


def available(directory: str | Path | None = None, *, single_pose: bool = False) -> list[str]:
    """Names of the robots that have a shipped network (both files present), sorted; ``single_pose=True``: the
    names of the shipped single-pose networks instead (``<robot>_one``, recorded role ``single_pose``)."""
    d = Path(directory) if directory is not None else PRETRAINED_DIR
    return sorted(st.stem for st, _ in index([d]) if (role_of(st) == SINGLE_POSE) == single_pose)


def read_meta(name: str, directory: str | Path | None = None) -> dict:
    """The ``.json`` block of the network ``name`` in ``directory`` (default: the shipped folder)."""
    d = Path(directory) if directory is not None else PRETRAINED_DIR
    return read_pair_meta(d / f"{name}.json")


@torch.no_grad()
def validation_error(net, *, seed: int, n: int) -> dict:
    """Errors of ``net`` on ``n`` poses from uniform joints inside the limits (``torch.Generator`` seeded
    with ``seed``, float64 FK): medians and p95 of the position (mm) and rotation (deg) error of the best
    hypothesis by FK (``best_*``) and of the first hypothesis (``single_*``: branch 0 of a branch net, head 0
    of a multi-head net), as plain floats. A plain network (:class:`nik.nets.IKNet`) has one guess a pose: both are
    its guess, clamped to the limits."""
    robot = net.robot
    g = torch.Generator().manual_seed(int(seed))
    q = robot.sample(int(n), generator=g, dtype=torch.float64)
    T = robot.fk(q)
    hyp = net.hypotheses(T) if hasattr(net, "hypotheses") else net.predict(T)[:, None]
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = score(pos, rot).argmin(-1, keepdim=True)
    out = {"seed": int(seed), "n": int(n)}
    for name, (p, r) in {
        "best": (pos.gather(1, best)[:, 0], rot.gather(1, best)[:, 0]),
        "single": (pos[:, 0], rot[:, 0]),
    }.items():
        p_mm, r_deg = p * 1e3, torch.rad2deg(r)
        out[f"{name}_pos_mm_median"] = float(p_mm.median())
        out[f"{name}_pos_mm_p95"] = float(torch.quantile(p_mm, 0.95))
        out[f"{name}_rot_deg_median"] = float(r_deg.median())
        out[f"{name}_rot_deg_p95"] = float(torch.quantile(r_deg, 0.95))
    return out


def save(
    net, directory: str | Path, *, training: dict | None = None, validation: dict | None = None, role: str | None = None
) -> Path:
    """Write ``net`` as a pair (:func:`nik.nets.pair.save_pair`): ``directory`` is a folder (the pair is named
    after the robot) or a ``NAME.safetensors`` path; returns the ``.json`` path.

    The validation error is measured here (:func:`validation_error` with ``validation``, default
    :data:`VALIDATION`) and recorded, with the SHA-256 of the weights."""
    val = dict(VALIDATION, **(validation or {}))
    record = validation_error(net.eval(), seed=val["seed"], n=val["n"])
    return pair_paths(save_pair(net, directory, training=training, validation=record, role=role))[1]


def load(robot, directory: str | Path | None = None):
    """The network for ``robot`` (a :class:`nik.Robot`, built-in name or robot file), eval mode: the pair
    in ``directory`` (default: the user folder, then the shipped one; :mod:`nik.nets.registry`) whose
    recorded robot hash is the robot's definition hash, else that of its bare arm (:attr:`nik.Robot.arm`: base and
    tool frames left out, so the built-in arms' flanges keep their networks), whatever its name. Its weights' SHA-256
    is checked. A network found for the bare arm guesses in the bare arm's frame (its ``robot`` is ``robot.arm``):
    for a robot with frames, give it ``base^-1 @ T @ tool^-1`` (:class:`nik.IKSolver` does).

    Raises:
        CheckpointError: no network for this robot's definition (the message names the robots that have
            one, and says so when a network of that name exists for another definition), or a damaged file.
    """
    if not isinstance(robot, Robot):
        robot = load_robot(robot)
    dirs = [Path(directory)] if directory is not None else None
    path = find_network(robot, dirs)
    if path is None:
        have = sorted({st.stem for st, _ in index(dirs)})
        same_name = [st for st, h in index(dirs) if st.stem == robot.name]
        if same_name:
            other = read_pair_meta(same_name[0]).get("robot_hash")
            raise CheckpointError(
                f"the network {same_name[0]} was trained for robot definition hash {other}, not for this "
                f"robot's {robot.definition_hash} (the arm was changed); train one for it: nik train {robot.name}"
            )
        raise CheckpointError(
            f"no pretrained network for robot {robot.name!r} (definition hash {robot.definition_hash}); "
            f"pretrained networks exist for: {', '.join(have) or 'none'}; train one: nik train ROBOT"
        )
    return load_pair(path, robot=robot)


def pretrained_robots() -> list[str]:
    """Names of the robots with a network shipped in ``nik/nets/weights`` (sorted)."""
    return available()


def load_pretrained(robot: Robot | str | Path):
    """The network for ``robot`` (a :class:`nik.Robot`, built-in name or robot file), eval mode: the one
    installed in the user folder (``nik train --install``) or else shipped with nik, matched by the robot's
    definition hash (the same arm under another name gets it).

    It is a multi-solution network (:mod:`nik.nets.multi`): ``net.hypotheses(T)`` gives ``(B, K, dof)``
    joint hypotheses, ``net.predict(T)`` the best of them by FK. Read from safetensors (no pickle).

    Raises:
        CheckpointError: no network for this robot's definition (the message names the robots that have
            one), or a damaged file (the SHA-256 of its weights is checked).
    """
    return load(robot)
