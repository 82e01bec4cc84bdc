"""nik.learn: losses, DE, batched population evaluation, and the Lightning training entry point."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest
import torch

import nik
from nik.learn import (
    DECfg,
    de_minimize,
    init_population,
    joint_mse,
    population_fitness,
    pose_loss,
    set_flat_params,
)
from nik.learn.population import sample_chunk
from nik.models import IKNet, load_checkpoint

ROOT = Path(__file__).resolve().parents[1]
METHODS = ["bp", "adam", "lbfgs", "de", "de_bp"]
pytestmark = [
    pytest.mark.filterwarnings("ignore:LightningCLI's args parameter"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*treespec"),
]
QUIET = ["--trainer.enable_progress_bar", "false", "--trainer.enable_model_summary", "false"]


def _train_cli():
    spec = importlib.util.spec_from_file_location("nik_train_script", ROOT / "train.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.cli_main


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nik.data import generate_dataset

    out = tmp_path_factory.mktemp("data") / "kuka_tiny"
    return generate_dataset("kuka_kr", 500, out, seed=0, progress=False)


@pytest.fixture(scope="module")
def kuka():
    return nik.load_robot("kuka_kr")


def _run(method, dataset, root, *extra):
    args = [
        "fit",
        "--config",
        str(ROOT / "configs" / "train" / f"{method}.yaml"),
        "--data.path",
        str(dataset),
        "--trainer.default_root_dir",
        str(root),
        "--trainer.logger",
        "false",
        *QUIET,
        *extra,
    ]
    return _train_cli()(args)


# -- differential evolution -------------------------------------------------------
def _sphere(x):
    return (x - 0.3).square().sum(-1)


@pytest.mark.parametrize("strategy,jde", [("rand1bin", False), ("current_to_best1bin", False), ("rand1bin", True)])
def test_de_converges_on_a_sphere(strategy, jde):
    g = torch.Generator().manual_seed(0)
    cfg = DECfg(pop_size=30, F=0.6, CR=0.9, strategy=strategy, jde=jde)
    x0 = torch.rand(30, 5, generator=g, dtype=torch.float64) * 4 - 2
    state = de_minimize(_sphere, x0, cfg, 200, generator=g)
    assert state.best_fitness < 1e-6
    torch.testing.assert_close(state.best_x, torch.full((5,), 0.3, dtype=torch.float64), atol=1e-3, rtol=0)
    assert state.generation == 200 and state.evals == 30 * 201


def test_de_respects_bounds():
    # the optimum (0.3 in every coordinate) lies outside the box [-1, 0.1]: DE must stay inside and end on the bound
    g = torch.Generator().manual_seed(1)
    cfg = DECfg(pop_size=20, F=0.9, CR=0.9)
    x0 = torch.rand(20, 4, generator=g, dtype=torch.float64) * 1.1 - 1.0
    lo, hi = torch.tensor(-1.0, dtype=torch.float64), torch.tensor(0.1, dtype=torch.float64)
    seen = []

    def fitness(x):
        seen.append(x.clone())
        return _sphere(x)

    state = de_minimize(fitness, x0, cfg, 150, generator=g, lower=lo, upper=hi)
    every = torch.cat(seen)
    assert float(every.min()) >= -1.0 and float(every.max()) <= 0.1
    torch.testing.assert_close(state.best_x, torch.full((4,), 0.1, dtype=torch.float64), atol=1e-3, rtol=0)


def test_de_config_is_checked():
    with pytest.raises(ValueError, match="strategy"):
        DECfg(strategy="best2exp")
    with pytest.raises(ValueError, match="CR"):
        DECfg(CR=1.5)


def test_des_initial_population_is_pytorchs_default_init_and_selection_never_worsens_anyone(kuka):
    # paper C's DE on the 6-8-6 net: the +-10 bound is a box, not the initial spread (uniform in +-10
    # would saturate tanh); every individual starts like nn.Linear's default init, and greedy selection
    # keeps each individual's fitness non-increasing while the population improves
    g = torch.Generator().manual_seed(6)
    q = kuka.sample(400, generator=g)
    T = kuka.fk(q)
    net = IKNet(kuka, hidden=[8], activation="tanh", representation="rpy").fit_normalisation(T, q)
    W = init_population(net, 220, generator=g)
    w1 = W[:, : 8 * 6]
    assert float(w1.abs().max()) <= 1 / 6**0.5 + 1e-12  # fan_in 6
    pre = torch.einsum("nd,phd->pnh", net.features(T), w1.reshape(220, 8, 6))
    assert float((pre.abs() > 3).double().mean()) < 0.01  # tanh is not saturated
    x, y = net.features(T), net.encode(q)

    def fitness(V):
        return population_fitness(net, V, x, y_target=y)

    from nik.learn import de_init, de_step

    cfg = DECfg()
    state = de_init(W, fitness(W), cfg, lower=torch.tensor(-10.0), upper=torch.tensor(10.0))
    start = state.fitness.clone()
    for _ in range(5):
        before = state.fitness.clone()
        state = de_step(state, fitness, cfg, generator=g)
        assert bool((state.fitness <= before).all())
        torch.testing.assert_close(fitness(state.x), state.fitness)  # the stored fitness is the population's
    assert float(state.fitness.mean()) < float(start.mean())


# -- batched population against a per-individual reference -------------------------
@pytest.mark.parametrize("loss", ["joint", "pose", "both"])
def test_population_fitness_matches_one_network_at_a_time(kuka, loss):
    g = torch.Generator().manual_seed(2)
    q = kuka.sample(300, generator=g)
    T = kuka.fk(q)
    net = IKNet(kuka, hidden=[8, 5]).fit_normalisation(T, q)
    W = init_population(net, 7, generator=g)
    x, y_t = net.features(T), net.encode(q)
    # tiny memory caps force several sample chunks
    got = population_fitness(net, W, x, y_target=y_t, T_target=T, loss=loss, max_elements=7 * 40 * 8, max_fk=7 * 64)
    want = []
    for w in W:
        set_flat_params(net, w)
        with torch.no_grad():
            y = net.raw(x)
            value = 0.0
            if loss != "pose":
                value = value + joint_mse(y, y_t)
            if loss != "joint":
                value = value + pose_loss(net.decode(y), T, kuka, length_scale=net.length_scale)
        want.append(value)
    torch.testing.assert_close(got, torch.stack(want), rtol=1e-5, atol=1e-6)


def test_a_slice_of_the_population_scored_with_the_whole_populations_chunk_gives_the_same_bits(kuka):
    # how DE splits a generation across processes: rank r scores W[slice r] and the pieces are gathered
    g = torch.Generator().manual_seed(3)
    q = kuka.sample(400, generator=g).float()
    T = kuka.fk(q.double()).float()
    net = IKNet(kuka, hidden=[8]).fit_normalisation(T, q).float()
    W = init_population(net, 25, generator=g)
    x, y_t = net.features(T), net.encode(q)
    cap = 25 * 8 * 64  # several sample chunks
    whole = population_fitness(net, W, x, y_target=y_t, max_elements=cap)
    chunk = sample_chunk(net, 25, x.shape[1], max_elements=cap)
    parts = [
        population_fitness(net, W[s], x, y_target=y_t, max_elements=cap, chunk=chunk)
        for s in (slice(0, 13), slice(13, 25))
    ]
    assert torch.equal(torch.cat(parts), whole)


def test_pose_loss_is_zero_at_the_answer_and_geodesic_to_second_order(kuka):
    q = kuka.sample(4, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    T = kuka.fk(q)
    assert float(pose_loss(q, T, kuka, length_scale=1.0)) == 0.0
    # a pure rotation of 1e-3 rad about the tool z axis (last joint: position unchanged)
    dq = torch.zeros_like(q)
    dq[:, -1] = 1e-3
    value = float(pose_loss(q + dq, T, kuka, length_scale=1.0, rot_weight=1.0))
    assert math.isclose(value, 1e-6, rel_tol=1e-3)


# -- Lightning -------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_every_config_runs_fast_dev_run(method, dataset, tmp_path):
    cli = _run(method, dataset, tmp_path, "--trainer.fast_dev_run", "true")
    assert cli.trainer.state.finished
    assert cli.model.net.robot.name == "kuka_kr"


def test_de_bp_hands_des_best_weights_to_bp_and_leaves_a_loadable_checkpoint(dataset, tmp_path, kuka):
    cli = _run(
        "de_bp",
        dataset,
        tmp_path,
        "--model.pop_size",
        "24",
        "--model.generations",
        "4",
        "--trainer.max_epochs",
        "8",
        "--trainer.check_val_every_n_epoch",
        "2",
    )
    model = cli.model
    assert model.de_state.generation == 4
    # BP's first loss is DE's best fitness, on the same (full) batch
    torch.testing.assert_close(model.first_bp_loss, model.history[-1], rtol=1e-5, atol=0)
    ckpts = list(Path(tmp_path).rglob("last.ckpt"))
    assert len(ckpts) == 1
    assert "nik" in torch.load(ckpts[0], weights_only=True)
    net = load_checkpoint(ckpts[0], robot=kuka)
    T = cli.datamodule.test_data[0]
    assert torch.equal(net.predict(T), model.net.predict(T))
    with pytest.raises(nik.CheckpointError, match="puma560"):
        load_checkpoint(ckpts[0], robot="puma560")


@pytest.mark.parametrize("method, generations", [("de", 4), ("de_bp", 3)])
def test_max_steps_counts_de_generations(method, dataset, tmp_path, generations):
    # 5 steps: the initial population, then generations (de_bp: 3 generations, then 1 BP step);
    # max_epochs only caps the old behaviour, where DE generations did not count as steps
    cli = _run(
        method,
        dataset,
        tmp_path,
        *("--model.pop_size", "8", "--model.generations", "3" if method == "de_bp" else "null"),
        *("--trainer.max_steps", "5", "--trainer.max_epochs", "30", "--trainer.check_val_every_n_epoch", "5"),
    )
    assert cli.trainer.global_step == 5
    assert cli.model.de_state.generation == generations
    assert cli.trainer.current_epoch == 5
    if method == "de_bp":
        assert cli.model.first_bp_loss is not None


@pytest.mark.parametrize("method", ["de", "adam"])
def test_same_seed_same_run(method, dataset, tmp_path):
    extra = ["--trainer.max_epochs", "3", "--trainer.check_val_every_n_epoch", "3"]
    if method == "de":
        extra += ["--model.pop_size", "16", "--model.jde", "true"]
    else:
        extra += ["--model.hidden", "[16]"]
    runs = [_run(method, dataset, tmp_path / str(i), *extra).model for i in range(2)]
    for a, b in zip(runs[0].net.parameters(), runs[1].net.parameters(), strict=True):
        assert torch.equal(a, b)
    if method == "de":
        assert runs[0].history == runs[1].history
        assert torch.equal(runs[0].de_state.x, runs[1].de_state.x)


def test_nik_compare_is_registered_with_the_cli():
    from nik.cli import build_parser

    args = build_parser().parse_args(["compare", "--data", "data/x", "--budget", "5", "--methods", "de", "bp"])
    assert args.command == "compare" and args.budget == 5.0 and args.methods == ["de", "bp"]
    assert callable(args.func)


def test_threads_callback_sets_torch_threads_for_the_fit_and_shares_cores_among_ddp_ranks():
    import os

    import lightning as L

    from nik.learn.callbacks import Threads

    before = torch.get_num_threads()
    one = L.Trainer(accelerator="cpu", devices=1, logger=False, enable_checkpointing=False)
    cb = Threads(1)
    cb.setup(one, None, "fit")
    assert torch.get_num_threads() == 1
    cb.teardown(one, None, "fit")
    assert torch.get_num_threads() == before
    assert Threads().chosen(one) is None  # one process: torch's own choice
    two = L.Trainer(accelerator="cpu", devices=2, strategy="ddp", logger=False, enable_checkpointing=False)
    assert Threads().chosen(two) == max(1, (os.cpu_count() or 1) // 2)
    with pytest.raises(ValueError, match="positive integer"):
        Threads(0)


# -- DE says what it does (issue 50): progress lines during DE, a closing line of the phases that ran ---------------
def _de_lines(text: str) -> list[str]:
    return [ln[len("train.py: ") :] for ln in text.splitlines() if ln.startswith("train.py: ")]


def test_de_bp_prints_progress_and_the_phases_it_ran(dataset, tmp_path, capsys):
    progress = ["--trainer.enable_model_summary", "false", "--trainer.logger", "false"]  # the progress bar stays on
    cli = _train_cli()(
        [
            *("fit", "--config", str(ROOT / "configs/train/de_bp.yaml"), "--data.path", str(dataset)),
            *("--trainer.default_root_dir", str(tmp_path), *progress),
            *("--model.pop_size", "8", "--model.generations", "3"),
            *("--trainer.max_epochs", "6", "--trainer.check_val_every_n_epoch", "3"),
        ]
    )
    lines = _de_lines(capsys.readouterr().err)
    n_train = cli.datamodule.train_data[0].shape[0]
    first = [ln for ln in lines if ln.startswith("DE generation 1/3: ")]
    assert len(first) == 1, lines
    assert "s a generation" in first[0] and f"8 networks x {n_train:,} samples" in first[0] and "then BP" in first[0]
    assert any(ln.startswith("DE done: 3 generations") for ln in lines), lines
    # 6 steps: the initial population and 3 generations, then 2 BP steps
    assert cli.trainer.global_step == 6 and cli.model.de_state.generation == 3
    assert lines[-1].startswith("phases run: DE 3 of 3 generations (")
    assert "then BP 2 steps" in lines[-1] and lines[-1].endswith("stopped by max_epochs (6)")


def test_de_bp_stopped_by_max_time_during_de_says_that_bp_never_ran(dataset, tmp_path, capsys):
    cli = _run(
        "de_bp",
        dataset,
        tmp_path,
        *("--model.pop_size", "8", "--model.generations", "1000000"),
        *("--trainer.max_time", "00:00:00:01", "--trainer.max_epochs", "-1"),
    )
    lines = _de_lines(capsys.readouterr().err)
    g = cli.model.de_state.generation
    assert 0 < g < 1_000_000 and cli.model.first_bp_loss is None
    assert len(lines) == 1, lines  # progress lines off with the progress bar (QUIET); the closing line always
    assert lines[-1].startswith(f"phases run: DE {g} of 1000000 generations (")
    assert "BP did not run" in lines[-1] and lines[-1].endswith("stopped by max_time (1.0 s)")
    from nik.learn.callbacks import DEProgress

    (cb,) = [c for c in cli.trainer.callbacks if isinstance(c, DEProgress)]
    assert cb.summary == lines[-1]


def test_de_progress_warns_when_max_time_ends_before_bp(dataset, tmp_path, capsys):
    _train_cli()(
        [
            *("fit", "--config", str(ROOT / "configs/train/de_bp.yaml"), "--data.path", str(dataset)),
            *("--trainer.default_root_dir", str(tmp_path), "--trainer.logger", "false"),
            *("--trainer.enable_model_summary", "false"),
            *("--model.pop_size", "8", "--model.generations", "1000000"),
            *("--trainer.max_time", "00:00:00:01", "--trainer.max_epochs", "-1"),
        ]
    )
    lines = _de_lines(capsys.readouterr().err)
    assert lines[0].startswith("DE generation 1/1000000: ") and lines[0].endswith(
        "max_time (1.0 s) ends before BP starts"
    )


# -- module settings: a dataclass or keywords ---------------------------------------
def test_module_settings_come_as_one_dataclass_or_as_keywords_in_at_most_twelve_parameters():
    import inspect

    from nik.learn.modules import DEIK, DEIKCfg, GradientIK, GradientIKCfg, IKModule

    for cls in (IKModule, GradientIK, DEIK):
        assert len(inspect.signature(cls.__init__).parameters) <= 12, cls
    a = GradientIK(GradientIKCfg(hidden=(16,), lr=0.01), optimizer="sgd")  # a keyword overrides the dataclass
    b = GradientIK(hidden=(16,), lr=0.01, optimizer="sgd")
    assert dict(a.hparams) == dict(b.hparams)
    # flat plain values, so a checkpoint's hyper_parameters load with torch.load(weights_only=True)
    assert set(a.hparams) == set(GradientIKCfg.__dataclass_fields__)
    assert all(isinstance(v, (str, int, float, tuple)) for v in a.hparams.values())
    assert (a.hparams.hidden, a.hparams.lr, a.hparams.optimizer, a.hparams.schedule) == ((16,), 0.01, "sgd", "none")
    d = DEIK(DEIKCfg(pop_size=12, generations=3, bp=True), F=0.4)
    assert (d.cfg.pop_size, d.cfg.F, d.hparams.bp, d.hparams.generations) == (12, 0.4, True, 3)
    with pytest.raises(TypeError, match="hiden"):
        GradientIK(hiden=(16,))
    with pytest.raises(ValueError, match="optimizer"):
        GradientIK(optimizer="rmsprop")
    with pytest.raises(ValueError, match="generations"):
        DEIK(bp=True, generations=None)


def test_checkpoints_with_flat_keyword_hyperparameters_load(tmp_path):
    """Checkpoints written before the settings dataclasses (hyper_parameters: the keywords, flat; LightningCLI's
    runs add _class_path and _instantiator) build the same module."""
    import lightning

    from nik.learn.modules import DEIK, GradientIK

    old = {"hidden": [16, 16], "activation": "silu", "representation": "rot6d", "output": "angles", "loss": "pose"}
    old |= {"rot_weight": 0.5, "pose_weight": 1.0, "optimizer": "adam", "lr": 0.002, "momentum": 0.0}
    old |= {"weight_decay": 0.0, "schedule": "cosine", "min_lr_ratio": 0.01, "lbfgs_max_iter": 20, "lbfgs_history": 50}
    path = tmp_path / "old.ckpt"
    torch.save({"state_dict": {}, "hyper_parameters": old, "pytorch-lightning_version": lightning.__version__}, path)
    m = GradientIK.load_from_checkpoint(path)
    assert (list(m.hparams.hidden), m.hparams.loss, m.hparams.lr, m.hparams.rot_weight) == (
        [16, 16],
        "pose",
        0.002,
        0.5,
    )
    cli = {"hidden": [8], "pop_size": 7, "bp": True, "generations": 2}
    cli |= {"_class_path": "nik.learn.modules.DEIK", "_instantiator": "lightning.pytorch.cli.instantiate_module"}
    torch.save({"state_dict": {}, "hyper_parameters": cli, "pytorch-lightning_version": lightning.__version__}, path)
    d = DEIK.load_from_checkpoint(path)
    assert isinstance(d, DEIK) and (d.cfg.pop_size, d.hparams.generations) == (7, 2)
