"""Lightning module for the multi-solution networks (:mod:`nik.nets.multi`) and a training-curve plot.

:class:`MultiSolutionIK` trains a :class:`nik.nets.multi.BranchHeadsIKNet` (``kind: branch_heads``; the legacy
:class:`nik.nets.multi.BranchIKNet` is ``kind: branch``) or a :class:`nik.nets.multi.MultiHypIKNet`
(``kind: multihead``) with Adam and a cosine learning rate
(time- or step-based, as :class:`nik.learn.modules.GradientIK`), in two phases of one run:

1. **joint space** until ``pose_start`` of the run: a branch net regresses the ``(sin, cos)``
   encoding of the sample's joints on the hypothesis of its branch label (computed from the joints); the
   multi-head net uses a relaxed winner-takes-all loss, ``(1 - wta_eps) min_k l_k + wta_eps mean_k l_k``
   over its K heads (the best head learns the sample, the others are pulled only a little, so no
   head stays unused);
2. **pose space (FK)** from then on: the same, with ``l`` the pose loss of the reached pose
   (``|p - p*|^2 / L^2 + rot_weight |R - R*|_F^2 / 2``, :func:`nik.learn.losses.pose_loss` per sample),
   plus ``joint_weight`` times the joint loss (keeps a branch net on its branch).

Validation logs ``val_loss``, ``val_pos_mm`` / ``val_rot_deg`` (medians of the best hypothesis by FK,
and, for a branch net, ``val_label_pos_mm`` / ``val_label_rot_deg`` of the labelled branch) and their p95,
with ``sync_dist=True`` so DDP runs agree. Checkpoints carry ``checkpoint["nik"]`` (robot definition,
hash, ``net`` = the network's plain-data config with its ``kind``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

import lightning as L
import torch

from nik.learn.modules import GradientIK, GradientIKCfg
from nik.nets.multi import BranchHeadsIKNet, BranchIKNet, MultiHypIKNet, hypothesis_pose_error
from nik.tolerances import score

#: Kinds trained on the hypothesis of each sample's branch label (the others: relaxed winner-takes-all).
BRANCH_KINDS = ("branch_heads", "branch")

__all__ = [
    "MultiSolutionIK",
    "MultiSolutionCfg",
    "CurvePlot",
    "FinalCheckpoint",
    "pose_loss_per_sample",
    "plot_history",
]


def pose_loss_per_sample(q: torch.Tensor, T: torch.Tensor, robot, *, length_scale, rot_weight: float = 1.0):
    """Pose loss of joints ``q: (..., B, dof)`` against ``T: (B, 4, 4)``, per sample: ``(..., B)``."""
    That = robot.fk(q)
    T = T.to(That.dtype)
    pos = (That[..., :3, 3] - T[..., :3, 3]).square().sum(-1)
    rot = 0.5 * (That[..., :3, :3] - T[..., :3, :3]).square().sum((-1, -2))
    return pos / (length_scale**2) + rot_weight * rot


#: The :class:`GradientIK` settings :class:`MultiSolutionIK` fixes (recorded in its ``hparams``; given back as keywords,
#: e.g. by Lightning loading a checkpoint, they must have these values).
FIXED = {
    "optimizer": "adam",
    "momentum": 0.0,
    "representation": "rot6d",
    "output": "sincos",
    "loss": "both",
    "pose_weight": 1.0,
    "lbfgs_max_iter": 20,
    "lbfgs_history": 50,
}


@dataclass
class MultiSolutionCfg:
    """Settings of :class:`MultiSolutionIK` (documented there); each is also a keyword of the module."""

    kind: str = "branch_heads"
    hidden: tuple[int, ...] = (512, 512, 512)
    activation: str = "silu"
    heads: int = 8
    pose_start: float = 0.5
    joint_weight: float = 0.01
    wta_eps: float = 0.05
    rot_weight: float = 1.0
    lr: float = 1e-3
    schedule: str = "cosine"
    min_lr_ratio: float = 0.01
    weight_decay: float = 0.0
    eval_samples: int = 20000


class MultiSolutionIK(GradientIK):
    """Two-phase training of a multi-solution network (module docstring).

    Settings: one :class:`MultiSolutionCfg` as ``cfg`` (keywords override its fields) or each as a keyword.

    Args:
        kind: ``branch_heads`` (arms with branch labels; one pass), ``multihead``, or the legacy ``branch``.
        hidden: hidden layer sizes.
        activation: one of :data:`nik.nets.ACTIVATIONS`.
        heads: K of the multi-head net (ignored for ``branch``: always 8).
        pose_start: fraction of the run (steps or ``trainer.max_time``) after which the pose loss is used.
        joint_weight: weight of the joint loss in the pose phase.
        wta_eps: share of the mean over heads in the relaxed winner-takes-all loss (multi-head).
        rot_weight: rotation weight of the pose loss.
        lr, schedule, min_lr_ratio, weight_decay: Adam and its schedule (see :class:`GradientIK`).
        eval_samples: validation uses the first this many samples of each validation batch.
    """

    def __init__(self, cfg: MultiSolutionCfg | None = None, **kwargs):
        clash = sorted(k for k, v in kwargs.items() if k in FIXED and v != FIXED[k])
        if clash:
            raise ValueError(f"MultiSolutionIK fixes {', '.join(f'model.{k}={FIXED[k]!r}' for k in clash)}")
        kwargs = {k: v for k, v in kwargs.items() if k not in FIXED}
        cfg = MultiSolutionCfg(**kwargs) if cfg is None else replace(cfg, **kwargs)
        if cfg.kind not in (*BRANCH_KINDS, "multihead"):
            raise ValueError(f"model.kind must be branch_heads, multihead or branch, got {cfg.kind!r}")
        if not 0.0 <= cfg.pose_start <= 1.0:
            raise ValueError(f"model.pose_start must be in [0, 1], got {cfg.pose_start}")
        gradient = {k: v for k, v in asdict(cfg).items() if k in GradientIKCfg.__dataclass_fields__}
        super().__init__(GradientIKCfg(**{**gradient, **FIXED}))
        # the fixed choices GradientIK reads from hparams are recorded beside the settings
        self.record_settings(cfg, fixed=FIXED)
        self._total_steps = None

    # -- network -----------------------------------------------------------------
    def build(self, robot):
        h = self.hparams
        if h.kind == "branch_heads":
            return BranchHeadsIKNet(robot, hidden=h.hidden, activation=h.activation)
        if h.kind == "branch":
            return BranchIKNet(robot, hidden=h.hidden, activation=h.activation)
        return MultiHypIKNet(robot, hidden=h.hidden, activation=h.activation, heads=h.heads)

    def setup(self, stage: str) -> None:
        if self.net is not None:
            return
        dm = self.ik_datamodule()
        pose, _ = dm.train_data
        self.net = self.build(dm.robot).fit_normalisation(pose).to(dtype=pose.dtype)

    # -- objective ---------------------------------------------------------------
    def in_pose_phase(self) -> bool:
        if self.trainer is None or self._total_steps is None:
            return False
        return self._progress() >= self.hparams.pose_start

    def per_sample_losses(self, T: torch.Tensor, q: torch.Tensor, pose: bool) -> torch.Tensor:
        """Loss of each sample (branch: ``(B,)``) or each sample and head (multi-head: ``(B, K)``)."""
        h, net = self.hparams, self.net
        target = net.encode(q)
        labelled = h.kind in BRANCH_KINDS
        if labelled:
            y = net.raw_branch(T, net.labels(q))
            loss = (y - target).square().sum(-1)
        else:
            y = net.raw_hypotheses(T)
            loss = (y - target[:, None]).square().sum(-1)
        if pose:
            pl = pose_loss_per_sample(
                net.decode(y) if labelled else net.decode(y).transpose(0, 1),
                T,
                net.robot,
                length_scale=net.length_scale,
                rot_weight=h.rot_weight,
            )
            pl = pl if labelled else pl.transpose(0, 1)
            loss = pl + h.joint_weight * loss
        return loss

    def reduce(self, loss: torch.Tensor) -> torch.Tensor:
        if loss.ndim == 1:
            return loss.mean()
        eps = self.hparams.wta_eps
        return ((1 - eps) * loss.amin(-1) + eps * loss.mean(-1)).mean()

    def batch_loss(self, batch) -> torch.Tensor:
        T, q = batch
        loss = self.reduce(self.per_sample_losses(T, q, self.in_pose_phase()))
        self.loss_evals += 1
        self.sample_evals += T.shape[0]
        return loss

    def training_step(self, batch, batch_idx):
        loss = self.batch_loss(batch)
        self.log("train_loss", loss, on_step=False, on_epoch=True, batch_size=batch[0].shape[0], sync_dist=True)
        self.log("pose_phase", float(self.in_pose_phase()), on_step=False, on_epoch=True, sync_dist=True)
        return loss

    # -- metrics -----------------------------------------------------------------
    @torch.no_grad()
    def metrics(self, T: torch.Tensor, q: torch.Tensor) -> dict[str, float]:
        """Errors (mm, degrees) of the best hypothesis and, for a branch net, of the labelled branch."""
        net = self.net
        hyp = net.hypotheses(T).double()
        pos, rot = hypothesis_pose_error(net.robot, T.double(), hyp)
        best = score(pos, rot).argmin(-1, keepdim=True)
        bpos, brot = pos.gather(1, best)[:, 0] * 1e3, torch.rad2deg(rot.gather(1, best)[:, 0])
        out = {
            "pos_mm": float(bpos.median()),
            "rot_deg": float(brot.median()),
            "pos_mm_p95": float(torch.quantile(bpos, 0.95)),
            "rot_deg_p95": float(torch.quantile(brot, 0.95)),
        }
        if isinstance(net, BranchIKNet | BranchHeadsIKNet):
            lab = net.labels(q)[:, None]
            spos, srot = pos.gather(1, lab)[:, 0] * 1e3, torch.rad2deg(rot.gather(1, lab)[:, 0])
            out["label_pos_mm"] = float(spos.median())
            out["label_rot_deg"] = float(srot.median())
        return out

    def _eval_step(self, batch, prefix: str) -> None:
        T, q = batch
        n = min(T.shape[0], int(self.hparams.eval_samples))
        T, q = T[:n], q[:n]
        with torch.no_grad():
            loss = self.reduce(self.per_sample_losses(T, q, pose=True))
        values = {"loss": float(loss), **self.metrics(T, q)}
        for k, v in values.items():
            self.log(f"{prefix}_{k}", v, batch_size=n, prog_bar=k in ("loss", "pos_mm", "rot_deg"), sync_dist=True)
        if prefix == "val":
            self.log("wall_s", self.wall_s, on_step=False, on_epoch=True, sync_dist=True)
            self.log("sample_evals", float(self.sample_evals), on_step=False, on_epoch=True, sync_dist=True)

    def on_save_checkpoint(self, checkpoint: dict) -> None:
        super().on_save_checkpoint(checkpoint)
        checkpoint["nik"]["net"] = self.net.config()
        checkpoint["nik"]["hparams"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.hparams.items()}


# ---------------------------------------------------------------------------
# Training curve
# ---------------------------------------------------------------------------
def plot_history(rows: list[dict], path: str | Path, *, title: str = "") -> Path:
    """Plot validation position / rotation medians (and the loss) against wall-clock time to a PNG.

    ``rows``: dicts with ``wall_s`` and any of ``val_pos_mm``, ``val_rot_deg``, ``val_loss`` (as written by
    :class:`nik.learn.callbacks.History`). matplotlib is imported here. Written to a temp name, then renamed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = [r for r in rows if "wall_s" in r]
    t = [r["wall_s"] / 60 for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for key, label in (("val_pos_mm", "position median (mm)"), ("val_pos_mm_p95", "position p95 (mm)")):
        axes[0].plot(t, [r.get(key, float("nan")) for r in rows], label=label)
    for key, label in (("val_rot_deg", "rotation median (deg)"), ("val_rot_deg_p95", "rotation p95 (deg)")):
        axes[1].plot(t, [r.get(key, float("nan")) for r in rows], label=label)
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("wall-clock time (min)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(title or "validation error of the best hypothesis")
    fig.tight_layout()
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    tmp.replace(path)
    return path


class CurvePlot(L.Callback):
    """At the end of the fit, plots the rows of the run's :class:`nik.learn.callbacks.History` callback
    to ``<trainer.default_root_dir>/<filename>``; also after every ``every`` validations (progress)."""

    def __init__(self, filename: str = "curve.png", every: int = 5):
        super().__init__()
        self.filename = filename
        self.every = every
        self._n = 0

    def _rows(self, trainer) -> list[dict]:
        hist = next((cb for cb in trainer.callbacks if type(cb).__name__ == "History"), None)
        return [] if hist is None else hist.rows

    def _plot(self, trainer, pl_module) -> None:
        rows = self._rows(trainer)
        if rows and trainer.is_global_zero:
            name = pl_module.net.robot.name if pl_module.net is not None else ""
            plot_history(rows, Path(trainer.default_root_dir) / self.filename, title=f"{name}: validation error")

    def on_validation_end(self, trainer, pl_module) -> None:
        if trainer.sanity_checking:
            return
        self._n += 1
        if self.every and self._n % self.every == 0:
            self._plot(trainer, pl_module)

    def on_fit_end(self, trainer, pl_module) -> None:
        self._plot(trainer, pl_module)


class FinalCheckpoint(L.Callback):
    """Saves the network as it is when the fit ends (also when ``trainer.max_time`` stops it inside an epoch,
    after the last epoch-end checkpoint) to ``<trainer.default_root_dir>/<filename>``."""

    def __init__(self, filename: str = "final.ckpt"):
        super().__init__()
        self.filename = filename

    def on_fit_end(self, trainer, pl_module) -> None:
        if trainer.fast_dev_run:
            return
        # full state, like every checkpoint nik writes (weights_only said, so Lightning has nothing to note)
        trainer.save_checkpoint(Path(trainer.default_root_dir) / self.filename, weights_only=False)
