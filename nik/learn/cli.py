"""The LightningCLI behind ``python train.py``: ``fit | validate | test --config configs/train/<method>.yaml``.

Every run writes ``<trainer.default_root_dir>/last.ckpt`` (see :class:`nik.learn.callbacks.StableLastCheckpoint`);
the shipped configs set ``default_root_dir`` to ``runs/<method>``. The default logger is a ``CSVLogger`` in
``default_root_dir``. Refused before training starts, each in one line (``train.py: error: ...``, exit status 2):

- a ``--ckpt_path`` that is not a loadable nik checkpoint, or one made for another robot than the data's (matched by
  definition hash, as :func:`nik.nets.load_checkpoint` and :class:`nik.IKSolver` match), or for another network
  architecture (:class:`nik.CheckpointError`);
- a zero budget (``--trainer.max_time 00:00:00:00``, ``--trainer.max_epochs 0``, ``--trainer.max_steps 0``): such a run
  trains nothing and keeps no ``last.ckpt``, so it is refused rather than run;
- an option or config key that does not exist (``--model.hiden``, a YAML ``hiden:``): the message names the key and
  the closest accepted one (:func:`difflib.get_close_matches`), in place of jsonargparse's usage text.

DE and DE-BP runs (:class:`nik.learn.modules.DEIK`) get :class:`nik.learn.callbacks.DEProgress`: progress lines on
stderr during DE (unless ``--trainer.enable_progress_bar false``) and a closing line that says which phases ran.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import io
import logging
import re
import sys
import warnings
from datetime import timedelta
from pathlib import Path

from nik.errors import CheckpointError, NikError

__all__ = [
    "TRAIN_CONFIG_DIR",
    "METHODS",
    "NET_NAMES",
    "ConfigError",
    "build_parser",
    "check_budget",
    "check_resume_checkpoint",
    "cli_main",
    "config_error_line",
    "method_config",
]

#: The shipped training configs (``configs/train`` at the repository root), one per method.
TRAIN_CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "train"
METHODS = ("bp", "adam", "lbfgs", "de", "de_bp")
#: The networks ``nik compare`` trains (:data:`nik.learn.compare.NETS`): paper C's 6-8-6 net and the default.
NET_NAMES = ("paper", "default")
#: ``--ckpt_path`` values that Lightning resolves itself (not files).
_SPECIAL_CKPT = ("last", "best", "hpc", "registry")


def build_parser(ap: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The arguments of ``nik compare`` (:func:`nik.learn.compare.compare`); here, so that parsing imports no torch.

    Every option's help states its default. The values are checked by :func:`nik.learn.compare.check_args`
    before any work (``nik compare`` refuses a bad value in one line, exit status 2)."""
    ap = ap or argparse.ArgumentParser(description="Compare bp, adam, lbfgs, de, de_bp on one dataset and budget")
    ap.add_argument(
        "--data", type=Path, default=Path("data/kuka_kr_100k"), help="dataset folder (default data/kuka_kr_100k)"
    )
    ap.add_argument(
        "--budget",
        type=float,
        default=None,
        metavar="SECONDS",
        help="wall-clock seconds of training per run, kept inside the steps (a DE generation or an L-BFGS step is "
        "abandoned when the time is up); default 60 when --steps is not given, else none. Timed runs differ "
        "from one repetition to the next",
    )
    ap.add_argument(
        "--steps",
        type=int,
        default=None,
        metavar="N",
        help="training steps per run (an optimiser step on a batch, an L-BFGS step of up to 20 iterations, a DE "
        "generation, a BP step of de_bp): the reproducible budget, the same seed gives the same table; "
        "default none. With --budget too, whichever ends first",
    )
    ap.add_argument(
        "--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="SEED", help="seeds, one run each (default 0 1 2)"
    )
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS, help="methods (default all five)")
    ap.add_argument(
        "--nets",
        nargs="+",
        default=list(NET_NAMES),
        choices=list(NET_NAMES),
        help="paper: paper C's 6-8-6 tanh net; default: nik.nets.DEFAULT, 3 x 256 SiLU (default both)",
    )
    ap.add_argument(
        "--de-samples",
        type=int,
        default=1000,
        metavar="N",
        help="de, de_bp: each DE generation scores every individual on the same random N-sample subset of the "
        "training split (parents re-scored on it); 0: the whole split, as paper C (default 1000)",
    )
    ap.add_argument(
        "--de-generations",
        type=int,
        default=500,
        metavar="N",
        help="de, de_bp: DE generations (de_bp then continues by BP; de stops) (default 500, paper C)",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="PREFIX",
        help="writes PREFIX.md (table and verdict), PREFIX.csv (one row per run), PREFIX_history.csv and "
        "PREFIX.png (validation loss against time) (default runs/compare/DATA/compare, DATA the dataset "
        "folder's name)",
    )
    ap.add_argument(
        "--runs-dir",
        type=Path,
        default=None,
        metavar="RUNS",
        help="folder of the runs' checkpoints, RUNS/NET/METHOD/seedSEED/ (default runs/compare/DATA)",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (default 1: on a shared CPU, 2 OpenMP threads stall on each other)",
    )
    return ap


