"""Trained multi-solution networks shipped with nik: ``<robot>.safetensors`` + ``<robot>.json``.

The ``.safetensors`` file holds the weights and buffers (read without pickle); the ``.json`` file holds
plain data: the robot's name, definition hash and definition, the architecture (:meth:`config` of
:mod:`nik.nets.multi`), how it was trained (command and config), and its recorded validation error with
the seed and size of the validation set that reproduces it (:func:`validation_error`).

:func:`load_pretrained` (also ``nik.models.load_pretrained``) is the public entry point; ``python -m
nik.nets.export`` writes a pair from a training checkpoint. The shipped files live in ``nik/nets/weights/``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from nik.errors import CheckpointError
from nik.nets.multi import build_net, hypothesis_pose_error
from nik.robots import Robot, load_robot

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
PRETRAINED_DIR = Path(__file__).resolve().parent / "weights"
#: Default validation set of a shipped network: ``n`` uniform joint vectors inside the limits from ``seed``.
VALIDATION = {"seed": 12345, "n": 2000}


def available(directory: str | Path | None = None) -> list[str]:
    """Names of the robots that have a shipped network (both files present), sorted."""
    d = Path(directory) if directory is not None else PRETRAINED_DIR
    return sorted(p.stem for p in d.glob("*.json") if p.with_suffix(".safetensors").is_file())


def read_meta(name: str, directory: str | Path | None = None) -> dict:
    """The ``.json`` block of robot ``name``'s shipped network."""
    d = Path(directory) if directory is not None else PRETRAINED_DIR
    path = d / f"{name}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise CheckpointError(f"cannot read {path}: {err}") from err


@torch.no_grad()
def validation_error(net, *, seed: int, n: int) -> dict:
    """Errors of ``net`` on ``n`` poses from uniform joints inside the limits (``torch.Generator`` seeded
    with ``seed``, float64 FK): medians and p95 of the position (mm) and rotation (deg) error of the best
    hypothesis by FK (``best_*``) and of the first hypothesis (``single_*``: branch 0 of a branch net, head 0
    of a multi-head net), as plain floats."""
    robot = net.robot
    g = torch.Generator().manual_seed(int(seed))
    q = robot.sample(int(n), generator=g, dtype=torch.float64)
    T = robot.fk(q)
    hyp = net.hypotheses(T)
    pos, rot = hypothesis_pose_error(robot, T, hyp)
    best = (pos + 0.1 * rot).argmin(-1, keepdim=True)
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


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        write(tmp)
        tmp.replace(path)
    finally:
        if tmp.exists():
            tmp.unlink()


def save(net, directory: str | Path, *, training: dict | None = None, validation: dict | None = None) -> Path:
    """Write ``<robot>.safetensors`` and ``<robot>.json`` for ``net`` into ``directory``; returns the json path.

    The validation error is measured here (:func:`validation_error` with ``validation``, default
    :data:`VALIDATION`) and recorded."""
    from safetensors.torch import save_file

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    name = net.robot.name
    net = net.eval()
    state = {k: v.detach().cpu().contiguous().clone() for k, v in net.state_dict().items()}
    val = dict(VALIDATION, **(validation or {}))
    meta = {
        "format": 1,
        "robot": name,
        "robot_hash": net.robot.definition_hash,
        "robot_definition": net.robot.to_definition(),
        "net": net.config(),
        "n_params": int(net.n_params),
        "training": training or {},
        "validation": validation_error(net, seed=val["seed"], n=val["n"]),
    }
    _atomic_write(
        d / f"{name}.safetensors", lambda p: (save_file(state, str(p), metadata={"robot": name}), p.chmod(0o644))
    )
    _atomic_write(d / f"{name}.json", lambda p: p.write_text(json.dumps(meta, indent=2, sort_keys=False) + "\n"))
    return d / f"{name}.json"


def load(robot, directory: str | Path | None = None):
    """The shipped network of ``robot`` (a :class:`nik.Robot` or a built-in name), in eval mode.

    Raises:
        CheckpointError: no network for this robot (the message names the robots that have one), or
            one made for a different definition of it (hash mismatch), or unreadable files.
    """
    from safetensors.torch import load_file

    d = Path(directory) if directory is not None else PRETRAINED_DIR
    if not isinstance(robot, Robot):
        robot = load_robot(robot)
    have = available(d)
    if robot.name not in have:
        raise CheckpointError(
            f"no pretrained network for robot {robot.name!r}; "
            f"pretrained networks exist for: {', '.join(have) or 'none'}"
        )
    meta = read_meta(robot.name, d)
    if meta.get("robot_hash") != robot.definition_hash:
        raise CheckpointError(
            f"the pretrained network for {robot.name!r} was trained for robot definition hash "
            f"{meta.get('robot_hash')}, not for this robot's {robot.definition_hash} (the arm was changed); "
            "train one for it (README, Learned multi-solution networks)"
        )
    try:
        net = build_net(robot, meta["net"])
        state = load_file(str(d / f"{robot.name}.safetensors"))
        net.load_state_dict(state)
    except (KeyError, ValueError, RuntimeError, OSError) as err:
        raise CheckpointError(f"cannot load the pretrained network for {robot.name!r}: {err}") from err
    return net.eval()


def pretrained_robots() -> list[str]:
    """Names of the robots with a network shipped in ``nik/nets/weights`` (sorted)."""
    return available()


def load_pretrained(robot: Robot | str | Path):
    """The network shipped with nik for ``robot`` (a :class:`nik.Robot`, built-in name or robot file), eval mode.

    It is a multi-solution network (:mod:`nik.nets.multi`): ``net.hypotheses(T)`` gives ``(B, K, dof)``
    joint hypotheses, ``net.predict(T)`` the best of them by FK. Read from safetensors (no pickle).

    Raises:
        CheckpointError: no network is shipped for this robot (the message names the robots that have
            one), or the shipped one was trained for a different definition of it (hash mismatch).
    """
    return load(robot)
