"""Training data drawn fresh from the forward kinematics at every step, instead of read from a fixed file.

:class:`FKStreamDataModule` gives the same ``(pose (B, 4, 4), q (B, dof))`` batches as
:class:`nik.learn.datamodule.IKDataModule`, but every training batch is new: ``q`` uniform inside the
joint limits (a seeded ``torch.Generator``), ``pose = robot.fk(q)`` in float64, then cast to ``dtype``.
The network never sees a sample twice, so there is nothing to overfit and nothing to store.

Why (``benchmarks/learned.py``, stream section, one CPU thread): a batch of 1,024 fresh samples costs 0.9 ms
(2.6 ms with the branch labels of a UR-type arm), one training step of the 4 x 256 network on it 24-30 ms:
streaming costs 3 % of the step (11 % with labels), while a fixed file of a million samples would be seen
40 times over in the 45 million samples of a 24-minute run. Validation uses a fixed seeded set (``val_n``
samples), and a fixed seeded sample of ``norm_n`` poses sets the network's input normalisation
(``train_data``, as the file module has it).

An "epoch" is ``steps_per_epoch`` batches (validation and the resumable ``last.ckpt`` follow each one).
The generator of epoch ``e`` is seeded from ``(seed, e)``, so a run resumed at epoch ``e`` draws what the
uninterrupted run would have drawn.
"""

from __future__ import annotations

import lightning as L
import torch
from torch.utils.data import DataLoader, IterableDataset

from nik.robots import Robot

__all__ = ["FKStream", "FKStreamDataModule"]

_DTYPES = {"float32": torch.float32, "float64": torch.float64}


def fk_samples(
    robot: Robot, n: int, generator: torch.Generator, dtype: torch.dtype
) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` uniform joint vectors inside the limits and their poses: ``(pose (n, 4, 4), q (n, dof))`` in ``dtype``
    (FK in float64)."""
    q = robot.sample(n, generator=generator, dtype=torch.float64)
    return robot.fk(q, check=False).to(dtype), q.to(dtype)


class FKStream(IterableDataset):
    """``steps`` batches of ``batch_size`` fresh FK samples per iteration; ``epoch()`` names the epoch (seed)."""

    def __init__(self, robot: Robot, batch_size: int, steps: int, seed: int, dtype: torch.dtype, epoch):
        super().__init__()
        self.robot, self.batch_size, self.steps, self.seed, self.dtype, self.epoch = (
            robot,
            batch_size,
            steps,
            seed,
            dtype,
            epoch,
        )

    def __len__(self) -> int:
        return self.steps

    def __iter__(self):
        g = torch.Generator().manual_seed(int(self.seed) * 1_000_003 + 7919 * int(self.epoch()) + 1)
        for _ in range(self.steps):
            yield fk_samples(self.robot, self.batch_size, g, self.dtype)


class FKStreamDataModule(L.LightningDataModule):
    """Fresh FK samples every training step (module docstring).

    Args:
        robot: the arm (a :class:`nik.Robot`).
        batch_size: samples per training step.
        steps_per_epoch: training steps between two validations.
        val_n: size of the fixed validation set.
        norm_n: size of the fixed sample that sets the input normalisation (``train_data``).
        seed: seeds the validation set, the normalisation sample and every training batch.
        dtype: ``float32`` or ``float64``.
    """

    def __init__(
        self,
        robot: Robot,
        batch_size: int = 1024,
        steps_per_epoch: int = 200,
        val_n: int = 5000,
        norm_n: int = 100_000,
        seed: int = 0,
        dtype: str = "float32",
    ):
        super().__init__()
        if dtype not in _DTYPES:
            raise ValueError(f"dtype must be one of {sorted(_DTYPES)}, got {dtype!r}")
        for name, value in (("batch_size", batch_size), ("steps_per_epoch", steps_per_epoch), ("val_n", val_n)):
            if int(value) < 1:
                raise ValueError(f"{name} must be >= 1, got {value}")
        self.robot = robot
        self.batch_size, self.steps_per_epoch = int(batch_size), int(steps_per_epoch)
        self.val_n, self.norm_n, self.seed = int(val_n), int(norm_n), int(seed)
        self.dtype = _DTYPES[dtype]
        self.train_data = self.val_data = None

    def setup(self, stage: str | None = None) -> None:
        if self.val_data is not None:
            return
        g = torch.Generator().manual_seed(self.seed)
        self.val_data = fk_samples(self.robot, self.val_n, g, self.dtype)
        self.train_data = fk_samples(self.robot, max(self.norm_n, 2), g, self.dtype)
        self.test_data = self.val_data

    def _epoch(self) -> int:
        trainer = getattr(self, "trainer", None)
        return int(trainer.current_epoch) if trainer is not None else 0

    def train_dataloader(self) -> DataLoader:
        stream = FKStream(self.robot, self.batch_size, self.steps_per_epoch, self.seed, self.dtype, self._epoch)
        return DataLoader(stream, batch_size=None)

    def _fixed(self, tensors) -> DataLoader:
        return DataLoader([tensors], batch_size=None)

    def val_dataloader(self) -> DataLoader:
        return self._fixed(self.val_data)

    def test_dataloader(self) -> DataLoader:
        return self._fixed(self.val_data)

    def describe(self) -> dict:
        """Plain data naming the training data (recorded in checkpoints and exported networks)."""
        return {
            "source": "fk_stream",
            "sampler": "uniform inside the joint limits, fresh every step (torch.Generator seeded per epoch)",
            "seed": self.seed,
            "batch_size": self.batch_size,
            "steps_per_epoch": self.steps_per_epoch,
            "val_n": self.val_n,
            "norm_n": self.norm_n,
            "fk": "float64",
            "dtype": str(self.dtype).replace("torch.", ""),
        }
