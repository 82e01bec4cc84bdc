"""Device paths: every entry point takes a device. The CUDA tests skip without a GPU and run where one is."""

import subprocess
import sys
from pathlib import Path

import pytest
import torch

import nik
from nik.cli import main
from nik.device import resolve_device
from nik.models import IKNet, save_checkpoint

ROOT = Path(__file__).resolve().parents[1]
cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on machines without CUDA")


@pytest.fixture(scope="module")
def kuka():
    return nik.load_robot("kuka_kr")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory, kuka):
    """An (untrained) 6-8-6 net saved as a checkpoint: enough to exercise the device plumbing."""
    q = kuka.sample(200, generator=torch.Generator().manual_seed(0))
    torch.manual_seed(0)
    net = IKNet(kuka, hidden=[8]).fit_normalisation(kuka.fk(q), q)
    return save_checkpoint(net, tmp_path_factory.mktemp("ckpt") / "net.ckpt")


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    from nik.data import generate_dataset

    return generate_dataset("kuka_kr", 300, tmp_path_factory.mktemp("data") / "kuka", seed=0, progress=False)


def test_resolve_device_accepts_cpu_and_refuses_unknown_devices():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device(None) == torch.device("cpu")
    assert resolve_device(torch.device("cpu")) == torch.device("cpu")
    for bad in ("tpu9", "gpu", 3.5):
        with pytest.raises(ValueError, match="device"):
            resolve_device(bad)


@no_cuda
def test_cuda_without_a_gpu_is_a_clear_error(kuka, capsys):
    with pytest.raises(ValueError, match="CUDA is not available"):
        nik.IKSolver(kuka, device="cuda")
    assert main(["solve", "--robot", "kuka_kr", "--pose", "1", "0", "1", "1", "0", "0", "0", "--device", "cuda"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "CUDA is not available" in err


def test_cpu_device_through_solver_cli_and_evaluate(kuka, checkpoint, tiny_data, tmp_path, capsys):
    solver = nik.IKSolver(kuka, checkpoint=checkpoint, refine="lm", device="cpu")
    assert next(solver.net.parameters()).device.type == "cpu"
    code = main(["solve", "--robot", "kuka_kr", "--unit", "mm", "--device", "cpu", "--json"] + _pose_args(kuka))
    assert code == 0, capsys.readouterr().err
    from nik.evaluate import evaluate

    rep = evaluate(kuka, data=tiny_data, n=4, refinements=("lm",), include_pk=False, device="cpu")
    assert rep.device == "cpu"


def _pose_args(robot):
    """``--pose x y z qw qx qy qz`` (mm) of a reachable pose."""
    from nik.poses import matrix_to_quaternion

    q = robot.sample(1, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    T = robot.fk(q)[0]
    quat = matrix_to_quaternion(T[:3, :3])
    return ["--pose", *[f"{v * 1e3:.9f}" for v in T[:3, 3].tolist()], *[f"{v:.12f}" for v in quat.tolist()]]


# -- CUDA ------------------------------------------------------------------------------
@cuda
def test_generate_on_cuda_draws_the_same_joints_and_the_same_poses_to_rounding(tmp_path):
    from nik.data import Compute, generate_dataset, load_dataset

    a = load_dataset(generate_dataset("kuka_kr", 2000, tmp_path / "cpu", seed=1, progress=False))
    b = load_dataset(
        generate_dataset("kuka_kr", 2000, tmp_path / "gpu", seed=1, progress=False, compute=Compute(device="cuda"))
    )
    assert torch.equal(a.q, b.q)
    torch.testing.assert_close(a.pose, b.pose, rtol=0, atol=1e-12)
    assert b.meta["fk"]["device"].startswith("cuda")


@cuda
def test_solver_on_cuda_solves_cuda_poses(kuka, checkpoint):
    solver = nik.IKSolver(kuka, checkpoint=checkpoint, refine="lm", device="cuda")
    q = kuka.sample(64, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    T = kuka.fk(q).cuda()
    res = solver.solve(T)
    assert res.q.device.type == "cuda"
    assert float(res.success.float().mean()) >= 0.95
    lo, hi = kuka.limits.cuda().T
    assert bool(((res.q >= lo - 1e-12) & (res.q <= hi + 1e-12)).all())


@cuda
def test_population_fitness_on_cuda_matches_cpu(kuka):
    from nik.learn import init_population, population_fitness

    g = torch.Generator().manual_seed(4)
    q = kuka.sample(500, generator=g)
    T = kuka.fk(q)
    net = IKNet(kuka, hidden=[8]).fit_normalisation(T, q)
    W = init_population(net, 30, generator=g)
    cpu = population_fitness(net, W, net.features(T), y_target=net.encode(q), T_target=T, loss="both")
    netc = net.cuda()
    Tc, qc = T.cuda(), q.cuda()
    gpu = population_fitness(netc, W.cuda(), netc.features(Tc), y_target=netc.encode(qc), T_target=Tc, loss="both")
    torch.testing.assert_close(gpu.cpu(), cpu, rtol=1e-9, atol=1e-12)


@cuda
@pytest.mark.parametrize("method", ["adam", "de_bp"])
def test_train_on_the_gpu_leaves_a_checkpoint_the_solver_loads(method, tiny_data, tmp_path, kuka):
    extra = ["--model.pop_size", "16", "--model.generations", "2"] if method == "de_bp" else ["--model.hidden", "[16]"]
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        "fit",
        "--config",
        str(ROOT / "configs" / "train" / f"{method}.yaml"),
        "--data.path",
        str(tiny_data),
        "--trainer.default_root_dir",
        str(tmp_path),
        "--trainer.accelerator",
        "gpu",
        "--trainer.devices",
        "1",
        "--trainer.max_epochs",
        "4",
        "--trainer.check_val_every_n_epoch",
        "1",
        "--trainer.enable_progress_bar",
        "false",
        *extra,
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={"PYTHONPATH": str(ROOT), **_env()})
    assert proc.returncode == 0, proc.stderr[-3000:]
    (ckpt,) = tmp_path.rglob("last.ckpt")
    solver = nik.IKSolver(kuka, checkpoint=ckpt, refine="lm", device="cuda")
    q = kuka.sample(8, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    assert solver.solve(kuka.fk(q).cuda()).q.device.type == "cuda"


@cuda
def test_cli_solve_and_evaluate_on_cuda(kuka, checkpoint, tiny_data, tmp_path, capsys):
    assert main(["solve", "--robot", "kuka_kr", "--unit", "mm", "--device", "cuda"] + _pose_args(kuka)) == 0
    out = tmp_path / "eval"
    args = ["evaluate", "--robot", "kuka_kr", "--data", str(tiny_data), "--n", "8", "--device", "cuda"]
    args += ["--checkpoint", str(checkpoint), "--refinements", "lm", "--no-pk", "--out", str(out)]
    assert main(args) == 0, capsys.readouterr().err


def _env():
    import os

    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
