"""An exported network: ``NAME.safetensors`` (weights, read without pickle) + ``NAME.json`` (plain data).

The JSON holds what rebuilds and checks the network:

- ``robot``, ``robot_hash``, ``robot_definition``: the arm it was trained for (matched by the hash of
  the definition, never by the name: :attr:`nik.Robot.definition_hash`);
- ``net``: the architecture (:meth:`config` of :mod:`nik.nets.multi`, ``kind`` included; a plain
  :class:`nik.nets.IKNet` of ``train.py`` records ``kind: plain``);
- ``weights_sha256``, ``weights_bytes``: the SHA-256 and size of the ``.safetensors`` file beside it;
- ``training``: the command that really ran (``sys.argv``), the data it used, counters;
- ``validation``: its recorded error on a seeded validation set (:func:`nik.nets.pretrained.validation_error`);
- ``single_pose_network`` (optional): the file name of a small network for single poses beside it (``nik train``
  makes one where the main network does not pay for single poses, and ``--install`` installs both;
  :func:`link_single_pose`, :func:`single_pose_companion`);
- ``network_use`` (optional): whether it pays per call type on the CPU, with the figures
  (:func:`nik.ik.judge.record`, written by ``nik train``: :func:`nik.learn.report.record_use`); :func:`load_pair`
  attaches it to the network (``net.network_use_record``: the record and the weights' version counters, so a network
  trained further in place is measured again).

:func:`load_pair` checks, in this order, that the files exist, the JSON parses and has every field, the
weights' SHA-256 matches, the robot's definition hash matches, the architecture is known and every tensor
has the shape the architecture needs; any failure is a :class:`nik.CheckpointError` of one line naming the
file and the problem (a field of the JSON where the architecture does not fit).

:func:`write_pair_files` (used by :func:`save_pair` and :func:`nik.nets.registry.install`) replaces a pair so that a
kill at any instant leaves the old pair or the new one whole: both files are staged under hidden names
(``.NAME.new-<pid>-<random>.safetensors`` / ``.json``), the weights are checked against the JSON's SHA-256, the
staged JSON is renamed to ``.NAME.ready-<pid>-<random>.json`` (the commit point), then the weights and the JSON
take their names. :func:`recover_pairs` finishes a commit whose process died after its commit point (where the
staged weights still match the JSON's checksum) and deletes what a dead process staged before it, and the weights
of a removal (:func:`nik.nets.registry.remove`) that died after renaming the JSON to ``.NAME.del-<pid>-<random>.json``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import secrets
from pathlib import Path

import torch

from nik.data.storage import _fsync_dir, _pid_alive  # the datasets' kill-safe writes, shared
from nik.errors import CheckpointError, CheckpointNotFoundError
from nik.robots import Robot, load_robot

__all__ = [
    "PAIR_FORMAT",
    "architecture_mismatch",
    "link_single_pose",
    "load_pair",
    "pair_config",
    "pair_paths",
    "read_pair_meta",
    "recover_pairs",
    "save_pair",
    "single_pose_companion",
    "write_pair_files",
]

#: Version of the JSON; 2 added ``weights_sha256`` (format 1 files are refused: re-export them).
PAIR_FORMAT = 2
_REQUIRED = ("robot_hash", "net", "weights_sha256")


def _one_line(err: BaseException | str) -> str:
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__


def pair_config(net) -> dict:
    """The ``net`` field of a pair's JSON: ``net.config()``, with ``kind: plain`` for a plain :class:`nik.nets.IKNet`
    (whose own config, as its checkpoints store it, has no kind)."""
    from nik.nets.multi import PLAIN

    cfg = net.config()
    return cfg if "kind" in cfg else {"kind": PLAIN, **cfg}


def pair_paths(path: str | Path) -> tuple[Path, Path]:
    """``(NAME.safetensors, NAME.json)`` for either file of a pair (or a path without suffix)."""
    p = Path(path)
    if p.suffix == ".json":
        return p.with_suffix(".safetensors"), p
    if p.suffix == ".safetensors":
        return p, p.with_suffix(".json")
    return p.with_name(p.name + ".safetensors"), p.with_name(p.name + ".json")


def read_pair_meta(path: str | Path) -> dict:
    """The JSON of the pair at ``path`` (either file), checked for the fields every pair has.

    Raises:
        CheckpointNotFoundError (a CheckpointError and a FileNotFoundError): neither file exists.
        CheckpointError: a folder, no JSON beside the weights, unreadable JSON, a missing field, or format 1 (no
            SHA-256 recorded).
    """
    st, js = pair_paths(path)
    for p in (st, js):
        if p.is_dir():
            raise CheckpointError(f"{p} is a folder, not a network file (expected NAME.safetensors + NAME.json)")
    if not st.exists() and not js.exists():
        raise CheckpointNotFoundError(f"network file not found: {path}")
    if not js.exists():
        raise CheckpointError(f"{st}: no {js.name} beside it (the robot and architecture of the network)")
    try:
        meta = json.loads(js.read_text())
    except json.JSONDecodeError as err:
        raise CheckpointError(f"{js}: not valid JSON ({err.msg} at line {err.lineno}); the file is damaged") from err
    except (OSError, UnicodeDecodeError) as err:
        raise CheckpointError(f"{js}: unreadable ({_one_line(err)})") from err
    if not isinstance(meta, dict):
        raise CheckpointError(f"{js}: expected a JSON object, got {type(meta).__name__}")
    if meta.get("format") == 1 or ("weights_sha256" not in meta and "net" in meta):
        raise CheckpointError(
            f"{js}: records no SHA-256 of its weights (format 1, before nik checked files); "
            "re-export it with python -m nik.nets.export"
        )
    missing = [k for k in _REQUIRED if k not in meta]
    if missing:
        raise CheckpointError(f"{js}: field {missing[0]!r} is missing; not a nik network file")
    return meta


def architecture_mismatch(net: torch.nn.Module, state: dict[str, torch.Tensor], cfg: dict) -> str | None:
    """One line naming the field of ``cfg`` (the JSON's ``net``) whose architecture does not fit the tensors
    in ``state``, or None when every tensor of ``net`` is there with the right shape and nothing more."""
    want = net.state_dict()
    hidden = cfg.get("hidden")
    n_layers = len(getattr(net, "layers", []))
    file_layers = len({k.split(".")[1] for k in state if k.startswith("layers.")})
    if file_layers != n_layers:
        return f"net.hidden={hidden} makes {n_layers} layers, the weights have {file_layers}"
    for key, t in want.items():
        if key not in state:
            return f"tensor {key!r} is missing from the weights (net.kind={cfg.get('kind')!r})"
        got = tuple(state[key].shape)
        if got == tuple(t.shape):
            continue
        field = "net"
        if key.startswith("layers."):
            i = int(key.split(".")[1])
            out_dim_differs = got[0] != t.shape[0]
            if out_dim_differs and i < n_layers - 1:
                field = f"net.hidden[{i}]={hidden[i]}" if hidden else "net.hidden"
            elif out_dim_differs:
                if "heads" in cfg:
                    field = f"net.heads={cfg['heads']}"
                elif "output" in cfg:
                    field = f"net.output={cfg['output']!r}"
                else:
                    field = f"net.kind={cfg.get('kind')!r}"
            elif i > 0:
                field = f"net.hidden[{i - 1}]={hidden[i - 1]}" if hidden else "net.hidden"
            else:
                field = f"net.representation={cfg.get('representation')!r} / net.kind={cfg.get('kind')!r}"
        elif key in ("in_mean", "in_std"):
            field = f"net.representation={cfg.get('representation')!r}"
        return f"{field} needs {key} of shape {tuple(t.shape)}, the weights hold {got}"
    extra = sorted(set(state) - set(want))
    if extra:
        return f"the weights hold tensor {extra[0]!r} that net.kind={cfg.get('kind')!r} does not have"
    return None


def load_pair(path: str | Path, *, robot: Robot | str | Path | None = None):
    """The network of the pair at ``path`` (``NAME.safetensors`` or ``NAME.json``), eval mode, float32.

    Args:
        path: either file of the pair.
        robot: the arm it must belong to (object, built-in name or file), matched by definition hash, so the
            same arm under another name gets it; the network's ``robot`` is then this one. A robot with base or
            tool frames also takes a network made for its bare arm (:attr:`nik.Robot.arm`), whose ``robot`` is then
            that bare arm (it guesses in the arm's frame: ``base^-1 @ T @ tool^-1``). None: the arm stored in the
            JSON.

    Raises:
        CheckpointNotFoundError (a CheckpointError and a FileNotFoundError): no such file. CheckpointError: anything
            else wrong (module docstring), one line.
    """
    from safetensors.torch import load as st_load

    from nik.nets.multi import build_net

    st, js = pair_paths(path)
    meta = read_pair_meta(path)
    if not st.exists():
        raise CheckpointNotFoundError(f"network file not found: {st} (its {js.name} exists)")
    try:
        data = st.read_bytes()
    except OSError as err:
        raise CheckpointError(f"{st}: unreadable ({_one_line(err)})") from err
    digest = hashlib.sha256(data).hexdigest()
    if digest != meta["weights_sha256"] and recover_pairs(st.parent):  # a replacement killed half-way: finish it
        return load_pair(st, robot=robot)
    if digest != meta["weights_sha256"]:
        size = meta.get("weights_bytes")
        how = f"{len(data)} bytes, {size} recorded: truncated or grown" if size not in (None, len(data)) else "damaged"
        raise CheckpointError(
            f"{st}: SHA-256 {digest[:16]}... differs from {str(meta['weights_sha256'])[:16]}... recorded in "
            f"{js.name} ({how}, or not the file that was exported)"
        )
    if robot is not None:
        robot = robot if isinstance(robot, Robot) else load_robot(robot)
        if robot.definition_hash != meta["robot_hash"] and robot.arm_hash == meta["robot_hash"]:
            robot = robot.arm
        if robot.definition_hash != meta["robot_hash"]:
            raise CheckpointError(
                f"{st} was trained for robot {meta.get('robot')!r} (definition hash {meta['robot_hash']}), "
                f"not for {robot.name!r} (hash {robot.definition_hash}): another arm, or the arm was changed"
            )
    else:
        try:
            robot = Robot.from_definition(meta["robot_definition"])
        except (KeyError, TypeError, ValueError) as err:
            raise CheckpointError(f"{js}: field 'robot_definition' is missing or malformed ({_one_line(err)})") from err
        if robot.definition_hash != meta["robot_hash"]:
            raise CheckpointError(f"{js}: field 'robot_definition' does not have the recorded robot_hash")
    cfg = meta["net"]
    try:
        net = build_net(robot, cfg)
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{js}: field 'net' does not describe a network: {_one_line(err)}") from err
    try:
        state = st_load(data)
    except Exception as err:  # SafetensorError and friends: never let them escape raw
        raise CheckpointError(f"{st}: not a readable safetensors file ({_one_line(err)})") from err
    problem = architecture_mismatch(net, state, cfg)
    if problem is not None:
        raise CheckpointError(f"{st} does not fit the architecture in {js.name}: {problem}")
    net.load_state_dict(state)
    net = net.to(torch.float32).eval()
    if isinstance(meta.get("network_use"), dict):  # per call type, whether it pays (nik.ik.judge): valid while the
        net.network_use_record = (meta["network_use"], tuple(p._version for p in net.parameters()))  # weights stay
    return net


_STAGED = re.compile(r"^\.(?P<name>.+)\.(?P<kind>new|ready|del)-(?P<pid>\d+)-(?P<tag>[0-9a-f]+)\.(safetensors|json)$")


def _write_synced(path: Path, data: bytes) -> None:
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    path.chmod(0o644)


def _sha_of(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def _recorded_sha(text: str) -> str | None:
    """The ``weights_sha256`` a pair's JSON text records, or None."""
    try:
        meta = json.loads(text)
    except ValueError:
        return None
    return meta.get("weights_sha256") if isinstance(meta, dict) else None


def write_pair_files(st: str | Path, weights: bytes, meta_text: str) -> Path:
    """Replace the pair ``st`` (``NAME.safetensors`` + ``NAME.json``) by ``weights`` and the JSON ``meta_text`` so
    that a kill at any instant leaves the old pair or the new one whole (module docstring); returns ``st``.

    Raises:
        CheckpointError: ``meta_text`` does not record the SHA-256 of ``weights`` (nothing is replaced).
    """
    st, js = pair_paths(st)
    d = st.parent
    recover_pairs(d)
    if hashlib.sha256(weights).hexdigest() != _recorded_sha(meta_text):
        raise CheckpointError(f"{js}: the JSON does not record the SHA-256 of the weights to write; nothing written")
    tag = f"{os.getpid()}-{secrets.token_hex(4)}"
    new_st, new_js = d / f".{st.stem}.new-{tag}.safetensors", d / f".{st.stem}.new-{tag}.json"
    ready = d / f".{st.stem}.ready-{tag}.json"
    try:
        _write_synced(new_st, weights)
        _write_synced(new_js, meta_text.encode())
        os.rename(new_js, ready)  # the commit point: from here on the new pair wins
        _fsync_dir(d)
    except BaseException:
        for p in (new_st, new_js):
            if p.exists():
                p.unlink()
        raise
    os.replace(new_st, st)
    os.replace(ready, js)
    _fsync_dir(d)
    return st


def recover_pairs(directory: str | Path) -> bool:
    """Tidy what dead processes left in ``directory`` while replacing pairs: a commit past its commit point is
    finished (where the weights, staged or already in place, match the JSON's checksum), anything else they
    staged is deleted. Returns whether a pair was finished. Cheap where there is nothing to do (one listing)."""
    d = Path(directory)
    try:
        names = [p.name for p in d.iterdir() if p.name.startswith(".")]
    except OSError:
        return False
    staged = {}
    for n in names:
        m = _STAGED.match(n)
        if m and not _pid_alive(int(m["pid"])):
            staged.setdefault((m["name"], m["pid"], m["tag"]), set()).add(m["kind"])
    finished = False
    for (name, pid, tag), kinds in sorted(staged.items()):
        new_st, new_js = d / f".{name}.new-{pid}-{tag}.safetensors", d / f".{name}.new-{pid}-{tag}.json"
        ready = d / f".{name}.ready-{pid}-{tag}.json"
        st, js = d / f"{name}.safetensors", d / f"{name}.json"
        try:
            if "ready" in kinds:
                try:
                    want = _recorded_sha(ready.read_text())
                except (OSError, UnicodeDecodeError):
                    want = None
                weights = new_st if new_st.exists() else st
                if want is not None and _sha_of(weights) == want:
                    if weights == new_st:
                        os.replace(new_st, st)
                    os.replace(ready, js)
                    _fsync_dir(d)
                    finished = True
            installing = any(n.startswith(f".{name}.ready-") for n in names)  # a live install's weights: keep
            if "del" in kinds and not js.exists() and st.exists() and not installing:
                st.unlink()  # a removal died after taking the JSON away
            for p in (new_st, new_js, ready, d / f".{name}.del-{pid}-{tag}.json"):
                if p.exists():
                    p.unlink()
        except OSError:
            continue
    return finished


def save_pair(
    net, path: str | Path, *, training: dict | None = None, validation: dict | None = None, role: str | None = None
) -> Path:
    """Write ``net`` as ``path`` (``NAME.safetensors``, or a folder: ``<folder>/<robot name>.safetensors``)
    and the JSON beside it; returns the ``.safetensors`` path. ``validation``: the recorded error
    (:func:`nik.nets.pretrained.validation_error`'s dict), stored as given; ``role``: ``"single_pose"`` for a small
    network made to guess single poses (:mod:`nik.nets.registry`), recorded when given."""
    from safetensors.torch import save as st_save

    p = Path(path)
    if p.suffix not in (".safetensors", ".json"):
        p = p / f"{net.robot.name}.safetensors"
    st, js = pair_paths(p)
    st.parent.mkdir(parents=True, exist_ok=True)
    net = net.eval()
    state = {k: v.detach().cpu().contiguous().clone() for k, v in net.state_dict().items()}
    data = st_save(state, metadata={"robot": net.robot.name, "robot_hash": net.robot.definition_hash})
    meta = {
        "format": PAIR_FORMAT,
        "robot": net.robot.name,
        "robot_hash": net.robot.definition_hash,
        "robot_definition": net.robot.to_definition(),
        "net": pair_config(net),
        "n_params": int(net.n_params),
        "weights_sha256": hashlib.sha256(data).hexdigest(),
        "weights_bytes": len(data),
        "training": training or {},
        "validation": validation or {},
    }
    if role is not None:
        meta["role"] = role

    return write_pair_files(st, data, json.dumps(meta, indent=2) + "\n")


def link_single_pose(main: str | Path, companion: str | Path) -> None:
    """Record in ``main``'s JSON the single-pose network ``companion`` (a pair in the same folder) by its file name;
    the pair is replaced whole (:func:`write_pair_files`), the weights untouched."""
    st, _ = pair_paths(main)
    one, _ = pair_paths(companion)
    if one.parent.resolve() != st.parent.resolve():
        raise ValueError(f"{one}: a single-pose network must lie beside its main network {st}")
    meta = read_pair_meta(st)
    meta["single_pose_network"] = one.name
    write_pair_files(st, st.read_bytes(), json.dumps(meta, indent=2) + "\n")


def single_pose_companion(path: str | Path) -> Path | None:
    """The single-pose network that the pair at ``path`` names (:func:`link_single_pose`), or None: not a pair, none
    named, or the named file is not beside it (a pair copied without it)."""
    st, js = pair_paths(path)
    if st.suffix != ".safetensors" or not js.is_file():
        return None
    name = read_pair_meta(st).get("single_pose_network")
    if not isinstance(name, str) or Path(name).name != name:
        return None
    one = st.with_name(name)
    return one if one.is_file() else None
