"""Lightning data module over a dataset written by :func:`nik.data.generate_dataset`."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import torch
from torch.utils.data import DataLoader, Dataset, Sampler

__all__ = ["IKDataModule", "TensorBatches", "IndexBatches"]

_DTYPES = {"float32": torch.float32, "float64": torch.float64}


class TensorBatches(Dataset):
    """Tensors indexed by a whole batch of rows at once: ``ds[idx]`` with ``idx`` an index tensor or a slice."""

    def __init__(self, *tensors: torch.Tensor):
        self.tensors = tensors

    def __len__(self) -> int:
        return int(self.tensors[0].shape[0])

    def __getitem__(self, idx):
        if isinstance(idx, slice):
            return tuple(t[idx] for t in self.tensors)
        # index_select, not t[idx]: advanced indexing of a (N, 4, 4) tensor is ~1000x slower on CPU here
        return tuple(t.index_select(0, idx) for t in self.tensors)


class IndexBatches(Sampler):
    """Yields batches of row indices: index tensors of a fresh random permutation (``shuffle``), or
    contiguous slices. Shuffling draws from torch's global RNG (seeded by ``seed_everything``)."""

    def __init__(self, n: int, batch_size: int, *, shuffle: bool):
        self.n, self.batch_size, self.shuffle = n, batch_size, shuffle

    def __len__(self) -> int:
        return -(-self.n // self.batch_size)

    def __iter__(self):
        if self.shuffle and self.batch_size < self.n:
            yield from torch.randperm(self.n).split(self.batch_size)
        else:
            for i in range(0, self.n, self.batch_size):
                yield slice(i, min(i + self.batch_size, self.n))


class IKDataModule(L.LightningDataModule):
    """Train / val / test splits of a nik dataset as ``(pose (B, 4, 4), q (B, dof))`` batches.

    Args:
        path: the dataset directory (``data/NAME``, made by ``nik generate``).
        batch_size: training batch size; ``None`` gives the whole training split as one batch
            (full batch: paper C's BP and DE, L-BFGS), one optimisation step / DE generation per epoch.
        eval_batch_size: batch size of val/test; ``None``: the whole split at once.
        branch: keep only samples with this IK branch label (0..7; datasets of arms with a branch
            classifier, e.g. ``puma560``, ``kuka_kr``). A joint-space regression cannot average across
            branches; the pose loss does not need this.
        max_train: use only the first ``max_train`` training samples (``None``: all).
        dtype: ``float32`` or ``float64``.
        verify: check the dataset's checksums when opening it.

    After :meth:`setup`: ``robot`` (from the dataset's stored definition) and the splits
    ``train_data``/``val_data``/``test_data``: ``(pose, q)`` tensor pairs.
    """

    def __init__(
        self,
        path: str = "data/kuka_kr",
        batch_size: int | None = 1024,
        eval_batch_size: int | None = None,
        branch: int | None = None,
        max_train: int | None = None,
        dtype: str = "float32",
        verify: bool = True,
    ):
        super().__init__()
        if dtype not in _DTYPES:
            raise ValueError(f"data.dtype must be one of {sorted(_DTYPES)}, got {dtype!r}")
        if batch_size is not None and batch_size < 1:
            raise ValueError(f"data.batch_size must be >= 1 or null (full batch), got {batch_size}")
        self.path = Path(path)
        self.batch_size = batch_size
        self.eval_batch_size = eval_batch_size
        self.branch = branch
        self.max_train = max_train
        self.dtype = _DTYPES[dtype]
        self.verify = verify
        self.robot = None
        self.train_data = self.val_data = self.test_data = None

    def setup(self, stage: str | None = None) -> None:
        if self.robot is not None:
            return
        from nik.data import load_dataset

        ds = load_dataset(self.path, verify=self.verify, mmap=False)  # in RAM: random batches
        self.robot = ds.robot
        self.meta = ds.meta
        for name in ("train", "val", "test"):
            part = ds.split(name)
            pose, q = part.pose.to(self.dtype), part.q.to(self.dtype)
            if self.branch is not None:
                if part.branch is None:
                    raise ValueError(f"data.branch={self.branch} but dataset {self.path} has no branch labels")
                keep = part.branch.long() == int(self.branch)
                pose, q = pose[keep], q[keep]
            if name == "train" and self.max_train is not None:
                pose, q = pose[: self.max_train], q[: self.max_train]
            if pose.shape[0] == 0:
                raise ValueError(
                    f"dataset {self.path}: the {name} split is empty"
                    + (f" for branch {self.branch}" if self.branch is not None else "")
                )
            setattr(self, f"{name}_data", (pose.contiguous(), q.contiguous()))

    def describe(self) -> dict:
        """Plain data naming the training data (recorded in checkpoints and exported networks): the dataset's
        path, size, seed, sampler and the SHA-256 of its files, and the filters applied here."""
        meta = getattr(self, "meta", None) or {}
        return {
            "source": "dataset",
            "path": str(self.path),
            "n": meta.get("n"),
            "seed": meta.get("seed"),
            "sampler": meta.get("sampler"),
            "ranges": (meta.get("ranges") or {}).get("source"),
            "sha256": {k: v.get("sha256") for k, v in (meta.get("files") or {}).items()},
            "branch": self.branch,
            "max_train": self.max_train,
            "dtype": str(self.dtype).replace("torch.", ""),
        }

    def _loader(self, tensors, batch_size: int | None, shuffle: bool) -> DataLoader:
        data = TensorBatches(*tensors)
        n = len(data)
        bs = n if batch_size is None else min(batch_size, n)
        # whole batches of indices: one gather (or slice) per batch, no per-row collate
        return DataLoader(data, batch_size=None, sampler=IndexBatches(n, bs, shuffle=shuffle))

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train_data, self.batch_size, shuffle=True)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_data, self.eval_batch_size, shuffle=False)

    def test_dataloader(self) -> DataLoader:
        return self._loader(self.test_data, self.eval_batch_size, shuffle=False)