def method_config(method: str) -> Path:
    """Path of the shipped config of ``method`` (one of :data:`METHODS`)."""
    if method not in METHODS:
        raise ValueError(f"unknown training method {method!r}; expected one of {METHODS}")
    return TRAIN_CONFIG_DIR / f"{method}.yaml"


class _DropTips(logging.Filter):
    """Drops Lightning's advertising tips ("💡 Tip: ... try installing litlogger / litmodels")."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith("💡 Tip")


def _quiet_lightning() -> None:
    """Silence what nik's use of Lightning does not need to show. Narrow on purpose:

    - the litlogger / litmodels tips (Lightning's ``rank_zero_info`` advertisements);
    - torch 2.13's ``FutureWarning`` that ``LeafSpec`` is deprecated, raised inside Lightning 2.6's own
      ``lightning/pytorch/utilities/_pytree.py`` (a dependency's use of torch, not nik's).
    """
    for name in ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero"):
        log = logging.getLogger(name)
        if not any(isinstance(f, _DropTips) for f in log.filters):
            log.addFilter(_DropTips())
    warnings.filterwarnings(
        "ignore", message=r"`isinstance\(treespec, LeafSpec\)` is deprecated", category=FutureWarning
    )


class ConfigError(NikError):
    """A ``train.py`` option or config value that cannot run (an unknown key, a zero budget), said in one line."""


def check_resume_checkpoint(path: str | Path, data: str | Path | None = None) -> None:
    """Refuse a ``--ckpt_path`` that is missing, not a loadable nik checkpoint, an exported network (``.safetensors``
    / ``.json``: weights without the training state) or, with ``data`` (the dataset folder of the run), made for
    another robot than the dataset's: the robots are matched by definition hash, not by name (a kuka_kr run resumed
    on puma560 data, both 6 joints, would otherwise train on silently). One line, no traceback from deep inside
    Lightning. Raises :class:`FileNotFoundError` or :class:`nik.CheckpointError`."""
    from nik.nets import load_checkpoint

    if Path(path).suffix in (".safetensors", ".json"):
        raise CheckpointError(
            f"--ckpt_path {path} is an exported network (weights only, no training state): resume from the run's "
            "last.ckpt, or give this file to nik.IKSolver(robot, checkpoint=PATH) to solve with it"
        )
    net = load_checkpoint(path)  # weights_only=True: no code from the file runs
    if data is None:
        return
    from nik.data import read_meta

    try:
        meta = read_meta(data)
        name, digest = meta["robot"]["name"], meta["robot"]["definition_hash"]
    except (NikError, KeyError, TypeError):
        return  # a missing or damaged dataset is refused, in its own words, when the data module opens it
    stored = net.robot
    if stored.definition_hash != digest:
        raise CheckpointError(
            f"--ckpt_path {path} is a run of robot {stored.name!r} (definition hash {stored.definition_hash}), the "
            f"data {data} is of robot {name!r} (hash {digest}): resume a run of the same robot, or drop --ckpt_path "
            "to start a new one"
        )


def _time_budget(value) -> timedelta | None:
    """``trainer.max_time`` as Lightning reads it (``"DD:HH:MM:SS"``, a mapping of ``days`` / ``hours`` / ``minutes``
    / ``seconds``, or a ``timedelta``), None where unset or not one of these (Lightning words that error)."""
    if value is None or isinstance(value, timedelta):
        return value
    try:
        if isinstance(value, str):
            parts = [int(v) for v in value.split(":")]
            if len(parts) != 4:
                return None
            return timedelta(**dict(zip(("days", "hours", "minutes", "seconds"), parts, strict=True)))
        return timedelta(**{k: float(v) for k, v in dict(value).items()})
    except (TypeError, ValueError):
        return None


def check_budget(trainer: dict) -> None:
    """Refuse a fit whose budget is zero: ``max_time`` of zero or less, ``max_epochs`` or ``max_steps`` of 0. Such a
    run would train nothing, keep no ``last.ckpt`` (every other run keeps one) and exit 0; it is refused in one line
    (:class:`ConfigError`) instead. ``-1`` (no limit) and ``None`` stay allowed."""
    budget = _time_budget(trainer.get("max_time"))
    if budget is not None and budget.total_seconds() <= 0:
        raise ConfigError(
            f"--trainer.max_time {trainer.get('max_time')} is a budget of {budget.total_seconds():g} s: the run "
            "would train nothing and keep no last.ckpt; give a positive time (DD:HH:MM:SS, e.g. 00:00:05:00)"
        )
    for key in ("max_epochs", "max_steps"):
        if trainer.get(key) == 0:
            raise ConfigError(
                f"--trainer.{key} 0: the run would train nothing and keep no last.ckpt; give a positive number "
                "(-1: no limit)"
            )


def _accepted_keys(parser) -> list[str]:
    """Every option key of a jsonargparse parser (``data.path``, ``trainer.max_epochs``, ...)."""
    keys = []
    for action in getattr(parser, "_actions", []):
        dest = getattr(action, "dest", None)
        if isinstance(dest, str) and dest not in ("help", argparse.SUPPRESS) and not dest.endswith(".help"):
            keys.append(dest)
    return keys


def _init_keys(class_path: str) -> list[str]:
    """The constructor arguments of the class at ``class_path`` (the model's ``init_args``), or []; a settings
    dataclass among them (``cfg: GradientIKCfg | None``, whose fields are keywords too) adds its fields."""
    import dataclasses
    import importlib
    import inspect
    import typing

    module, _, name = class_path.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), name)
        params = inspect.signature(cls.__init__).parameters
        hints = typing.get_type_hints(cls.__init__)
    except (ImportError, AttributeError, ValueError, TypeError, NameError):
        return []
    keys = [
        p for p in params if p != "self" and params[p].kind not in (params[p].VAR_POSITIONAL, params[p].VAR_KEYWORD)
    ]
    for p in list(keys):
        for t in (hints.get(p), *typing.get_args(hints.get(p))):
            if dataclasses.is_dataclass(t):
                keys += [f.name for f in dataclasses.fields(t) if f.name not in keys]
    return keys


def _closest(key: str, accepted: list[str]) -> str:
    """``"; did you mean 'X'?"`` for the accepted key nearest to ``key`` (difflib), else ``""``."""
    near = difflib.get_close_matches(key, accepted, n=1, cutoff=0.6)
    if not near and "." in key:  # a typo in the last part only: compare the last parts within the same group
        head, _, tail = key.rpartition(".")
        same = [a.rpartition(".")[2] for a in accepted if a.rpartition(".")[0] == head]
        near = [f"{head}.{m}" for m in difflib.get_close_matches(tail, same, n=1, cutoff=0.6)]
    return f"; did you mean {near[0]!r}?" if near else ""


def config_error_line(message: str, parser, model_class: str | None = None) -> str:
    """jsonargparse's error ``message`` (many lines, after a page of usage) as one line that names the key and, for
    an unknown one, the closest accepted key. ``parser``: the (sub)command's parser, whose keys are the candidates;
    ``model_class``: the model's class path (its constructor arguments are the candidates under ``model``)."""
    text = message.strip()
    m = re.search(r"Option '([^']+)' is not accepted", text)
    if m:
        cls = re.search(r"class_path '([^']+)'", text)
        class_path = cls.group(1) if cls else model_class
        group = re.match(r'Parser key "([^"]+)"', text)
        where = group.group(1) if group else "model"
        keys = _init_keys(class_path) if class_path else []
        key = m.group(1)
        near = difflib.get_close_matches(key, keys, n=1, cutoff=0.6)
        hint = f"; did you mean {where}.{near[0]}?" if near else (f"; accepted: {', '.join(keys)}" if keys else "")
        return f"{where}.{key} is not an option of {class_path or where}{hint}"
    m = re.search(r"does not accept option '([^']+)'", text) or re.search(r"unrecognized arguments: (.+)", text)
    if m:
        given = [a for a in m.group(1).split() if a.startswith("--")] if "unrecognized" in m.group(0) else [m.group(1)]
        if not given:  # only positional leftovers
            return " ".join(text.split())
        key = given[0].lstrip("-").split("=", 1)[0]
        accepted = _accepted_keys(parser)
        if key.startswith("model.") and model_class:
            init = [f"model.{k}" for k in _init_keys(model_class)]
            accepted = accepted + init + [f"model.init_args.{k.split('.', 1)[1]}" for k in init]
        return f"option {key!r} is not accepted{_closest(key, accepted)}"
    noise = ("Subtypes:", "Errors:", "Given value", "- Expected a <class 'NoneType'>", "Does not validate against")
    kept = [
        ln.strip().lstrip("- ").strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith(noise)
    ]
    return ": ".join(k.rstrip(":") for k in kept) if kept else text


def _ckpt_path_arg(args: list[str]) -> str | None:
    """The value of ``--ckpt_path`` in ``args`` (``--ckpt_path X`` or ``--ckpt_path=X``), else None."""
    for i, a in enumerate(args):
        if a == "--ckpt_path" and i + 1 < len(args):
            return args[i + 1]
        if a.startswith("--ckpt_path="):
            return a.split("=", 1)[1]
    return None


def _class_path(callback) -> str:
    """The class path of a callback as the config holds it (a Namespace before instantiation, or an object)."""
    path = getattr(callback, "class_path", None)
    return str(path) if path is not None else f"{type(callback).__module__}.{type(callback).__name__}"


def _parser_and_model(cli, parser, args) -> tuple:
    """``(parser of the subcommand that ran, the model's class path)`` for :func:`config_error_line`."""
    subs = getattr(cli, "_subcommand_parsers", None) or {}
    argv = [str(a) for a in (sys.argv[1:] if args is None else args)] if not isinstance(args, dict) else []
    name = next((a for a in argv if a in subs), None)
    model = None
    for i, a in enumerate(argv):  # the model class given on the command line or in a config file
        if a in ("--model", "--model.class_path") and i + 1 < len(argv):
            model = argv[i + 1]
        elif a.startswith(("--model=", "--model.class_path=")):
            model = a.split("=", 1)[1]
        elif a in ("--config", "-c") and i + 1 < len(argv) and model is None:
            model = _config_model(argv[i + 1], name) or model
    if model is not None and "." not in model:
        model = f"nik.learn.modules.{model}"
    return (subs.get(name, parser) if name else parser), model


def _config_model(path: str, subcommand: str | None) -> str | None:
    """The model's ``class_path`` in the YAML config ``path``, or None."""
    try:
        import yaml

        data = yaml.safe_load(Path(path).read_text())
    except Exception:  # noqa: BLE001 - only a hint for the error line
        return None
    if isinstance(data, dict) and subcommand in data and isinstance(data[subcommand], dict):
        data = data[subcommand]
    model = data.get("model") if isinstance(data, dict) else None
    return model.get("class_path") if isinstance(model, dict) else (model if isinstance(model, str) else None)


def _cli_class(command: str | None = None):
    from jsonargparse import Namespace
    from lightning.pytorch.cli import LightningCLI

    class NikCLI(LightningCLI):
        def parse_arguments(self, parser, args) -> None:
            """Parse as LightningCLI does; a parse error is one line (:func:`config_error_line`), raised as
            :class:`ConfigError`, not a page of usage. ``--help`` and ``--print_config`` print as before."""
            buf = io.StringIO()
            try:
                with contextlib.redirect_stderr(buf):
                    super().parse_arguments(parser, args)
            except SystemExit as stop:
                text = buf.getvalue()
                if stop.code in (0, None) or "error:" not in text:
                    sys.stderr.write(text)
                    raise
                message = text[text.rindex("\nerror:") + 7 :] if "\nerror:" in text else text.split("error:", 1)[1]
                raise ConfigError(config_error_line(message, *_parser_and_model(self, parser, args))) from None
            sys.stderr.write(buf.getvalue())
            self._check_run()

        def _check_run(self) -> None:
            """Refuse a zero budget and a ``--ckpt_path`` of another robot, before Lightning says anything."""
            sub = self.config.get("subcommand") if "subcommand" in self.config else None
            cfg = self.config[sub] if sub else self.config
            if sub in (None, "fit"):
                check_budget(cfg["trainer"])
            ckpt = cfg.get("ckpt_path")
            if ckpt is not None and str(ckpt) not in _SPECIAL_CKPT:
                check_resume_checkpoint(ckpt, (cfg.get("data") or {}).get("path"))

        def before_instantiate_classes(self) -> None:
            cfg = self.config[self.subcommand] if self.subcommand else self.config
            trainer = cfg["trainer"]
            root = trainer.get("default_root_dir") or "."
            if trainer.get("logger") in (None, True):  # Lightning's default, said explicitly: CSV, no tensorboard
                trainer["logger"] = Namespace(
                    class_path="lightning.pytorch.loggers.CSVLogger", init_args=Namespace(save_dir=str(root))
                )
            if trainer.get("enable_checkpointing") is not False:  # every run keeps <default_root_dir>/last.ckpt
                trainer["callbacks"] = [
                    *(trainer.get("callbacks") or []),
                    Namespace(class_path="nik.learn.callbacks.StableLastCheckpoint", init_args=Namespace()),
                ]
            if trainer.get("enable_progress_bar") is not False and not sys.stdout.isatty():
                callbacks = trainer.get("callbacks") or []
                if not any("ProgressBar" in _class_path(cb) for cb in callbacks):  # bars would fill the log
                    trainer["callbacks"] = [
                        *callbacks,
                        Namespace(class_path="nik.learn.callbacks.EpochLines", init_args=Namespace()),
                    ]
            model_path = str((cfg.get("model") or {}).get("class_path") or "")
            if model_path.rpartition(".")[2] == "DEIK":  # progress lines during DE, a closing line of the phases run
                progress = trainer.get("enable_progress_bar") is not False
                trainer["callbacks"] = [
                    *(trainer.get("callbacks") or []),
                    Namespace(
                        class_path="nik.learn.callbacks.DEProgress",
                        init_args=Namespace(every_s=10.0 if progress else None),
                    ),
                ]

        def instantiate_classes(self) -> None:
            super().instantiate_classes()
            self.model.run_command = command  # what really ran, recorded in the checkpoints

    return NikCLI


def cli_main(args: list[str] | None = None, *, run: bool = True):
    """Run the training CLI with ``args`` (``sys.argv[1:]`` when None); returns the ``LightningCLI``
    (``cli.model``, ``cli.datamodule``, ``cli.trainer``). Lightning is imported here, not at module import.

    Raises:
        CheckpointError, FileNotFoundError: ``--ckpt_path`` names a file that is missing or not a loadable
            nik checkpoint (checked with ``weights_only=True`` before Lightning reads it), or a run of another robot
            than the data's or of another architecture than the model's.
        ConfigError: an unknown option or config key, a bad value, or a zero budget (module docstring).
    """
    import shlex

    from nik.learn.datamodule import IKDataModule
    from nik.learn.modules import IKModule

    argv = sys.argv[1:] if args is None else [str(a) for a in args]
    command = shlex.join(["python", "train.py", *argv])
    ckpt = _ckpt_path_arg(argv)
    if ckpt is not None and ckpt not in _SPECIAL_CKPT:
        check_resume_checkpoint(ckpt)
    _quiet_lightning()
    return _cli_class(command)(
        IKModule,
        IKDataModule,
        subclass_mode_model=True,
        args=args,
        run=run,
        save_config_kwargs={"overwrite": True},
    )


def main(args: list[str] | None = None) -> int:
    """``train.py``'s entry point: :func:`cli_main`, with nik's input errors (a bad ``--ckpt_path``, a
    missing or corrupt dataset) printed as one line ``train.py: error: ...`` and exit status 2."""
    try:
        cli_main(args)
    except (NikError, FileNotFoundError) as err:
        print(f"train.py: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2
    return 0
