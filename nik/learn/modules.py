"""Lightning modules: gradient-trained networks (``bp``, ``adam``, ``lbfgs``) and DE / DE-BP.

Every module owns one :class:`nik.nets.IKNet` (``self.net``), built in :meth:`IKModule.setup`
from the data module's robot and training split (its normalisation buffers are fitted there), and
reports the same metrics at validation/test: ``val_loss`` (the training objective), ``val_joint_mse``
(paper C eq. 4), ``val_pose_loss``, ``val_joint_rmse_deg``, ``val_pose_pos_mm`` / ``val_pose_rot_deg``
(means) and ``_p95``, ``loss_evals`` (losses of one weight vector on one batch so far, all
closure calls and DE individuals included), ``sample_evals`` (network forward passes on single
samples so far) and ``wall_s`` (seconds since the fit started).

Several processes (``--trainer.strategy ddp --trainer.devices N``): gradient modules train as usual
under DDP (each rank its share of the batches, gradients averaged); validation metrics are reduced
across ranks (``sync_dist``), the counters are summed over ranks and ``wall_s`` is the slowest rank's.
DE splits each generation's population across the ranks (see :class:`DEIK`).

Keeping a wall-clock budget (``keep_budget = True``, set by ``nik compare``): Lightning's ``Timer`` stops a run
only after the step that crosses ``trainer.max_time``, which on a large network is seconds (a full-batch L-BFGS
step, a DE generation). With ``keep_budget`` the module also checks the clock inside its steps: a step is not
started when the time left is shorter than the last one took; a DE generation is abandoned between its sample
chunks (the population stays as it was after the last whole generation); an L-BFGS step is abandoned between
loss evaluations and the weights go back to the best point it evaluated. One process only (under several
processes the ranks would have to agree on the clock: Lightning's ``Timer`` alone then).

Checkpoints carry ``checkpoint["nik"]`` (robot definition, hash, architecture; plain data) so that
:func:`nik.nets.load_checkpoint` reads them with ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

import lightning as L
import torch

from nik.learn.de import DECfg, DEState, de_init, de_step
from nik.learn.losses import LOSSES, evaluate, joint_mse, pose_loss
from nik.learn.population import flat_params, init_population, population_fitness, sample_chunk, set_flat_params
from nik.nets import IKNet, checkpoint_extra

__all__ = ["IKModule", "IKModuleCfg", "GradientIK", "GradientIKCfg", "DEIK", "DEIKCfg", "OutOfTime"]

#: Under a kept wall-clock budget a DE fitness evaluation runs in at least this many sample chunks, the clock checked
#: before each: an evaluation then overruns the budget by at most about one chunk's time.
CLOCK_CHUNKS = 8
#: Before the first generation's ask (the trial vectors: partners gathered, two (NP, D) uniform draws, the
#: crossover and the bounds, about ten passes over the population) is timed, its cost is estimated as the first
#: population's draw (one pass) times this; afterwards the last ask's time is used.
ASK_PASSES = 8.0


class OutOfTime(Exception):
    """Raised inside a step when the wall-clock budget ends before the step can finish (``keep_budget``)."""


def _all_gather(t: torch.Tensor) -> torch.Tensor:
    """``(world, *t.shape)``: ``t`` of every rank, in rank order (torch.distributed directly: Lightning's
    ``all_gather`` goes through a deprecated autograd collective and warns on every rank)."""
    import torch.distributed as dist

    parts = [torch.empty_like(t) for _ in range(dist.get_world_size())]
    dist.all_gather(parts, t.contiguous())
    return torch.stack(parts)


def _plain(value):
    """A config value comparable across a checkpoint and a module: sequences as lists."""
    return list(value) if isinstance(value, (list, tuple)) else value


@dataclass
class IKModuleCfg:
    """Settings of :class:`IKModule` (the network and the objective); each is also a keyword of the module."""

    hidden: tuple[int, ...] = (8,)
    activation: str = "tanh"
    representation: str = "rpy"
    output: str = "angles"
    loss: str = "joint"
    rot_weight: float = 1.0
    pose_weight: float = 1.0


@dataclass
class GradientIKCfg(IKModuleCfg):
    """Settings of :class:`GradientIK`: :class:`IKModuleCfg`'s and the optimiser's (documented there)."""

    optimizer: str = "adam"
    lr: float = 1e-3
    momentum: float = 0.0
    weight_decay: float = 0.0
    schedule: str = "none"
    min_lr_ratio: float = 0.01
    lbfgs_max_iter: int = 20
    lbfgs_history: int = 50


@dataclass
class DEIKCfg(IKModuleCfg):
    """Settings of :class:`DEIK`: :class:`IKModuleCfg`'s and differential evolution's (documented there)."""

    pop_size: int = 220
    F: float = 0.6
    CR: float = 0.5
    strategy: str = "rand1bin"
    jde: bool = False
    generations: int | None = 500
    bound: float | None = 10.0
    fitness_samples: int | None = None
    bp: bool = False
    bp_optimizer: str = "sgd"
    bp_lr: float = 0.1
    bp_momentum: float = 0.9
    max_fk: int = 2**18
    max_elements: int = 2**21


class IKModule(L.LightningModule):
    """Shared part: the network, the objective, metrics, counters and the checkpoint block.

    Settings: one :class:`IKModuleCfg` as ``cfg`` (keywords given too override its fields), or each setting as a
    keyword (``IKModule(hidden=(64,), loss="pose")``, ``train.py``'s ``model.init_args``; a subclass's settings
    likewise, with its own dataclass). ``hparams`` holds them flat, one key a setting.

    Args:
        hidden: hidden layer sizes (paper C: ``[8]``).
        activation: ``tanh`` (paper C), ``silu``, ``relu``, ... (:data:`nik.nets.ACTIVATIONS`).
        representation: network input: ``rpy`` (paper C), ``quat`` or ``rot6d``.
        output: ``angles`` or ``sincos``.
        loss: training objective: ``joint`` (paper C eq. 4), ``pose`` (through FK) or ``both``
            (joint + ``pose_weight`` * pose).
        rot_weight: weight of the rotation term of the pose loss (1 rad ~ one workspace length scale).
        pose_weight: weight of the pose loss in ``both``.
    """

    def __init__(self, cfg: IKModuleCfg | None = None, **kwargs):
        super().__init__()
        cfg = IKModuleCfg(**kwargs) if cfg is None else replace(cfg, **kwargs)
        if cfg.loss not in LOSSES:
            raise ValueError(f"model.loss must be one of {LOSSES}, got {cfg.loss!r}")
        self.record_settings(cfg)
        self.net: IKNet | None = None
        self.loss_evals = 0
        self.sample_evals = 0
        self._t0: float | None = None
        self._wall_before = 0.0  # seconds spent in earlier (resumed) fits
        #: the command line of this run (set by train.py's CLI and ``nik train``), recorded in checkpoints
        self.run_command: str | None = None
        self._earlier_commands: list[str] = []  # of the runs this one resumed
        #: check the clock inside steps so that a ``trainer.max_time`` budget is kept (see the module's docstring)
        self.keep_budget = False
        #: set when the module stopped the run for the clock (``keep_budget``); ``train_s``: seconds from the start
        #: of training to its end, as Lightning's Timer counts ``max_time`` (set when training ends)
        self.stopped_for_time = False
        self.train_s: float | None = None
        self._step_s = 0.0  # duration of the last training step (seconds)
        self._step_t0: float | None = None

    def record_settings(self, cfg, fixed: dict | None = None) -> None:
        """``hparams`` = the fields of the settings ``cfg`` (flat: one key a field, so a checkpoint's
        ``hyper_parameters`` are the module's keywords and old checkpoints load), ``fixed`` (choices a subclass
        makes, recorded too), and what Lightning adds under LightningCLI (``_class_path``, ``_instantiator``)."""
        self.save_hyperparameters()
        lightning_keys = {k: v for k, v in self.hparams.items() if k.startswith("_")}
        self.hparams.clear()  # Lightning merges into what is there: the collected arguments (``cfg`` itself) go
        self.save_hyperparameters({**asdict(cfg), **(fixed or {}), **lightning_keys})

    # -- network ---------------------------------------------------------------
    def net_config(self) -> dict:
        h = self.hparams
        return {
            "hidden": list(h.hidden),
            "activation": h.activation,
            "representation": h.representation,
            "output": h.output,
        }

    def ik_datamodule(self):
        """The trainer's :class:`IKDataModule` (it supplies the robot and the training data)."""
        dm = self.trainer.datamodule
        if dm is None or getattr(dm, "robot", None) is None:
            raise ValueError("nik training modules need an IKDataModule (it supplies the robot and training data)")
        return dm

    def setup(self, stage: str) -> None:
        if self.net is not None:
            return
        dm = self.ik_datamodule()
        pose, q = dm.train_data
        net = IKNet(dm.robot, **self.net_config())
        net.fit_normalisation(pose, q)
        self.net = net.to(dtype=pose.dtype)

    # -- objective ---------------------------------------------------------------
    def objective(self, y: torch.Tensor, T: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """Training loss of raw outputs ``y: (..., N, out)`` for poses ``T: (N, 4, 4)`` and joints ``q: (N, dof)``."""
        h, net = self.hparams, self.net
        total = 0.0
        if h.loss in ("joint", "both"):
            total = total + joint_mse(y, net.encode(q))
        if h.loss in ("pose", "both"):
            pl = pose_loss(net.decode(y), T, net.robot, length_scale=net.length_scale, rot_weight=h.rot_weight)
            total = total + (h.pose_weight if h.loss == "both" else 1.0) * pl
        return total

    def batch_loss(self, batch) -> torch.Tensor:
        T, q = batch
        loss = self.objective(self.net.raw(self.net.features(T)), T, q)
        self.loss_evals += 1
        self.sample_evals += T.shape[0]
        return loss

    # -- timing and metrics ------------------------------------------------------------
    def on_fit_start(self) -> None:
        self._t0 = time.perf_counter()

    def time_left(self) -> float | None:
        """Seconds left of the trainer's wall-clock budget (its ``Timer``, from ``trainer.max_time``), None
        without one, or when ``keep_budget`` is off or several processes train."""
        if not self.keep_budget or self._trainer is None or self.trainer.world_size > 1:
            return None
        timer = next((cb for cb in self.trainer.callbacks if type(cb).__name__ == "Timer"), None)
        if timer is None or getattr(timer, "_duration", None) is None:
            return None
        return timer.time_remaining("train")

    def step_cost_s(self) -> float:
        """Seconds the next step is expected to need before it can be abandoned: the last step's duration
        (subclasses that can abandon a step part-way return less)."""
        return self._step_s

    def on_train_batch_start(self, batch, batch_idx):
        left = self.time_left()
        if left is not None and left <= self.step_cost_s():
            self.stopped_for_time = True
            self.trainer.should_stop = True
            return -1  # Lightning: skip the rest of the epoch; should_stop ends the fit
        self._step_t0 = time.perf_counter()
        return None

    def on_train_batch_end(self, outputs, batch, batch_idx) -> None:
        if self._step_t0 is not None:
            self._step_s = time.perf_counter() - self._step_t0

    def on_train_start(self) -> None:
        self._train_t0 = time.perf_counter()

    def on_train_end(self) -> None:
        # from the start of training to its end, as Lightning's Timer counts a max_time budget
        self.train_s = time.perf_counter() - getattr(self, "_train_t0", self._t0 or time.perf_counter())

    @property
    def wall_s(self) -> float:
        return self._wall_before + (0.0 if self._t0 is None else time.perf_counter() - self._t0)

    def _log_counters(self) -> None:
        # work done by this rank: summed over ranks; the wall clock of the slowest rank
        self.log("loss_evals", float(self.loss_evals), on_step=False, on_epoch=True, sync_dist=True, reduce_fx="sum")
        self.log(
            "sample_evals", float(self.sample_evals), on_step=False, on_epoch=True, sync_dist=True, reduce_fx="sum"
        )
        self.log("wall_s", self.wall_s, on_step=False, on_epoch=True, sync_dist=True, reduce_fx="max")

    def _eval_step(self, batch, prefix: str) -> None:
        T, q = batch
        with torch.no_grad():
            loss = self.objective(self.net.raw(self.net.features(T)), T, q)
        m = evaluate(self.net, T, q, rot_weight=self.hparams.rot_weight)
        n = T.shape[0]
        values = {
            "loss": float(loss),
            "joint_mse": m["joint_mse"],
            "pose_loss": m["pose_loss"],
            "joint_rmse_deg": m["joint_rmse_deg"],
            "pose_pos_mm": m["pos_mm_mean"],
            "pose_rot_deg": m["rot_deg_mean"],
            "pose_pos_mm_p95": m["pos_mm_p95"],
            "pose_rot_deg_p95": m["rot_deg_p95"],
        }
        for k, v in values.items():
            self.log(f"{prefix}_{k}", v, batch_size=n, prog_bar=k == "loss", sync_dist=True)
        if prefix == "val":
            self._log_counters()

    def validation_step(self, batch, batch_idx):
        self._eval_step(batch, "val")

    def test_step(self, batch, batch_idx):
        self._eval_step(batch, "test")

    # -- checkpoints -------------------------------------------------------------
    def on_save_checkpoint(self, checkpoint: dict) -> None:
        extra = checkpoint_extra(self.net)
        extra["counters"] = {
            "loss_evals": int(self.loss_evals),
            "sample_evals": int(self.sample_evals),
            "wall_s": float(self.wall_s),
        }
        run = {"command": self.run_command or "not recorded (trained through the Python API)"}
        if self._earlier_commands:
            run["resumed_from_commands"] = list(self._earlier_commands)
        dm = self.trainer.datamodule if self._trainer is not None else None
        if dm is not None and hasattr(dm, "describe"):
            run["data"] = dm.describe()
        extra["run"] = run
        checkpoint["nik"] = extra

    def check_resumable(self, checkpoint: dict) -> None:
        """Refuse a checkpoint of another robot or another network than this run's, in one line
        (:class:`nik.CheckpointError`), before Lightning loads its weights: robots are matched by definition hash,
        not by name (a 6-joint arm's run resumed on another 6-joint arm's data would otherwise train on silently),
        and the architecture by the checkpoint's recorded ``net`` block against this module's."""
        from nik.errors import CheckpointError

        extra = checkpoint.get("nik")
        if self.net is None or not isinstance(extra, dict):
            return
        robot = self.net.robot
        stored = extra.get("robot_hash")
        if stored is not None and stored != robot.definition_hash:
            name = (extra.get("robot") or {}).get("name", "?") if isinstance(extra.get("robot"), dict) else "?"
            raise CheckpointError(
                f"the checkpoint is a run of robot {name!r} (definition hash {stored}), this run's data is of robot "
                f"{robot.name!r} (hash {robot.definition_hash}): resume a run of the same robot, or start a new one"
            )
        cfg = extra.get("net")
        if isinstance(cfg, dict) and "kind" not in cfg:
            mine = self.net.config()
            differ = [k for k in mine if k in cfg and _plain(cfg[k]) != _plain(mine[k])]
            if differ:
                k = differ[0]
                raise CheckpointError(
                    f"the checkpoint's network has {k} {_plain(cfg[k])!r}, this run's model {_plain(mine[k])!r}: "
                    f"resume with the checkpoint's --model.{k}, or start a new run"
                )

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        self.check_resumable(checkpoint)
        run = checkpoint.get("nik", {}).get("run", {})
        earlier = run.get("resumed_from_commands", [])
        self._earlier_commands = [*earlier, run["command"]] if "command" in run else list(earlier)
        counters = checkpoint.get("nik", {}).get("counters", {})
        self.loss_evals = int(counters.get("loss_evals", 0))
        self.sample_evals = int(counters.get("sample_evals", 0))
        self._wall_before = float(counters.get("wall_s", 0.0))


class GradientIK(IKModule):
    """Gradient training: ``optimizer`` ``sgd`` (plain back-propagation, paper C's baseline), ``adam``
    or ``lbfgs`` (use it with a full batch, ``data.batch_size: null``).

    Args (beyond :class:`IKModule`):
        optimizer: ``sgd`` | ``adam`` | ``lbfgs``.
        lr: learning rate (L-BFGS: step scale, 1 is standard).
        momentum: SGD momentum (0 = plain gradient descent).
        weight_decay: L2 penalty (sgd/adam).
        schedule: ``none`` or ``cosine``: the LR decays from ``lr`` to ``lr * min_lr_ratio`` over the
            run, measured by whichever is further along, steps (of ``trainer.max_steps`` / the
            estimated total) or wall-clock time (of ``trainer.max_time``), so a time-budgeted run decays too.
        min_lr_ratio: final LR of the cosine schedule relative to ``lr``.
        lbfgs_max_iter: L-BFGS iterations per step (each evaluates the loss at least once).
        lbfgs_history: L-BFGS memory.
    """

    def __init__(self, cfg: GradientIKCfg | None = None, **kwargs):
        cfg = GradientIKCfg(**kwargs) if cfg is None else replace(cfg, **kwargs)
        if cfg.optimizer not in ("sgd", "adam", "lbfgs"):
            raise ValueError(f"model.optimizer must be sgd, adam or lbfgs, got {cfg.optimizer!r}")
        if cfg.schedule not in ("none", "cosine"):
            raise ValueError(f"model.schedule must be none or cosine, got {cfg.schedule!r}")
        super().__init__(cfg)

    def training_step(self, batch, batch_idx):
        loss = self.batch_loss(batch)
        self.log("train_loss", loss, on_step=False, on_epoch=True, batch_size=batch[0].shape[0], sync_dist=True)
        return loss

    def step_cost_s(self) -> float:
        # an L-BFGS step can be abandoned between its loss evaluations: one evaluation is the unit
        if self.hparams.optimizer == "lbfgs":
            return getattr(self, "_eval_s", 0.0)
        return self._step_s

    def optimizer_step(self, epoch, batch_idx, optimizer, optimizer_closure=None):
        if self.hparams.optimizer != "lbfgs" or self.time_left() is None:
            return super().optimizer_step(epoch, batch_idx, optimizer, optimizer_closure)
        best = {"loss": math.inf, "w": flat_params(self.net)}

        def closure():
            left = self.time_left()
            if left is not None and left <= getattr(self, "_eval_s", 0.0):
                raise OutOfTime
            t0 = time.perf_counter()
            loss = optimizer_closure()
            self._eval_s = time.perf_counter() - t0
            value = float(loss)
            if value < best["loss"]:  # the weights at which the loss was evaluated
                best["loss"], best["w"] = value, flat_params(self.net)
            return loss

        try:
            optimizer.step(closure=closure)
        except OutOfTime:
            set_flat_params(self.net, best["w"])  # a line search may have left the weights at a trial point
            self.stopped_for_time = True
            self.trainer.should_stop = True

    def _progress(self) -> float:
        """Fraction of the run done, in [0, 1]: the larger of the step and the time fractions."""
        trainer = self.trainer
        frac = 0.0
        total = self._total_steps
        if total and math.isfinite(total):
            frac = trainer.global_step / max(1, total)
        timer = next((cb for cb in trainer.callbacks if type(cb).__name__ == "Timer"), None)
        duration = getattr(timer, "_duration", None) if timer is not None else None
        if duration:
            frac = max(frac, self.wall_s / duration)
        return min(1.0, frac)

    def configure_optimizers(self):
        h = self.hparams
        params = self.net.parameters()
        # computed once: Lightning's estimate re-walks the data loaders on every access
        t = self.trainer
        self._total_steps = t.max_steps if t.max_steps and t.max_steps > 0 else t.estimated_stepping_batches
        if h.optimizer == "sgd":
            opt = torch.optim.SGD(params, lr=h.lr, momentum=h.momentum, weight_decay=h.weight_decay)
        elif h.optimizer == "adam":
            opt = torch.optim.Adam(params, lr=h.lr, weight_decay=h.weight_decay)
        else:
            opt = torch.optim.LBFGS(
                params, lr=h.lr, max_iter=h.lbfgs_max_iter, history_size=h.lbfgs_history, line_search_fn="strong_wolfe"
            )
        if h.schedule == "none":
            return opt
        r = h.min_lr_ratio

        def factor(_step: int) -> float:
            return r + (1 - r) * 0.5 * (1 + math.cos(math.pi * self._progress()))

        sched = torch.optim.lr_scheduler.LambdaLR(opt, factor)
        return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}


