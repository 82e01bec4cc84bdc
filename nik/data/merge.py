"""Join dataset shards (``nik generate --shard I/N``) into one dataset (``nik data merge``).

Each shard is a directory like a dataset whose ``meta.json`` has a ``shard`` entry
``{"index": I, "count": N, "rows": [start, stop]}`` and otherwise describes the whole dataset
(``n``, splits, seed, robot, ranges, ...). Merging checks that the shards are the ``N`` parts of one
dataset (same description, every index once, rows contiguous from 0 to ``n``), verifies every
shard's checksums, and streams their rows into new ``.npy`` files under a temporary name that is
renamed into place when complete. The arrays, checksums and metadata equal those of the same
``nik generate`` run without ``--shard``; only ``created`` is the time of the merge.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np

from nik.data.storage import ARRAY_FILES, AtomicDirectory, NpyStreamWriter, _open_array, read_meta, write_meta
from nik.errors import DatasetError

__all__ = ["merge_shards"]

#: Metadata that differs between the shards of one dataset (everything else must be equal).
_PER_SHARD = ("shard", "files", "created", "branch", "fk", "nik_version", "torch_version")
_ROWS_PER_COPY = 1 << 18


def _shard_meta(path: Path) -> dict:
    meta = read_meta(path)
    if "shard" not in meta:
        raise DatasetError(f"{path} is a whole dataset, not a shard (made by nik generate --shard I/N)")
    return meta


def _describe(meta: dict) -> dict:
    """What must agree between shards of one dataset."""
    d = {k: v for k, v in meta.items() if k not in _PER_SHARD}
    if meta.get("branch") is not None:
        d["branch"] = {k: v for k, v in meta["branch"].items() if k not in ("counts", "candidates")}
    d["fk"] = {k: v for k, v in meta["fk"].items() if k != "device"}
    return d


def _joined(values: list[str]) -> str:
    unique = list(dict.fromkeys(values))
    return unique[0] if len(unique) == 1 else ", ".join(unique)


def merge_shards(
    out: str | Path,
    shards: list[str | Path],
    *,
    overwrite: bool = False,
    verify: bool = True,
    fsync: bool = True,
) -> Path:
    """Join the shard directories ``shards`` (any order) into the dataset directory ``out``.

    Args:
        out: the dataset directory to write.
        shards: all ``N`` shards of one dataset, each written by ``generate_dataset(..., shard=(i, N))``.
        overwrite: replace an existing dataset at ``out`` (only once the new one is complete).
        verify: check every shard file's SHA-256 before copying.
        fsync: flush the files to disk before the final rename.

    Returns:
        ``out`` as a :class:`pathlib.Path`.

    Raises:
        DatasetError: ``out`` is (or holds) one of the shards, a directory is not a shard, shards of different
            datasets, a missing or duplicate shard index, rows that do not tile ``[0, n)``, a corrupt shard file.
        FileExistsError: ``out`` exists and ``overwrite`` is False.
    """
    paths = [Path(p) for p in shards]
    if not paths:
        raise ValueError("merge: no shard directories given")
    target = Path(out).resolve()
    for p in paths:
        where = p.resolve()
        if where == target:
            raise DatasetError(
                f"merge: the output {out} is one of the inputs ({p}); write the merged dataset elsewhere"
            )
        if target in where.parents:
            raise DatasetError(f"merge: the output {out} holds input {p}; write the merged dataset elsewhere")
    metas = [_shard_meta(p) for p in paths]
    first, first_path = metas[0], paths[0]
    count = int(first["shard"]["count"])
    want = _describe(first)
    for p, m in zip(paths[1:], metas[1:], strict=True):
        if int(m["shard"]["count"]) != count:
            raise DatasetError(f"{p} is a shard of {m['shard']['count']}, {first_path} a shard of {count}")
        got = _describe(m)
        if got != want:
            keys = sorted(k for k in set(got) | set(want) if got.get(k) != want.get(k))
            raise DatasetError(
                f"{p} and {first_path} are shards of different datasets (they differ in {', '.join(keys)})"
            )
    by_index: dict[int, Path] = {}
    for p, m in zip(paths, metas, strict=True):
        i = int(m["shard"]["index"])
        if i in by_index:
            raise DatasetError(f"shard {i}/{count} given twice: {by_index[i]} and {p}")
        by_index[i] = p
    missing = sorted(set(range(count)) - set(by_index))
    if missing:
        raise DatasetError(
            f"shard(s) {', '.join(f'{i}/{count}' for i in missing)} missing: {len(by_index)} of {count} given"
        )
    order = [metas[paths.index(by_index[i])] for i in range(count)]
    n, dof = int(first["n"]), int(first["dof"])
    row = 0
    for i, m in enumerate(order):
        a, b = (int(v) for v in m["shard"]["rows"])
        if a != row or b < a:
            raise DatasetError(f"shard {i}/{count} ({by_index[i]}) holds rows [{a}, {b}), expected rows from {row}")
        row = b
    if row != n:
        raise DatasetError(f"the shards hold rows [0, {row}) of a dataset of n = {n}")

    files = [f for f in ARRAY_FILES if f in first["files"]]
    arrays = []  # per shard: {file: memory-mapped array}
    for i, m in enumerate(order):
        a, b = m["shard"]["rows"]
        shapes = {"q.npy": (b - a, dof), "pose.npy": (b - a, 4, 4), "branch.npy": (b - a,)}
        arrays.append({f: _open_array(by_index[i], f, m, shapes[f], verify=verify) for f in files})

    atomic = AtomicDirectory(out, overwrite=overwrite)
    atomic.prepare()
    writers: list[NpyStreamWriter] = []
    try:
        entries = {}
        for f in files:
            ref = arrays[0][f]
            w = NpyStreamWriter(atomic.tmp / f, ref.dtype, (n, *ref.shape[1:]))
            writers.append(w)
            for part in arrays:
                arr = part[f]
                for s in range(0, arr.shape[0], _ROWS_PER_COPY):
                    w.write(np.asarray(arr[s : s + _ROWS_PER_COPY]))
            digest = w.close(fsync=fsync)
            entries[f] = {
                "sha256": digest,
                "bytes": w.path.stat().st_size,
                "shape": list(w.shape),
                "dtype": str(w.dtype),
            }

        meta = {k: v for k, v in first.items() if k != "shard"}
        if first.get("branch") is not None:
            meta["branch"] = dict(first["branch"])
            meta["branch"]["counts"] = np.sum([m["branch"]["counts"] for m in order], axis=0).tolist()
            meta["branch"]["candidates"] = int(sum(m["branch"]["candidates"] for m in order))
        meta["fk"] = dict(first["fk"], device=_joined([m["fk"]["device"] for m in order]))
        for key in ("nik_version", "torch_version"):
            meta[key] = _joined([str(m[key]) for m in order])
        meta["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        meta["files"] = entries
        write_meta(atomic.tmp, meta)
        return atomic.commit()
    except BaseException:
        for w in writers:
            w.abort()
        atomic.abort()
        raise
