"""``nik train ROBOT``: one command from a robot to a usable, checked network (the work behind the CLI).

:func:`train_network` runs the recipe of :class:`TrainCfg`:

1. **the robot**: a built-in name, a YAML file or a URDF (``end_link``);
2. **the network kind**, chosen from the arm (:func:`choose_kind`): where :mod:`nik.data.branches` labels
   the IK branches (PUMA-type and UR-type 6R arms) a :class:`~nik.nets.multi.BranchHeadsIKNet` (8 heads,
   head k = branch k, each head a well-posed regression); for every other arm (redundant 7-DOF arms
   included) a :class:`~nik.nets.multi.MultiHypIKNet` (K heads, relaxed winner-takes-all);
3. **the data**: fresh FK samples at every step (:class:`nik.learn.stream.FKStreamDataModule`; measured
   to cost a few per cent of a step, module docstring there), or a dataset folder (``data``);
4. **training** through Lightning with :class:`nik.learn.multi.MultiSolutionIK` (the module and two-phase
   loss of ``configs/train/<robot>.yaml``) within ``minutes`` of wall-clock time (the cosine learning rate
   follows the clock), a progress line after every validation, ``runs/<name>/last.ckpt`` after each one
   (``resume`` continues from it, the time budget counting the earlier part), ``history.csv`` and
   ``curve.png`` in ``runs/<name>/``;
5. **export** of the pair (:mod:`nik.nets.pair`, SHA-256 recorded) to ``out`` (default
   ``runs/<name>/<name>.safetensors``) with the command that ran, the data, its hash (:func:`data_sha256`; no
   path of the machine) and the counters; ``install`` copies it to the user folder, where ``IKSolver(robot)``
   finds it for this arm by definition hash (:mod:`nik.nets.registry`), and says how to get it
   (:mod:`nik.learn.usage`: on an arm with a closed form the closed form stays the default, and
   ``checkpoint=PATH`` uses the network);
6. **what pays** (:func:`nik.learn.report.record_use`, before the install): whether the network pays for single
   poses and for batches on this machine's CPU, timed on the seeded probes of :mod:`nik.ik.judge` (0.12-0.18 s of
   CPU) and written into the JSON, so that a solver loading the network uses it only for the call types where it
   pays without measuring again (:attr:`nik.IKSolver.network_use`);
   **a single-pose network where the main one does not pay for single poses**: the main network trains for
   ``1 - single_pose_share`` of the budget; where its record says it does not serve single poses (slower there: a
   4 x 256 forward pass can cost more than the LM iterations it saves; or not earning its place), a small
   network (:data:`SINGLE_POSE_HIDDEN`) trains for the rest, as ``<out>_one.safetensors`` beside it (run
   ``runs/<name>_one``, role ``single_pose``), gets its own record, and the main JSON names it; ``install`` installs
   both, and ``IKSolver(robot)`` then guesses with the small one on the CPU where it pays (:mod:`nik.ik.plan`;
   ``checkpoint=PATH`` of the main file uses the main network alone, as its record says). Where the main network
   pays for both, the rest of the budget is not spent. Measured on TIAGo's arm (example-robot-data,
   ``torso_lift_link`` -> ``arm_tool_link``): a 2-minute single-pose network, 1.35x faster single poses and 3.09x
   faster batches than no network, where the 10-minute main network made single poses 1.27x slower;
7. **evaluation** (:func:`nik.learn.report.network_report`): raw error, network + LM against no network on a batch
   and on single poses, and per call type what the solver uses with the probes' times with and without it.
"""

from __future__ import annotations

import logging
import sys
import warnings
from dataclasses import dataclass, field, replace
from datetime import timedelta
from pathlib import Path

import lightning as L
import torch

from nik.errors import DatasetError
from nik.learn.callbacks import History, StableLastCheckpoint
from nik.learn.multi import CurvePlot, MultiSolutionIK
from nik.learn.report import network_report, record_use
from nik.nets.pretrained import save
from nik.nets.registry import install
from nik.robots import Robot, load_robot

__all__ = [
    "DEFAULT_HIDDEN",
    "SINGLE_POSE_HIDDEN",
    "Progress",
    "TrainCfg",
    "TrainResult",
    "choose_kind",
    "train_network",
]

#: The trunk of a ``nik train`` network: 4 x 256 SiLU. Chosen by measurement (``benchmarks/learned.py``):
#: its forward pass costs about a third of a 3 x 512 one per target on a batch of 10,000, one CPU thread.
DEFAULT_HIDDEN = (256, 256, 256, 256)
#: Hidden layers of a single-pose network (``nik train --single-pose``): a forward pass of about a twentieth of the
#: default's multiply-adds, cheap enough for one pose on the compiled backend (docs/learned.md).
SINGLE_POSE_HIDDEN = (64, 64)