class DEIK(IKModule):
    """Differential evolution of the flattened weights (``de``), optionally followed by
    back-propagation from the best individual (``de_bp``, paper C's flow). Manual optimisation.

    Each training step is one DE generation on that step's batch (``data.batch_size: null``: the
    whole training split, as in paper C), evaluated for all ``pop_size`` networks in one batched
    computation (:func:`nik.learn.population.population_fitness`). After every generation the
    network holds the best individual, so validation and checkpoints see it. With ``bp`` set, DE stops
    after ``generations`` generations and training continues by BP from the best individual. A
    generation counts as one trainer step: ``trainer.max_steps`` bounds generations plus BP steps.

    Several processes (DDP): every rank holds the whole state and draws the same trials from the same
    generator; rank ``r`` evaluates the ``r``-th slice of them, the fitness is gathered
    (``all_gather``) and every rank selects alike. Each slice is evaluated with the sample chunking
    of the whole population, so the result is bit-identical to one process. All ranks need the same
    batch: set ``trainer.use_distributed_sampler: false`` (the DE configs do; checked every step).

    Args (beyond :class:`IKModule`):
        pop_size, F, CR, strategy, jde: see :class:`nik.learn.de.DECfg` (paper C: 220, 0.6, 0.5, rand1bin, no).
        generations: DE generations (paper C: 500); for ``de`` alone ``null`` means "until the trainer stops".
        bound: every weight is kept in ``[-bound, bound]`` (``null``: unbounded).
        fitness_samples: if set, each generation scores all individuals on the same random subset of
            this many samples of the batch (parents re-evaluated on it too, so selection compares like
            with like); ``null``: the whole batch.
        bp: continue with back-propagation after ``generations`` (DE-BP).
        bp_optimizer, bp_lr, bp_momentum: the BP stage (``sgd`` = paper C's BP).
        max_fk, max_elements: memory bounds of the batched evaluation (see ``population_fitness``).
    """

    def __init__(self, cfg: DEIKCfg | None = None, **kwargs):
        cfg = DEIKCfg(**kwargs) if cfg is None else replace(cfg, **kwargs)
        if cfg.bp and cfg.generations is None:
            raise ValueError("model.bp (DE-BP) needs model.generations: how many DE generations before BP")
        if cfg.bp_optimizer not in ("sgd", "adam"):
            raise ValueError(f"model.bp_optimizer must be sgd or adam, got {cfg.bp_optimizer!r}")
        super().__init__(cfg)
        self.cfg = DECfg(pop_size=cfg.pop_size, F=cfg.F, CR=cfg.CR, strategy=cfg.strategy, jde=cfg.jde)
        self.automatic_optimization = False
        self.de_state: DEState | None = None
        self.generator: torch.Generator | None = None
        self.history: list[float] = []  # best fitness after each generation
        self.first_bp_loss: float | None = None
        self._ask_s = 0.0  # seconds the next generation's ask needs (it cannot be abandoned part-way)
        self._fitness_s = 0.0  # seconds spent in fitness evaluations

    @property
    def in_de_phase(self) -> bool:
        g = self.hparams.generations
        return g is None or self.de_state is None or self.de_state.generation < g or not self.hparams.bp

    def on_fit_start(self) -> None:
        super().on_fit_start()
        if self.generator is None:
            # drawn from the global RNG, which seed_everything has seeded: same seed, same run
            seed = int(torch.randint(0, 2**62, (1,)))
            # every rank draws the same trials: rank 0's seed for all
            seed = self.trainer.strategy.broadcast(seed, src=0)
            self.generator = torch.Generator().manual_seed(seed)

    def _fitness_fn(self, T: torch.Tensor, q: torch.Tensor):
        """``fitness(W: (M, P)) -> (M,)`` on the samples ``T, q``; under several processes each rank
        evaluates its slice of ``W`` and the pieces are gathered, so every rank gets all ``M`` values."""
        h, net = self.hparams, self.net
        x = net.features(T)
        y_t = net.encode(q) if h.loss != "pose" else None
        world = self.trainer.world_size if self._trainer is not None else 1
        rank = self.trainer.global_rank if world > 1 else 0

        def local(W: torch.Tensor, chunk: int) -> torch.Tensor:
            clock = self._chunk_clock() if self.time_left() is not None else None
            if clock is not None:  # keep_budget: at least CLOCK_CHUNKS checks per evaluation, so one can stop it
                chunk = min(chunk, max(1, -(-x.shape[0] // CLOCK_CHUNKS)))
            t_fit = time.perf_counter()
            value = population_fitness(
                net,
                W,
                x,
                y_target=y_t,
                T_target=T,
                loss=h.loss,
                rot_weight=h.rot_weight,
                pose_weight=h.pose_weight,
                chunk=chunk,
                between_chunks=clock,
            )
            self._fitness_s += time.perf_counter() - t_fit
            self.loss_evals += W.shape[0]  # counted when the evaluation completed
            self.sample_evals += W.shape[0] * T.shape[0]
            return value

        def fitness(W: torch.Tensor) -> torch.Tensor:
            m = W.shape[0]
            # the chunking of all M networks, whichever slice this rank evaluates: same bits as one process
            chunk = sample_chunk(net, m, x.shape[1], loss=h.loss, max_elements=h.max_elements, max_fk=h.max_fk)
            if world == 1:
                return local(W, chunk)
            per = -(-m // world)
            mine = W[rank * per : min((rank + 1) * per, m)]
            part = torch.full((per,), float("nan"), dtype=W.dtype, device=W.device)
            if mine.shape[0]:
                part[: mine.shape[0]] = local(mine, chunk)
            return _all_gather(part).reshape(-1)[:m]

        return fitness

    def step_cost_s(self) -> float:
        # a DE generation can be abandoned between sample chunks, not inside its ask; a BP step not at all
        return self._step_s if not self.in_de_phase else self._ask_s

    def _chunk_clock(self):
        """A check run before each sample chunk of a fitness evaluation: raises :class:`OutOfTime` when the time
        left is shorter than the last chunk took."""
        last = {"t": None}

        def check() -> None:
            now = time.perf_counter()
            if last["t"] is not None:
                self._chunk_s = now - last["t"]
            left = self.time_left()
            if left is not None and left <= getattr(self, "_chunk_s", 0.0):
                raise OutOfTime
            last["t"] = now

        return check

    def _check_same_batch(self, T: torch.Tensor, q: torch.Tensor) -> None:
        """Under several processes: every rank must see the same batch (DE's fitness is one function)."""
        if self.trainer.world_size == 1:
            return
        n = torch.tensor(float(T.shape[0]), dtype=torch.float64, device=T.device)
        marks = _all_gather(torch.stack([T.double().sum(), q.double().sum(), n]))
        if not bool((marks == marks[0]).all()):
            raise ValueError(
                "DE across processes needs the same training batch on every rank; set "
                "trainer.use_distributed_sampler: false (configs/train/de.yaml and de_bp.yaml do)"
            )

    def _count_step(self) -> None:
        """A DE generation is a trainer step (so ``trainer.max_steps`` stops DE): an optimizer step that
        changes nothing (no parameter has a gradient) advances ``trainer.global_step``."""
        opt = self.optimizers()
        opt.zero_grad(set_to_none=True)
        opt.step()

    def _bounds(self, like: torch.Tensor):
        b = self.hparams.bound
        if b is None:
            return None, None
        return (
            torch.tensor(-float(b), dtype=like.dtype, device=like.device),
            torch.tensor(float(b), dtype=like.dtype, device=like.device),
        )

    def training_step(self, batch, batch_idx):
        h = self.hparams
        T, q = batch
        if not self.in_de_phase:
            return self._bp_step(batch)
        self._check_same_batch(T, q)
        subsample = h.fitness_samples is not None and h.fitness_samples < T.shape[0]
        if subsample:
            idx = torch.randperm(T.shape[0], generator=self.generator)[: h.fitness_samples].to(T.device)
            T, q = T.index_select(0, idx), q.index_select(0, idx)
        fitness = self._fitness_fn(T, q)
        if self.de_state is not None and self.de_state.x.device != T.device:  # resumed from a checkpoint
            self.de_state = DEState(*(v.to(T.device) if isinstance(v, torch.Tensor) else v for v in self.de_state))
        try:
            if self.de_state is None:
                clock = self._chunk_clock() if self.time_left() is not None else None
                t_draw = time.perf_counter()
                x0 = init_population(self.net, self.cfg.pop_size, generator=self.generator, between_chunks=clock)
                self._ask_s = ASK_PASSES * (time.perf_counter() - t_draw)
                x0[0] = flat_params(self.net)  # the net's own initial weights are one of the individuals
                lo, hi = self._bounds(x0)
                if lo is not None:
                    x0 = x0.clamp(float(lo), float(hi))
                self.de_state = de_init(x0, fitness(x0), self.cfg, lower=lo, upper=hi)
            else:
                t_step, fit_before = time.perf_counter(), self._fitness_s
                self.de_state = de_step(
                    self.de_state, fitness, self.cfg, generator=self.generator, reevaluate=subsample
                )
                self._ask_s = time.perf_counter() - t_step - (self._fitness_s - fit_before)
        except OutOfTime:  # keep_budget: the generation is abandoned, the population is the last whole one
            self.stopped_for_time = True
            self.trainer.should_stop = True
            return None
        set_flat_params(self.net, self.de_state.best_x)
        best = self.de_state.best_fitness
        self.history.append(best)
        # the same on every rank (the fitness was gathered), so not reduced: a reduction here is a collective
        # that rank 0's progress bar runs at another point of the epoch's end than the other ranks (a deadlock)
        self.log("train_loss", best, on_step=False, on_epoch=True, batch_size=T.shape[0], rank_zero_only=True)
        self.log("de_generation", float(self.de_state.generation), on_step=False, on_epoch=True, rank_zero_only=True)
        if not h.bp and h.generations is not None and self.de_state.generation >= h.generations:
            self.trainer.should_stop = True
        self._count_step()
        return None

    def _bp_step(self, batch):
        opt = self.optimizers()
        opt.zero_grad()
        loss = self.batch_loss(batch)
        if self.first_bp_loss is None:
            self.first_bp_loss = float(loss.detach())
        self.manual_backward(loss)
        opt.step()
        # every rank has the same whole batch (no distributed sampler) and the same weights: no reduction
        self.log(
            "train_loss", loss.detach(), on_step=False, on_epoch=True, batch_size=batch[0].shape[0], rank_zero_only=True
        )
        return loss

    def configure_optimizers(self):
        h = self.hparams
        if h.bp_optimizer == "sgd":
            return torch.optim.SGD(self.net.parameters(), lr=h.bp_lr, momentum=h.bp_momentum)
        return torch.optim.Adam(self.net.parameters(), lr=h.bp_lr)

    # -- checkpoints: the population too, so that a DE run resumes where it stopped ------------
    def on_save_checkpoint(self, checkpoint: dict) -> None:
        super().on_save_checkpoint(checkpoint)
        s = self.de_state
        if s is not None:
            checkpoint["nik_de"] = {
                "x": s.x.detach().cpu(),
                "fitness": s.fitness.detach().cpu(),
                "F": s.F.detach().cpu(),
                "CR": s.CR.detach().cpu(),
                "generation": int(s.generation),
                "evals": int(s.evals),
                "generator": self.generator.get_state(),
                "history": list(self.history),
                "first_bp_loss": self.first_bp_loss,
            }

    def on_load_checkpoint(self, checkpoint: dict) -> None:
        super().on_load_checkpoint(checkpoint)
        d = checkpoint.get("nik_de")
        if d is None:
            return
        lo, hi = self._bounds(d["x"])
        self.de_state = DEState(d["x"], d["fitness"], d["F"], d["CR"], lo, hi, d["generation"], d["evals"])
        self.generator = torch.Generator()
        self.generator.set_state(d["generator"])
        self.history = list(d["history"])
        self.first_bp_loss = d["first_bp_loss"]
