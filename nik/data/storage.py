"""On-disk dataset format: a directory of ``.npy`` files plus ``meta.json``; no pickle.

Layout of ``data/NAME/``::

    q.npy        (N, dof)     joint vectors, radians, float32 or float64
    pose.npy     (N, 4, 4)    FK(q): tool poses in the base frame, metres, same dtype as q
    branch.npy   (N,) uint8   IK branch label 0..7 (only for arms with a branch classifier)
    meta.json                 everything else (see :func:`nik.data.generate_dataset`),
                              including a SHA-256 checksum of every array file

``.npy`` files open memory-mapped (``np.load(mmap_mode="r")``), so loading is lazy: only the
pages a training loop touches are read. Splits are contiguous index ranges
``{"train": [0, a], "val": [a, b], "test": [b, N]}`` stored in ``meta.json``; a split is a
zero-copy slice of the mapped arrays.

Writing is atomic at the directory level: files go to a hidden temporary sibling
``.NAME.tmp-<pid>-<random>`` that is renamed to ``NAME`` only when complete; a kill at any instant
leaves the old or the new dataset whole (:class:`AtomicDirectory`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from nik.errors import DatasetError

__all__ = [
    "ARRAY_FILES",
    "FORMAT_VERSION",
    "META_FILE",
    "IKDataset",
    "NpyStreamWriter",
    "AtomicDirectory",
    "is_whole",
    "load_dataset",
    "sha256_file",
]

#: Version of the on-disk layout; bumped on incompatible changes.
FORMAT_VERSION = 1
META_FILE = "meta.json"
#: Array files a dataset may hold, in the order they are written.
ARRAY_FILES = ("q.npy", "pose.npy", "branch.npy")
_HASH_BLOCK = 1 << 22  # 4 MiB


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a whole file, read in 4 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(_HASH_BLOCK):
            h.update(block)
    return h.hexdigest()


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------
class NpyStreamWriter:
    """Writes one ``.npy`` file of known shape sequentially, row block by row block.

    The header is written first; :meth:`write` appends C-ordered rows and feeds the same bytes
    to a SHA-256, so the checksum costs no second pass. Plain sequential ``write`` calls keep
    the process's memory bounded by one chunk (a memory map would count every written page
    in the resident set until it is flushed).
    """

    def __init__(self, path: str | Path, dtype: np.dtype, shape: tuple[int, ...]):
        self.path = Path(path)
        self.dtype = np.dtype(dtype).newbyteorder("<") if np.dtype(dtype).itemsize > 1 else np.dtype(dtype)
        self.shape = tuple(int(s) for s in shape)
        self.rows_written = 0
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            header, {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": self.shape}
        )
        self._file = open(self.path, "wb")
        self._file.write(header.getvalue())
        self._hash = hashlib.sha256(header.getvalue())

    def write(self, rows: np.ndarray) -> None:
        rows = np.ascontiguousarray(rows, dtype=self.dtype)
        if rows.shape[1:] != self.shape[1:]:
            raise ValueError(f"{self.path.name}: rows of shape {rows.shape[1:]}, expected {self.shape[1:]}")
        if self.rows_written + rows.shape[0] > self.shape[0]:
            raise ValueError(f"{self.path.name}: more than {self.shape[0]} rows written")
        buf = memoryview(rows).cast("B")
        self._file.write(buf)
        self._hash.update(buf)
        self.rows_written += rows.shape[0]

    def close(self, *, fsync: bool = True) -> str:
        """Check that every row was written, flush (and fsync) the file; returns its SHA-256."""
        if self.rows_written != self.shape[0]:
            self.abort()
            raise RuntimeError(f"{self.path.name}: {self.rows_written} of {self.shape[0]} rows written")
        self._file.flush()
        if fsync:
            os.fsync(self._file.fileno())
        self._file.close()
        return self._hash.hexdigest()

    def abort(self) -> None:
        if not self._file.closed:
            self._file.close()


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


class AtomicDirectory:
    """A directory written under a temporary sibling name and renamed into place when complete.

    Usage::

        with AtomicDirectory(out, overwrite=False) as tmp:
            ...write files into tmp...
            # on normal exit: tmp is renamed to out (an old out is swapped out, then removed)
        # on an exception (Ctrl-C included): tmp is removed, out is untouched

    A kill at any instant (SIGKILL, power loss) leaves ``out`` as the old or the new directory, whole, or,
    between the two renames of an overwrite, missing with the old one whole aside; the next
    :class:`AtomicDirectory` for the same ``out`` (:meth:`cleanup_stale`) puts it back. The sibling names,
    each ``.NAME.<kind>-<pid>-<random>``, say what a copy is:

    - ``tmp``: being written; never put back (removed once its process is gone);
    - ``old``: the old ``out``, moved aside whole by an overwrite before the new one takes its name; put back
      only where ``out`` is missing and the copy is whole, verified against its own checksums (a half copy, or
      one that is not a dataset, is deleted, never restored);
    - ``del``: being deleted; renamed so before the first file is removed, never put back.

    With ``overwrite=True`` the order is: rename ``out`` to ``old``, rename ``tmp`` to ``out``, rename ``old``
    to ``del``, delete ``del``. Only the directory renames change what ``out`` is, and each is atomic.
    """

    def __init__(self, out: str | Path, *, overwrite: bool = False, marker: str = META_FILE):
        self.out = Path(out)
        self.overwrite = overwrite
        self.marker = marker
        self.tmp: Path | None = None

    # -- checks done before any work ------------------------------------------------
    def prepare(self) -> None:
        """Validate the destination, clean stale temporaries, create the temporary directory."""
        out = self.out
        if out.name in ("", ".", ".."):
            raise ValueError(f"output path {str(out)!r} must name a directory, e.g. data/kuka_kr_1m")
        parent = out.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except FileExistsError as err:
            raise NotADirectoryError(f"cannot create output folder {parent}: a file is in the way") from err
        except OSError as err:
            raise PermissionError(f"cannot create output folder {parent}: {err.strerror or err}") from err
        if not parent.is_dir():
            raise NotADirectoryError(f"output folder {parent} is not a directory")
        self.cleanup_stale()
        if out.exists() or out.is_symlink():
            if not self.overwrite:
                raise FileExistsError(f"{out} already exists; pass --overwrite (overwrite=True) to replace it")
            replaceable = (
                out.is_dir() and not out.is_symlink() and ((out / self.marker).is_file() or not any(out.iterdir()))
            )
            if not replaceable:
                raise FileExistsError(f"refusing to overwrite {out}: it is not a nik dataset directory")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise PermissionError(f"output folder {parent} is not writable")
        tmp = self._sibling("tmp")
        try:
            tmp.mkdir()
        except OSError as err:
            raise PermissionError(f"cannot write in output folder {parent}: {err.strerror or err}") from err
        self.tmp = tmp

    def _sibling(self, kind: str) -> Path:
        return self.out.parent / f".{self.out.name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}"

    def _siblings(self, kind: str) -> Iterator[tuple[Path, int]]:
        prefix = f".{self.out.name}.{kind}-"
        try:
            entries = sorted(self.out.parent.iterdir())
        except OSError:
            return
        for p in entries:
            if not p.name.startswith(prefix):
                continue
            pid_text = p.name[len(prefix) :].split("-", 1)[0]
            if pid_text.isdigit():
                yield p, int(pid_text)

    def _delete(self, p: Path) -> None:
        """Rename ``p`` to a ``del`` name (never put back), then remove it."""
        doomed = self._sibling("del")
        try:
            os.rename(p, doomed)
        except OSError:
            return
        _remove(doomed)

    def cleanup_stale(self) -> list[Path]:
        """Tidy the siblings of ``out`` left by dead processes: put a whole old copy back where ``out`` is
        missing (class docstring), delete every other one. Returns the siblings removed."""
        removed = []
        for p, pid in self._siblings("del"):
            if not _pid_alive(pid):
                _remove(p)
                removed.append(p)
        for p, pid in self._siblings("old"):
            if _pid_alive(pid):
                continue
            if not (self.out.exists() or self.out.is_symlink()) and is_whole(p):
                os.rename(p, self.out)  # an overwrite died between its two renames: put the old one back
                _fsync_dir(self.out.parent)
            else:
                self._delete(p)
                removed.append(p)
        for p, pid in self._siblings("tmp"):
            if not _pid_alive(pid):
                self._delete(p)
                removed.append(p)
        return removed

    # -- commit / abort ---------------------------------------------------------------
    def commit(self) -> Path:
        assert self.tmp is not None
        _fsync_dir(self.tmp)
        out = self.out
        old = None
        if out.exists() or out.is_symlink():
            if not self.overwrite:  # appeared while we were writing
                raise FileExistsError(
                    f"{out} was created by someone else while this run was writing; pass "
                    "--overwrite (overwrite=True) to replace it"
                )
            old = self._sibling("old")
            os.rename(out, old)
        os.rename(self.tmp, out)
        _fsync_dir(out.parent)
        self.tmp = None
        if old is not None:
            self._delete(old)
        return out

    def abort(self) -> None:
        if self.tmp is not None:
            _remove(self.tmp)
            self.tmp = None

    def __enter__(self) -> Path:
        if self.tmp is None:
            self.prepare()
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self.commit()
            except BaseException:
                self.abort()
                raise
        else:
            self.abort()


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        try:
            p.unlink()
        except OSError:
            pass


def is_whole(path: str | Path) -> bool:
    """Whether the directory ``path`` is a whole nik dataset (or shard): its ``meta.json`` reads and every array
    file it lists is there with its recorded size and SHA-256 (one read of each file)."""
    path = Path(path)
    if path.is_symlink() or not path.is_dir():
        return False
    try:
        meta = read_meta(path)
        files = meta["files"]
        if not isinstance(files, dict) or not files:
            return False
        for fname, info in files.items():
            fpath = path / fname
            if Path(fname).name != fname or not fpath.is_file():
                return False
            if "bytes" in info and fpath.stat().st_size != info["bytes"]:
                return False
            if sha256_file(fpath) != info["sha256"]:
                return False
    except (DatasetError, OSError, KeyError, TypeError, AttributeError):
        return False
    return True


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_meta(directory: Path, meta: dict) -> None:
    path = Path(directory) / META_FILE
    text = json.dumps(meta, indent=1)
    # innermost lists of numbers on one line: G, limits and ranges stay readable
    text = re.sub(
        r"\[\s+([-+0-9.eE,\s]+?)\s+\]", lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text
    )
    with open(path, "w") as f:
        f.write(text + "\n")
        f.flush()
        os.fsync(f.fileno())


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------
class IKDataset:
    """A loaded dataset (or one split of it).

    Attributes:
        q: (N, dof) joint vectors, radians (a read-only memory-mapped tensor by default).
        pose: (N, 4, 4) tool poses in the base frame, metres, same dtype as ``q``.
        branch: (N,) uint8 IK branch labels 0..7, or None for arms without a classifier.
        meta: the dataset's metadata (``meta.json``), a dict.
        splits: ``{"train": (start, stop), "val": ..., "test": ...}`` contiguous row ranges.
        path: the dataset directory.
        name: ``None`` for the whole dataset, else the split name.

    ``len(ds)`` is N; ``ds.split("train")`` (or ``ds.train``, ``ds.val``, ``ds.test``) is a
    zero-copy view; ``ds[i]`` gives ``(q[i], pose[i])``. The tensors share memory with the
    read-only memory map: copy (``.clone()``) before writing into them.
    """

    def __init__(
        self,
        q: torch.Tensor,
        pose: torch.Tensor,
        branch: torch.Tensor | None,
        meta: dict,
        path: Path,
        *,
        name: str | None = None,
        offset: int = 0,
    ):
        self.q = q
        self.pose = pose
        self.branch = branch
        self.meta = meta
        self.path = path
        self.name = name
        self.offset = offset  # row of this view in the whole dataset

    @property
    def splits(self) -> dict[str, tuple[int, int]]:
        return {k: (int(v[0]), int(v[1])) for k, v in self.meta["splits"].items()}

    @property
    def dof(self) -> int:
        return int(self.q.shape[-1])

    @property
    def robot(self):
        """The :class:`nik.Robot` the dataset was generated for, rebuilt from its stored definition."""
        from nik.robots import Robot

        return Robot.from_definition(self.meta["robot"]["definition"])

    def split(self, name: str) -> IKDataset:
        """The rows of split ``name`` (``train``, ``val`` or ``test``) as a zero-copy view."""
        if self.name is not None:
            raise ValueError(f"split({name!r}) called on split {self.name!r}; call it on the whole dataset")
        if name not in self.meta["splits"]:
            raise KeyError(f"no split {name!r}; this dataset has {sorted(self.meta['splits'])}")
        a, b = self.splits[name]
        return IKDataset(
            self.q[a:b],
            self.pose[a:b],
            None if self.branch is None else self.branch[a:b],
            self.meta,
            self.path,
            name=name,
            offset=a,
        )

    def indices(self, name: str) -> torch.Tensor:
        """``(n_split,)`` int64 row indices of split ``name`` in the whole dataset."""
        a, b = self.splits[name]
        return torch.arange(a, b, dtype=torch.int64)

    @property
    def train(self) -> IKDataset:
        return self.split("train")

    @property
    def val(self) -> IKDataset:
        return self.split("val")

    @property
    def test(self) -> IKDataset:
        return self.split("test")

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def __getitem__(self, i):
        return self.q[i], self.pose[i]

    def __repr__(self) -> str:
        part = "" if self.name is None else f", split={self.name!r}"
        return (
            f"IKDataset(path={str(self.path)!r}, robot={self.meta['robot']['name']!r}, n={len(self)}, "
            f"dtype={self.meta['dtype']}{part})"
        )


def read_meta(path: str | Path) -> dict:
    """The ``meta.json`` of a dataset directory; DatasetError if missing or malformed."""
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"dataset not found: {path}")
    if not path.is_dir():
        raise DatasetError(f"{path} is not a dataset directory (expected a folder holding {META_FILE} and .npy files)")
    mfile = path / META_FILE
    if not mfile.is_file():
        raise DatasetError(f"{path}: no {META_FILE}; not a nik dataset (or its write was interrupted)")
    try:
        meta = json.loads(mfile.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DatasetError(f"{mfile}: unreadable metadata ({err})") from err
    for key in ("format", "n", "dof", "dtype", "robot", "splits", "files"):
        if not isinstance(meta, dict) or key not in meta:
            raise DatasetError(f"{mfile}: metadata lacks field {key!r}")
    if meta["format"].get("version") != FORMAT_VERSION:
        raise DatasetError(
            f"{path}: dataset format version {meta['format'].get('version')} is not supported "
            f"(this nik reads version {FORMAT_VERSION})"
        )
    return meta


def _open_array(path: Path, fname: str, meta: dict, expected_shape: tuple, *, verify: bool) -> np.ndarray:
    fpath = path / fname
    info = meta["files"].get(fname)
    if info is None:
        raise DatasetError(f"{path}: {fname} is not listed in {META_FILE}")
    if not fpath.is_file():
        raise DatasetError(f"{fpath}: file missing")
    size = fpath.stat().st_size
    if "bytes" in info and size != info["bytes"]:
        raise DatasetError(f"{fpath}: size {size} bytes, expected {info['bytes']} (truncated or altered file)")
    if verify:
        digest = sha256_file(fpath)
        if digest != info["sha256"]:
            raise DatasetError(
                f"{fpath}: SHA-256 checksum mismatch (file altered or corrupt); "
                f"expected {info['sha256'][:16]}..., got {digest[:16]}..."
            )
    try:
        arr = np.load(fpath, mmap_mode="r", allow_pickle=False)
    except (ValueError, OSError) as err:
        raise DatasetError(f"{fpath}: not a readable .npy array ({err})") from err
    if arr.shape != expected_shape:
        raise DatasetError(f"{fpath}: shape {arr.shape}, expected {expected_shape}")
    return arr


def _as_tensor(arr: np.ndarray) -> torch.Tensor:
    import warnings

    with warnings.catch_warnings():  # read-only memory map: torch warns that it is not writable
        warnings.simplefilter("ignore", UserWarning)
        return torch.from_numpy(arr)


def load_dataset(path: str | Path, *, robot=None, verify: bool = True, mmap: bool = True) -> IKDataset:
    """Open a dataset written by :func:`nik.data.generate_dataset`.

    Args:
        path: the dataset directory (``data/NAME``).
        robot: optional robot (a :class:`nik.Robot`, a built-in name or a robot file); if given,
            its definition hash must equal the dataset's, else :class:`nik.DatasetError` naming both.
        verify: check the SHA-256 of every array file (one sequential read of each; about
            1 s per GB). With ``verify=False`` only the file sizes are checked.
        mmap: map the arrays (lazy, read-only); ``False`` reads them into memory.

    Returns:
        :class:`IKDataset` with ``q: (N, dof)``, ``pose: (N, 4, 4)``, ``branch: (N,)`` or None,
        ``meta`` and the train/val/test splits.

    Where ``path`` is missing but an overwrite killed between its two renames left the old copy aside, that copy
    is put back first when whole (:meth:`AtomicDirectory.cleanup_stale`).

    Raises:
        DatasetError: missing or malformed directory, truncated or altered file, robot mismatch.
    """
    path = Path(path)
    if not path.exists() and path.name not in ("", ".", ".."):
        try:  # an overwrite killed between its two renames left the old copy aside: it comes back if whole
            AtomicDirectory(path).cleanup_stale()
        except OSError:
            pass
    meta = read_meta(path)
    if "shard" in meta:
        sh = meta["shard"]
        raise DatasetError(
            f"{path} is shard {sh['index']}/{sh['count']} of a dataset, not a dataset; join all "
            f"{sh['count']} shards with: nik data merge OUT SHARD_DIR..."
        )
    if robot is not None:
        from nik.robots import load_robot

        robot = load_robot(robot)
        want = meta["robot"].get("definition_hash")
        if robot.definition_hash != want:
            made = (meta["robot"].get("definition") or {}).get("end_link")
            tool = (
                f"; it was made with tool link {made!r}, this robot's is {robot.end_link!r} (--end-link)"
                if made != robot.end_link
                else ""
            )
            raise DatasetError(
                f"{path} was generated for robot {meta['robot'].get('name')!r} (definition {want}), "
                f"not for robot {robot.name!r} (definition {robot.definition_hash}){tool}"
            )
    n, dof = int(meta["n"]), int(meta["dof"])
    q = _open_array(path, "q.npy", meta, (n, dof), verify=verify)
    pose = _open_array(path, "pose.npy", meta, (n, 4, 4), verify=verify)
    branch = None
    if "branch.npy" in meta["files"]:
        branch = _open_array(path, "branch.npy", meta, (n,), verify=verify)
    if not mmap:
        q, pose = np.array(q), np.array(pose)
        branch = None if branch is None else np.array(branch)
    return IKDataset(_as_tensor(q), _as_tensor(pose), None if branch is None else _as_tensor(branch), meta, path)