@dataclass
class TrainCfg:
    """What ``nik train`` does (module docstring); the CLI's options, field for field."""

    robot: str | Path | Robot
    end_link: str | None = None
    root_link: str | None = None  # URDF: the link the chain starts from (default the URDF's root)
    minutes: float = 20.0  # wall-clock budget of the training (min), resumed parts included
    data: str | None = None  # dataset folder; None: fresh FK samples every step
    out: str | None = None  # NAME.safetensors; default runs/<name>/<name>.safetensors
    name: str | None = None  # run name (default: the robot's name)
    runs: str = "runs"  # folder of the runs
    install: bool = False  # copy the network to the user folder (checkpoint="auto" finds it, closed-form arms aside)
    resume: bool = False  # continue runs/<name>/last.ckpt
    kind: str = "auto"  # auto | branch_heads | multihead
    hidden: tuple[int, ...] = DEFAULT_HIDDEN
    heads: int = 8  # hypotheses of a multi-head net
    single_pose: bool = False  # a small network for single poses (recorded role "single_pose", nik.nets.registry)
    single_pose_share: float = 0.2  # of the budget, for a single-pose network where the main one does not pay (0: no)
    batch_size: int = 1024
    lr: float = 1e-3
    pose_start: float = 0.3  # fraction of the run in joint space before the FK pose loss
    steps_per_epoch: int = 200  # training steps between validations (streamed data)
    val_n: int = 5000  # validation samples
    seed: int = 0
    max_steps: int | None = None  # stop after this many steps too (tests, smoke runs)
    evaluate: bool = True
    eval_batch: int = 1000
    eval_one: int = 50
    command: str | None = None  # the command line to record (the CLI passes sys.argv)


@dataclass
class TrainResult:
    """What a run produced: the exported pair, where it was installed, the run folder, the figures."""

    out: Path
    run_dir: Path
    kind: str
    wall_s: float
    samples: int
    steps: int
    installed: Path | None = None
    single_pose: Path | None = None  # the single-pose network made beside ``out`` (module docstring, 6), or None
    single_pose_note: str = ""  # why there is one or not
    usage: list[str] = field(default_factory=list)  # how to solve with the installed network (nik.learn.usage)
    report: object = None
    validation: dict = field(default_factory=dict)


def choose_kind(robot: Robot) -> tuple[str, str]:
    """``(kind, why)``: ``branch_heads`` where :mod:`nik.data.branches` labels the arm's IK branches, else
    ``multihead``."""
    from nik.data.branches import ik_branch_classifier

    if ik_branch_classifier(robot) is not None:
        return "branch_heads", "the arm's IK branches are labelled (nik.data.branches): one head per branch"
    return "multihead", "no IK branch labels for this arm (e.g. redundant): K heads, winner-takes-all"


class Progress(L.Callback):
    """One line per validation: minutes used of the budget, steps, samples seen, validation error."""

    def __init__(self, minutes: float, write=None):
        super().__init__()
        self.minutes = minutes
        self.write = write or (lambda line: print(line, file=sys.stderr, flush=True))

    def on_validation_end(self, trainer, pl_module) -> None:
        if trainer.sanity_checking:
            return
        m = {k: float(v) for k, v in trainer.callback_metrics.items() if v.numel() == 1}
        line = (
            f"nik train: {pl_module.wall_s / 60:5.1f} / {self.minutes:g} min, step {trainer.global_step}, "
            f"{pl_module.sample_evals / 1e6:.2f} M samples; validation, best hypothesis: "
            f"{m.get('val_pos_mm', float('nan')):.2f} mm / {m.get('val_rot_deg', float('nan')):.2f} deg median, "
            f"{m.get('val_pos_mm_p95', float('nan')):.1f} mm / {m.get('val_rot_deg_p95', float('nan')):.1f} deg p95"
        )
        if pl_module.in_pose_phase():
            line += " (pose loss)"
        self.write(line)


def _quiet() -> None:
    from nik.learn.cli import _quiet_lightning

    _quiet_lightning()
    for name in ("lightning.pytorch", "lightning.fabric"):
        logging.getLogger(name).setLevel(logging.WARNING)
    for msg in (
        ".*does not have many workers.*",
        ".*LeafSpec.*",
        ".*treespec.*",
        ".*Total length of .*",
        ".*IterableDataset.*has `__len__` defined.*",
        ".*smaller than the logging interval.*",
    ):
        warnings.filterwarnings("ignore", message=msg)


def _datamodule(cfg: TrainCfg, robot: Robot):
    if cfg.data is None:
        from nik.learn.stream import FKStreamDataModule

        return FKStreamDataModule(
            robot, batch_size=cfg.batch_size, steps_per_epoch=cfg.steps_per_epoch, val_n=cfg.val_n, seed=cfg.seed
        )
    from nik.learn.datamodule import IKDataModule

    dm = IKDataModule(path=cfg.data, batch_size=cfg.batch_size, eval_batch_size=cfg.val_n, dtype="float32")
    dm.setup("fit")
    if dm.robot.definition_hash != robot.definition_hash:
        raise DatasetError(
            f"--data {cfg.data} was made for robot {dm.robot.name!r} (hash {dm.robot.definition_hash}), "
            f"not for {robot.name!r} (hash {robot.definition_hash})"
        )
    dm.robot = robot
    return dm


def data_sha256(data: dict, robot_hash: str) -> str:
    """The hash of the training data a pair records (``training.data_sha256``): the SHA-256 of the canonical JSON of
    the data's description (``training.data``: a seeded FK stream's sampler, seed and sizes, or a dataset's files'
    SHA-256) without its ``path``, and of the arm's definition hash. The samples are a function of these, so two
    runs with the same hash saw the same data, wherever their files were; no path of the machine is recorded."""
    import hashlib
    import json

    described = {k: v for k, v in data.items() if k != "path"}
    text = json.dumps({"data": described, "robot_hash": robot_hash}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def train_network(cfg: TrainCfg, *, log=None) -> TrainResult:
    """Run the recipe (module docstring); ``log(line)`` receives the progress lines (default: stderr).

    Raises:
        ValueError (nik's errors included): a bad option, a dataset for another arm, ``resume`` without a
            run to resume, a new run over an existing one, a damaged checkpoint.
    """
    write = log or (lambda line: print(line, file=sys.stderr, flush=True))
    robot = (
        cfg.robot
        if isinstance(cfg.robot, Robot)
        else load_robot(cfg.robot, end_link=cfg.end_link, root_link=cfg.root_link)
    )
    share = float(cfg.single_pose_share)
    if not 0.0 <= share < 1.0:
        raise ValueError(f"--single-pose-share must be in [0, 1), got {cfg.single_pose_share}")
    share = 0.0 if cfg.single_pose else share
    result = _train(replace(cfg, minutes=cfg.minutes * (1.0 - share)), robot, write, cfg.minutes)
    if share > 0:
        _single_pose_companion(cfg, robot, result, write)
    name = result.run_dir.name
    if cfg.install:
        from nik.learn.usage import network_usage

        result.installed = install(result.out, name=name)  # with its single-pose network, where it names one
        result.usage = network_usage(
            robot, result.installed, source=cfg.robot, end_link=cfg.end_link, root_link=cfg.root_link
        )
    if cfg.evaluate:
        result.report = network_report(robot, result.out, n_batch=cfg.eval_batch, n_one=cfg.eval_one)
        (result.run_dir / "report.txt").write_text("\n".join(result.report.lines()) + "\n")
    return result


def _single_pose_companion(cfg: TrainCfg, robot: Robot, main: TrainResult, write) -> None:
    """Where ``main``'s record says it does not serve single poses, train the single-pose network for the rest of
    the budget beside it and link it (module docstring, 6); ``main.single_pose`` / ``single_pose_note`` say what
    happened."""
    from nik.nets.pair import link_single_pose, read_pair_meta

    record = read_pair_meta(main.out).get("network_use", {})
    rec = record.get("against", {}).get("multistart", {})
    minutes = cfg.minutes * cfg.single_pose_share
    if rec.get("pose", False):
        main.single_pose_note = (
            f"the network pays for single poses too: no single-pose network ({minutes:.1f} min of the budget unused)"
        )
        write(f"nik train: {main.single_pose_note}")
        return
    w, wo = rec.get("pose_us", (float("nan"), float("nan")))
    why = (
        f"{w:.0f} us a pose with it, {wo:.0f} without"
        if w > wo
        else f"its best hypothesis the better start on {record.get('wins', 0.0):.0%} of the probe poses"
    )
    write(f"nik train: the network does not serve single poses ({why}): a single-pose network, {minutes:.1f} min")
    name = f"{main.run_dir.name}_one"
    out = main.out.with_name(f"{main.out.stem}_one.safetensors")
    one_cfg = replace(
        cfg, minutes=minutes, name=name, out=str(out), hidden=SINGLE_POSE_HIDDEN, single_pose=True, install=False,
        evaluate=False, resume=cfg.resume and (Path(cfg.runs) / name / "last.ckpt").is_file(),
    )  # fmt: skip
    one = _train(one_cfg, robot, write, cfg.minutes)
    link_single_pose(main.out, one.out)
    main.single_pose = one.out
    main.single_pose_note = f"single-pose network {one.out.name} ({one.wall_s / 60:.1f} min, {one.steps} steps)"


def _train(cfg: TrainCfg, robot: Robot, write, budget: float) -> TrainResult:
    """Train, export and record one network of ``cfg`` within ``cfg.minutes`` (module docstring, 1-6), the command's
    whole budget being ``budget`` minutes (both recorded); no install, no evaluation."""
    name = cfg.name or robot.name
    if not name or Path(name).name != name:
        raise ValueError(f"--name must be a plain name, got {name!r}")
    if cfg.minutes <= 0:
        raise ValueError(f"--minutes must be > 0, got {cfg.minutes}")
    run_dir = Path(cfg.runs) / name
    out = Path(cfg.out) if cfg.out else run_dir / f"{name}.safetensors"
    if out.suffix != ".safetensors":
        raise ValueError(f"--out must name a .safetensors file (its .json goes beside it), got {out}")
    kind, why = choose_kind(robot)
    if cfg.kind != "auto":
        if cfg.kind not in ("branch_heads", "multihead"):
            raise ValueError(f"--kind must be auto, branch_heads or multihead, got {cfg.kind!r}")
        if cfg.kind == "branch_heads" and kind != "branch_heads":
            raise ValueError(f"--kind branch_heads: {why}")
        kind, why = cfg.kind, "chosen with --kind"
    last = run_dir / "last.ckpt"
    ckpt_path = None
    if cfg.resume:
        if not last.is_file():
            raise FileNotFoundError(f"--resume: no run to resume at {last}")
        from nik.nets.checkpoint import load_checkpoint

        load_checkpoint(last, robot=robot)  # refuses a damaged file or another arm's run, in one line
        ckpt_path = str(last)
    elif last.exists():
        raise FileExistsError(
            f"{run_dir} holds a run already (last.ckpt): --resume continues it, --name starts another"
        )
    _quiet()
    write(f"nik train: {robot.name} ({robot.dof} joints, hash {robot.definition_hash}); network {kind}: {why}")
    write(
        f"nik train: data: {'fresh FK samples every step' if cfg.data is None else cfg.data}; "
        f"budget {cfg.minutes:g} min; run folder {run_dir}"
    )
    L.seed_everything(cfg.seed, verbose=False)
    dm = _datamodule(cfg, robot)
    model = MultiSolutionIK(
        kind=kind,
        hidden=tuple(cfg.hidden),
        heads=cfg.heads,
        pose_start=cfg.pose_start,
        lr=cfg.lr,
        eval_samples=cfg.val_n,
    )
    model.run_command = cfg.command
    run_dir.mkdir(parents=True, exist_ok=True)
    from lightning.pytorch.loggers import CSVLogger

    trainer = L.Trainer(
        default_root_dir=str(run_dir),
        max_time=timedelta(minutes=cfg.minutes),
        max_epochs=-1,
        max_steps=-1 if cfg.max_steps is None else int(cfg.max_steps),
        logger=CSVLogger(str(run_dir), name="logs"),
        callbacks=[History(), CurvePlot(filename="curve.png"), Progress(cfg.minutes, write), StableLastCheckpoint()],
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
        log_every_n_steps=max(1, min(50, cfg.steps_per_epoch)),
        devices=1,
    )
    trainer.fit(model, datamodule=dm, ckpt_path=ckpt_path)
    net = model.net.to(torch.float32).eval()
    counters = {"loss_evals": int(model.loss_evals), "sample_evals": int(model.sample_evals), "wall_s": model.wall_s}
    data = dm.describe()
    training = {
        "command": cfg.command or "not recorded (nik.learn.recipe.train_network called from Python)",
        "data": data,
        "data_sha256": data_sha256(data, robot.definition_hash),
        "kind_choice": why,
        "minutes_budget": budget,
        "minutes_network": cfg.minutes,
        "steps": int(trainer.global_step),
        "counters": counters,
        "seed": cfg.seed,
    }
    if model._earlier_commands:
        training["resumed_from_commands"] = list(model._earlier_commands)
    save(net, out, training=training, role="single_pose" if cfg.single_pose else None)
    record_use(out, robot)  # whether it pays per call type, in the JSON: solvers that load it need not measure
    write(f"nik train: wrote {out} and {out.with_suffix('.json')}")
    result = TrainResult(
        out=out,
        run_dir=run_dir,
        kind=kind,
        wall_s=counters["wall_s"],
        samples=int(model.sample_evals),
        steps=int(trainer.global_step),
    )
    return result
