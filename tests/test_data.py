"""Dataset generation, storage and loading (nik.data): correctness, reproducibility, safety."""

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.testing import assert_close

import nik
from nik.data import Compute, Sampling, branch_classifier, branch_name, generate_dataset, load_dataset, resolve_ranges
from nik.data import generate as gen_mod
from nik.data.storage import AtomicDirectory
from nik.errors import DatasetError

REPO = Path(__file__).resolve().parents[1]
KUKA_RANGES = REPO / "configs" / "robots" / "kuka_kr_training_ranges.yaml"


@pytest.fixture(scope="module")
def kuka():
    return nik.load_robot("kuka_kr")


@pytest.fixture(scope="module")
def small(tmp_path_factory, kuka):
    """One small float64 dataset shared by the read-only tests."""
    out = tmp_path_factory.mktemp("ds") / "kuka_small"
    generate_dataset(kuka, 5000, out, seed=7, progress=False, fsync=False, compute=Compute(chunk_size=1500))
    return out


def _arrays(path):
    ds = load_dataset(path)
    return ds.q.clone(), ds.pose.clone(), None if ds.branch is None else ds.branch.clone()


def _leftovers(folder: Path, name: str):
    return [p.name for p in folder.iterdir() if p.name.startswith(f".{name}.")]


# ---------------------------------------------------------------------------
# Content
# ---------------------------------------------------------------------------
def test_fk_of_stored_q_equals_stored_pose(small, kuka):
    ds = load_dataset(small)
    assert ds.q.shape == (5000, 6) and ds.pose.shape == (5000, 4, 4)
    assert ds.q.dtype == torch.float64
    assert_close(kuka.fk(ds.q.clone()), ds.pose, atol=1e-12, rtol=0)


def test_float32_pose_is_rounded_fk_of_the_stored_joints(tmp_path, kuka):
    out = generate_dataset(kuka, 3000, tmp_path / "f32", seed=1, dtype="float32", progress=False, fsync=False)
    ds = load_dataset(out)
    assert ds.q.dtype == torch.float32 and ds.pose.dtype == torch.float32
    exact = kuka.fk(ds.q.double())  # the stored joints, exactly, in float64
    assert_close(ds.pose.double(), exact, atol=2e-7, rtol=0)  # one rounding to float32
    assert bool(kuka.within_limits(ds.q).all())


def test_every_q_inside_the_limits(small, kuka):
    ds = load_dataset(small)
    lo, hi = kuka.limits[:, 0], kuka.limits[:, 1]
    assert bool(((ds.q >= lo) & (ds.q <= hi)).all())
    # and they fill the range: uniform samples come within 2 % of each end
    span = hi - lo
    assert bool((ds.q.min(0).values < lo + 0.02 * span).all()) and bool((ds.q.max(0).values > hi - 0.02 * span).all())


@pytest.mark.parametrize("sampler", ["uniform", "sobol"])
def test_every_q_inside_training_ranges_file(tmp_path, kuka, sampler):
    out = generate_dataset(
        kuka, 4000, tmp_path / "c", progress=False, fsync=False, sampling=Sampling(ranges=KUKA_RANGES, sampler=sampler)
    )
    ds = load_dataset(out)
    rng = (
        torch.tensor([[-180, 180], [-120, 35], [-120, 120], [-180, 180], [-120, 120], [-180, 180]], dtype=torch.float64)
        * math.pi
        / 180
    )
    assert bool(((ds.q >= rng[:, 0]) & (ds.q <= rng[:, 1])).all())
    assert_close(torch.tensor(ds.meta["ranges"]["radians"], dtype=torch.float64), rng)
    assert ds.meta["sampler"] == sampler


def test_sobol_is_more_even_than_uniform(tmp_path, kuka):
    """Scrambled Sobol points fill the box more evenly: per-joint histogram counts vary less."""
    spreads = {}
    for sampler in ("uniform", "sobol"):
        ds = load_dataset(
            generate_dataset(
                kuka, 4096, tmp_path / sampler, progress=False, fsync=False, sampling=Sampling(sampler=sampler)
            )
        )
        lo, hi = kuka.limits[:, 0], kuka.limits[:, 1]
        u = ((ds.q - lo) / (hi - lo)).numpy()
        counts = np.stack([np.histogram(u[:, j], bins=64, range=(0, 1))[0] for j in range(6)])
        spreads[sampler] = counts.std()
    assert spreads["sobol"] < 0.3 * spreads["uniform"]


def test_meta_records_provenance(small, kuka):
    meta = load_dataset(small).meta
    assert nik.data.load_dataset is load_dataset  # reachable after a plain ``import nik``
    assert meta["robot"]["name"] == "kuka_kr"
    assert meta["robot"]["definition_hash"] == kuka.definition_hash
    assert nik.Robot.from_definition(meta["robot"]["definition"]).definition_hash == kuka.definition_hash
    assert meta["seed"] == 7 and meta["sampler"] == "uniform" and meta["nik_version"] == nik.__version__
    assert meta["split_sizes"] == {"train": 4000, "val": 500, "test": 500}
    assert set(meta["files"]) == {"q.npy", "pose.npy", "branch.npy"}
    assert all(len(f["sha256"]) == 64 for f in meta["files"].values())
    assert "created" in meta and meta["dtype"] == "float64"
    assert_close(torch.tensor(meta["ranges"]["radians"], dtype=torch.float64), kuka.limits)


def test_loading_is_lazy_memory_mapped(small):
    ds = load_dataset(small)
    q_np = np.load(small / "q.npy", mmap_mode="r")
    assert isinstance(q_np, np.memmap)
    assert not ds.q.is_contiguous() or ds.q.data_ptr() != 0  # a tensor view on the map
    assert ds.robot.name == "kuka_kr"
    loaded = load_dataset(small, mmap=False)
    assert torch.equal(loaded.q, ds.q)


# ---------------------------------------------------------------------------
# Reproducibility
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("sampler", ["uniform", "sobol"])
def test_same_seed_same_arrays_across_chunk_and_block_boundaries(tmp_path, kuka, sampler, monkeypatch):
    monkeypatch.setattr(gen_mod, "BLOCK_SIZE", 4096)  # several randomness blocks in a tiny dataset
    ref = None
    for chunk in (20000, 4096, 777):
        out = generate_dataset(
            kuka,
            12000,
            tmp_path / f"c{chunk}",
            seed=3,
            progress=False,
            fsync=False,
            sampling=Sampling(sampler=sampler, block_size=4096),
            compute=Compute(chunk_size=chunk),
        )
        arrays = _arrays(out)
        if ref is None:
            ref = arrays
        else:
            for a, b in zip(arrays, ref, strict=True):
                assert torch.equal(a, b), f"chunk {chunk} differs"
    other = _arrays(
        generate_dataset(
            kuka,
            12000,
            tmp_path / "s4",
            seed=4,
            progress=False,
            fsync=False,
            sampling=Sampling(block_size=4096, sampler=sampler),
        )
    )
    assert not torch.equal(other[0], ref[0])


def test_same_arrays_with_one_or_two_threads(tmp_path, kuka):
    before = torch.get_num_threads()
    arrays = []
    for threads in (1, 2):
        out = generate_dataset(
            kuka, 20000, tmp_path / f"t{threads}", seed=5, progress=False, fsync=False, compute=Compute(threads=threads)
        )
        arrays.append(_arrays(out))
    assert torch.get_num_threads() == before  # restored
    for a, b in zip(*arrays, strict=True):
        assert torch.equal(a, b)


def test_prefix_property_larger_n_extends_smaller(tmp_path, kuka):
    a = _arrays(generate_dataset(kuka, 3000, tmp_path / "a", seed=2, progress=False, fsync=False))
    b = _arrays(generate_dataset(kuka, 5000, tmp_path / "b", seed=2, progress=False, fsync=False))
    assert torch.equal(a[0], b[0][:3000])


def test_splits_disjoint_and_covering(small):
    ds = load_dataset(small)
    idx = {name: ds.indices(name) for name in ("train", "val", "test")}
    allidx = torch.cat(list(idx.values()))
    assert torch.equal(torch.sort(allidx).values, torch.arange(len(ds)))  # covering, no duplicates
    assert len(ds.train) == 4000 and len(ds.val) == 500 and len(ds.test) == 500
    assert torch.equal(ds.val.q, ds.q[idx["val"]]) and torch.equal(ds.test.pose, ds.pose[idx["test"]])
    assert torch.equal(ds.train.branch, ds.branch[:4000])


def test_split_fractions_validated(tmp_path, kuka):
    with pytest.raises(ValueError, match="leaves no training"):
        generate_dataset(
            kuka, 10, tmp_path / "x", progress=False, sampling=Sampling(val_fraction=0.5, test_fraction=0.5)
        )
    with pytest.raises(ValueError, match="val_fraction"):
        generate_dataset(kuka, 10, tmp_path / "x", progress=False, sampling=Sampling(val_fraction=-0.1))
    out = generate_dataset(
        kuka, 10, tmp_path / "y", progress=False, fsync=False, sampling=Sampling(val_fraction=0, test_fraction=0)
    )
    assert load_dataset(out).splits == {"train": (0, 10), "val": (10, 10), "test": (10, 10)}


# ---------------------------------------------------------------------------
# Safety
# ---------------------------------------------------------------------------
def test_existing_output_is_not_overwritten(small):
    before = {p.name: p.stat().st_mtime_ns for p in small.iterdir()}
    with pytest.raises(FileExistsError, match="overwrite"):
        generate_dataset("kuka_kr", 100, small, seed=99, progress=False)
    assert {p.name: p.stat().st_mtime_ns for p in small.iterdir()} == before
    assert _leftovers(small.parent, small.name) == []


def test_overwrite_replaces_atomically(tmp_path, kuka):
    out = generate_dataset(kuka, 100, tmp_path / "d", seed=1, progress=False, fsync=False)
    old = _arrays(out)
    generate_dataset(kuka, 200, out, seed=2, overwrite=True, progress=False, fsync=False)
    new = load_dataset(out)
    assert len(new) == 200 and new.meta["seed"] == 2 and not torch.equal(new.q[:100], old[0])
    assert _leftovers(tmp_path, "d") == []


def test_overwrite_refuses_a_folder_that_is_not_a_dataset(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(FileExistsError, match="not a nik dataset"):
        generate_dataset("kuka_kr", 10, tmp_path / "mine", overwrite=True, progress=False)
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "precious"


def test_failed_overwrite_keeps_the_old_dataset(tmp_path, kuka, monkeypatch):
    out = generate_dataset(kuka, 3000, tmp_path / "d", seed=1, progress=False, fsync=False)
    old = _arrays(out)
    robot = nik.load_robot("kuka_kr")
    monkeypatch.setattr(robot, "fk", _failing_fk(robot.fk, fail_at=2))
    with pytest.raises(RuntimeError, match="simulated"):
        generate_dataset(
            robot,
            3000,
            out,
            seed=2,
            overwrite=True,
            progress=False,
            sampling=Sampling(block_size=1000),
            compute=Compute(chunk_size=1000),
        )
    for a, b in zip(_arrays(out), old, strict=True):
        assert torch.equal(a, b)
    assert _leftovers(tmp_path, "d") == []


def _failing_fk(fk, fail_at):
    calls = {"n": 0}

    def wrapped(q, **kw):
        calls["n"] += 1
        if calls["n"] == fail_at:
            raise RuntimeError("simulated crash in chunk 2")
        return fk(q, **kw)

    return wrapped


def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    robot = nik.load_robot("kuka_kr")
    monkeypatch.setattr(robot, "fk", _failing_fk(robot.fk, fail_at=2))
    with pytest.raises(RuntimeError, match="simulated"):
        generate_dataset(
            robot,
            5000,
            tmp_path / "d",
            progress=False,
            sampling=Sampling(block_size=1000),
            compute=Compute(chunk_size=1000),
        )
    assert not (tmp_path / "d").exists()
    assert list(tmp_path.iterdir()) == []


def test_keyboard_interrupt_leaves_nothing(tmp_path, monkeypatch):
    robot = nik.load_robot("kuka_kr")

    def interrupt(q, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(robot, "fk", interrupt)
    with pytest.raises(KeyboardInterrupt):
        generate_dataset(
            robot,
            5000,
            tmp_path / "d",
            progress=False,
            sampling=Sampling(block_size=1000),
            compute=Compute(chunk_size=1000),
        )
    assert list(tmp_path.iterdir()) == []


def test_killed_run_leaves_no_final_dir_and_next_run_cleans_up(tmp_path):
    """A process killed outright (SIGKILL) mid-write: no final directory; the next run removes its temporary."""
    script = (
        "import nik, sys\n"
        "from nik.data import Compute, Sampling, generate_dataset\n"
        "robot = nik.load_robot('kuka_kr')\n"
        "fk = robot.fk\n"
        "calls = [0]\n"
        "def slow(q, **kw):\n"
        "    calls[0] += 1\n"
        "    if calls[0] == 2:\n"
        "        import os, signal; os.kill(os.getpid(), signal.SIGKILL)\n"
        "    return fk(q, **kw)\n"
        "robot.fk = slow\n"
        f"generate_dataset(robot, 5000, {str(tmp_path / 'd')!r}, sampling=Sampling(block_size=1000), "
        "compute=Compute(chunk_size=1000), progress=False)\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == -9, proc.stderr
    assert not (tmp_path / "d").exists()
    stale = _leftovers(tmp_path, "d")
    assert len(stale) == 1 and ".tmp-" in stale[0]
    generate_dataset("kuka_kr", 100, tmp_path / "d", progress=False, fsync=False)
    assert _leftovers(tmp_path, "d") == []
    assert len(load_dataset(tmp_path / "d")) == 100


def test_temporaries_of_live_processes_are_kept(tmp_path):
    live = tmp_path / f".d.tmp-{os.getppid()}-abcd"  # our parent process is alive
    live.mkdir()
    AtomicDirectory(tmp_path / "d").cleanup_stale()
    assert live.exists()


def test_swap_interrupted_between_renames_is_restored(tmp_path, kuka):
    out = generate_dataset(kuka, 50, tmp_path / "d", progress=False, fsync=False)
    old = _arrays(out)
    os.rename(out, tmp_path / ".d.old-999999999-dead")  # as if killed after moving the old one aside
    AtomicDirectory(tmp_path / "d").cleanup_stale()
    assert torch.equal(_arrays(out)[0], old[0])


def test_loading_a_dataset_killed_between_the_renames_of_an_overwrite_puts_the_old_copy_back(tmp_path, kuka):
    out = generate_dataset(kuka, 50, tmp_path / "d", progress=False, fsync=False)
    old = _arrays(out)
    os.rename(out, tmp_path / ".d.old-999999999-dead")
    assert torch.equal(load_dataset(out).q, old[0])


@pytest.mark.parametrize("damage", ["truncate", "flip_byte", "delete"])
@pytest.mark.parametrize("fname", ["q.npy", "pose.npy", "branch.npy"])
def test_corruption_is_detected_naming_the_file(tmp_path, kuka, damage, fname):
    out = generate_dataset(kuka, 2000, tmp_path / "d", progress=False, fsync=False)
    f = out / fname
    data = bytearray(f.read_bytes())
    if damage == "truncate":
        f.write_bytes(bytes(data[: len(data) - 100]))
    elif damage == "flip_byte":
        data[len(data) // 2] ^= 0x01
        f.write_bytes(bytes(data))
    else:
        f.unlink()
    with pytest.raises(DatasetError, match=fname.replace(".", r"\.")):
        load_dataset(out)


def test_altered_metadata_checksum_detected(tmp_path, kuka):
    out = generate_dataset(kuka, 200, tmp_path / "d", progress=False, fsync=False)
    meta = json.loads((out / "meta.json").read_text())
    meta["files"]["q.npy"]["sha256"] = "0" * 64
    (out / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="checksum"):
        load_dataset(out)
    assert len(load_dataset(out, verify=False)) == 200


def test_robot_mismatch_refused_naming_both(small):
    with pytest.raises(DatasetError, match=r"kuka_kr.*puma560"):
        load_dataset(small, robot="puma560")
    assert len(load_dataset(small, robot="kuka_kr")) == 5000


def test_not_a_dataset(tmp_path):
    with pytest.raises(DatasetError, match="not found"):
        load_dataset(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="meta.json"):
        load_dataset(tmp_path / "empty")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n": 0}, "positive"),
        ({"n": -5}, "positive"),
        ({"robot": "no_such_robot"}, "unknown robot"),
        ({"sampling": Sampling(ranges=[[0, 1]] * 5)}, "5 ranges"),
        ({"sampling": Sampling(ranges=[[-4, 4]] * 6)}, "outside the joint limits"),
        ({"sampling": Sampling(ranges=[[1, 0]] * 6)}, "lo < hi"),
        ({"sampling": Sampling(sampler="halton")}, "sampler"),
        ({"sampling": {"sampler": "sobol"}}, "sampling: expected a nik.data.Sampling"),
        ({"dtype": "float16"}, "dtype"),
        ({"branch": 9}, "0..7"),
    ],
)
def test_bad_arguments(tmp_path, kwargs, match):
    args = {"robot": "kuka_kr", "n": 10, "out": tmp_path / "d", "progress": False} | kwargs
    with pytest.raises(ValueError, match=match):
        generate_dataset(args.pop("robot"), args.pop("n"), args.pop("out"), **args)
    assert list(tmp_path.iterdir()) == []


def test_ranges_file_errors(tmp_path, kuka):
    bad = tmp_path / "r.yaml"
    bad.write_text("angles: deg\nranges:\n  - [-180, 180]\n")
    with pytest.raises(ValueError, match="1 ranges"):
        resolve_ranges(kuka, bad)
    bad.write_text("angles: deg\nranges: [[-190, 180], [0, 1], [0, 1], [0, 1], [0, 1], [0, 1]]\n")
    with pytest.raises(ValueError, match="joint 1 .* outside"):
        resolve_ranges(kuka, bad)
    bad.write_text("angels: deg\nranges: []\n")
    with pytest.raises(ValueError, match="unknown field"):
        resolve_ranges(kuka, bad)
    with pytest.raises(FileNotFoundError):
        resolve_ranges(kuka, tmp_path / "missing.yaml")
    rng, _ = resolve_ranges(kuka, KUKA_RANGES)
    assert_close(rng[1], torch.tensor([-120.0, 35.0], dtype=torch.float64) * math.pi / 180)


def test_unwritable_output_folder(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises((NotADirectoryError, PermissionError)):
        generate_dataset("kuka_kr", 10, blocker / "d", progress=False)


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_read_only_output_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(PermissionError, match="not writable"):
            generate_dataset("kuka_kr", 10, ro / "d", progress=False)
    finally:
        ro.chmod(0o700)


# ---------------------------------------------------------------------------
# Branch labels
# ---------------------------------------------------------------------------
def test_which_robots_have_a_classifier():
    assert branch_classifier(nik.load_robot("puma560")) is not None
    assert branch_classifier(nik.load_robot("kuka_kr")) is not None
    assert branch_classifier(nik.load_robot("ur5")) is None  # no spherical wrist
    assert branch_classifier(nik.load_robot("panda")) is None  # 7 joints
    assert branch_name(0) == "front/up/noflip" and branch_name(7) == "back/down/flip"


def _dls_ik(robot, T, q0, iters=80):
    """Damped least squares IK from many starts at once (test reference, independent of nik.data)."""
    q = q0.clone()
    eye = torch.eye(6, dtype=q.dtype)
    for _ in range(iters):
        Tc, J = robot.fk_and_jacobian(q)
        Re = T[:3, :3] @ Tc[:, :3, :3].transpose(-1, -2)
        er = 0.5 * torch.stack([Re[:, 2, 1] - Re[:, 1, 2], Re[:, 0, 2] - Re[:, 2, 0], Re[:, 1, 0] - Re[:, 0, 1]], -1)
        e = torch.cat([T[:3, 3] - Tc[:, :3, 3], er], -1)
        JT = J.transpose(-1, -2)
        q = q + (JT @ torch.linalg.solve(J @ JT + 1e-4 * eye, e.unsqueeze(-1))).squeeze(-1)
    return q, (robot.fk(q) - T).abs().amax((-1, -2))


@pytest.mark.parametrize("name, seed", [("puma560", 1), ("kuka_kr", 4)])
def test_the_eight_ik_solutions_of_a_pose_get_eight_distinct_labels(name, seed):
    robot = nik.load_robot(name)
    clf = branch_classifier(robot)
    g = torch.Generator().manual_seed(seed)
    T = robot.fk(robot.sample(1, generator=g, dtype=torch.float64))[0]
    q0 = (torch.rand(160, 6, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    q, err = _dls_ik(robot, T, q0)
    sols = q[err < 1e-9]
    assert sols.shape[0] > 40
    labels = clf(sols)
    assert sorted(set(labels.tolist())) == list(range(8))
    for k in range(8):  # one solution per label (equal modulo 2 pi)
        s = sols[labels == k]
        diff = torch.remainder(s - s[0] + math.pi, 2 * math.pi) - math.pi
        assert diff.abs().max() < 1e-6


def test_wrist_bit_is_the_sign_of_sin_q5():
    for name in ("puma560", "kuka_kr"):
        robot = nik.load_robot(name)
        q = robot.sample(5000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
        labels = branch_classifier(robot)(q)
        assert torch.equal((labels >> 2) & 1, (torch.sin(q[:, 4]) < 0).to(torch.uint8))


@pytest.mark.parametrize("name", ["puma560", "kuka_kr"])
def test_label_constant_under_small_perturbations_away_from_boundaries(name):
    robot = nik.load_robot(name)
    clf = branch_classifier(robot)
    g = torch.Generator().manual_seed(2)
    q = robot.sample(4000, generator=g, dtype=torch.float64)
    comp = clf.components(q)
    far = (comp["t"].abs() > 0.05) & (comp["u"].abs() > 0.01) & (comp["w"].abs() > 0.05)
    q = q[far]
    assert q.shape[0] > 1000
    base = clf(q)
    for _ in range(3):
        dq = (torch.rand(q.shape, generator=g, dtype=torch.float64) * 2 - 1) * 1e-3  # +-0.06 deg
        assert torch.equal(clf(q + dq), base)
    # and crossing the wrist singularity flips exactly the wrist bit
    flipped = q.clone()
    flipped[:, 4] = -flipped[:, 4]
    assert torch.equal(clf(flipped) ^ base, torch.full_like(base, 4))


def test_stored_branch_labels_and_branch_filter(tmp_path):
    puma = nik.load_robot("puma560")
    out = generate_dataset(puma, 3000, tmp_path / "all", seed=1, progress=False, fsync=False)
    ds = load_dataset(out)
    assert torch.equal(ds.branch, branch_classifier(puma)(ds.q))
    assert sum(ds.meta["branch"]["counts"]) == 3000
    assert ds.meta["branch"]["counts"] == torch.bincount(ds.branch.long(), minlength=8).tolist()
    ref = None
    for chunk in (5000, 1234):
        out = generate_dataset(
            puma,
            2000,
            tmp_path / f"b3_{chunk}",
            seed=1,
            branch=3,
            progress=False,
            fsync=False,
            compute=Compute(chunk_size=chunk),
        )
        ds3 = load_dataset(out)
        assert len(ds3) == 2000 and bool((ds3.branch == 3).all())
        assert_close(puma.fk(ds3.q.clone()), ds3.pose, atol=1e-12, rtol=0)
        assert ds3.meta["branch"]["filter"] == 3 and ds3.meta["branch"]["candidates"] > 2000
        if ref is None:
            ref = ds3.q.clone()
        else:
            assert torch.equal(ds3.q, ref)
    # the kept samples are exactly the branch-3 samples of the unfiltered stream, in order
    stream = _arrays(generate_dataset(puma, 12000, tmp_path / "big", seed=1, progress=False, fsync=False))
    in_stream = stream[0][stream[2] == 3]
    assert in_stream.shape[0] > 1000
    assert torch.equal(in_stream, ref[: in_stream.shape[0]])


def test_branch_filter_needs_a_classifier(tmp_path):
    with pytest.raises(ValueError, match="no IK branch classification"):
        generate_dataset("ur5", 10, tmp_path / "d", branch=0, progress=False)
    out = generate_dataset("ur5", 10, tmp_path / "u", progress=False, fsync=False)
    ds = load_dataset(out)
    assert ds.branch is None and ds.meta["branch"] is None


@pytest.mark.parametrize("name", ["puma560", "kuka_kr", "rebot_v_6r"])
def test_fast_label_components_match_the_geometric_definition(name):
    robot = nik.load_robot(name)
    clf = branch_classifier(robot)
    q = robot.sample(3000, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    fast, ref = clf.components(q), clf.components_reference(q)
    for k in ("t", "u", "w"):
        assert_close(fast[k], ref[k], atol=1e-12, rtol=0)
    bits = (ref["t"] < 0).to(torch.uint8) + 2 * (ref["u"] < 0).to(torch.uint8) + 4 * (ref["w"] < 0).to(torch.uint8)
    assert torch.equal(clf(q), bits)


@pytest.mark.long
def test_compiled_fk_is_reproducible_across_chunks_and_threads(tmp_path, kuka):
    """FK runs on fixed output blocks, so even the compiled kernel sees identical batches."""
    arrays = []
    for threads, chunk in ((2, 20000), (1, 777)):
        out = generate_dataset(
            kuka,
            9000,
            tmp_path / f"c{chunk}",
            seed=6,
            progress=False,
            fsync=False,
            sampling=Sampling(block_size=4096),
            compute=Compute(chunk_size=chunk, compiled=True, threads=threads),
        )
        arrays.append(_arrays(out))
    for a, b in zip(*arrays, strict=True):
        assert torch.equal(a, b)
    assert load_dataset(tmp_path / "c777").meta["fk"]["compiled"] is True
    assert_close(kuka.fk(arrays[0][0]), arrays[0][1], atol=1e-12, rtol=0)


def test_dataset_of_an_arm_with_a_prismatic_joint(tmp_path):
    robot = nik.load_robot("stanford")
    assert branch_classifier(robot) is None  # branch labels are for PUMA-like (all-revolute) arms
    ranges = tmp_path / "ranges.yaml"
    ranges.write_text("angles: deg\nranges: [[-90, 90], [-90, 90], [0.4, 0.8], [-90, 90], [-45, 45], [-90, 90]]\n")
    out = generate_dataset(robot, 2000, tmp_path / "st", progress=False, fsync=False, sampling=Sampling(ranges=ranges))
    ds = load_dataset(out)
    assert ds.branch is None
    assert_close(ds.pose, robot.fk(ds.q), atol=1e-12, rtol=0)
    # the prismatic joint's range is in metres (not scaled by 'angles: deg'), the others in degrees
    rng = torch.tensor(ds.meta["ranges"]["radians"], dtype=torch.float64)
    assert_close(rng[2], torch.tensor([0.4, 0.8], dtype=torch.float64))
    assert_close(rng[0], torch.tensor([-math.pi / 2, math.pi / 2], dtype=torch.float64))
    assert bool(((ds.q >= rng[:, 0]) & (ds.q <= rng[:, 1])).all())
    assert nik.Robot.from_definition(ds.meta["robot"]["definition"]).prismatic.tolist() == robot.prismatic.tolist()
    bad = tmp_path / "bad.yaml"
    bad.write_text("angles: deg\nranges: [[-90, 90], [-90, 90], [0.1, 0.8], [-90, 90], [-45, 45], [-90, 90]]\n")
    with pytest.raises(ValueError, match=r"joint 3 range \[100 mm, 800 mm\] lies outside the joint limits \[304.8 mm"):
        generate_dataset(robot, 10, tmp_path / "bad", progress=False, fsync=False, sampling=Sampling(ranges=bad))


def _siblings(tmp_path, name):
    return sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(f".{name}."))


def test_a_half_deleted_old_copy_is_never_put_back_and_generate_works(tmp_path, monkeypatch):
    # issue 30.1's recipe: a half-deleted .X.old-* (meta.json and q.npy only) and X missing
    from nik.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["generate", "--robot", "kuka_kr", "--n", "1000", "--out", "X", "--no-progress"]) == 0
    half = tmp_path / ".X.old-999999999-abcd"
    half.mkdir()
    for f in ("meta.json", "q.npy"):
        (half / f).write_bytes((tmp_path / "X" / f).read_bytes())
    shutil.rmtree(tmp_path / "X")
    assert main(["generate", "--robot", "kuka_kr", "--n", "1000", "--out", "X", "--no-progress"]) == 0
    assert len(load_dataset(tmp_path / "X")) == 1000  # whole (checksums verified)
    assert _siblings(tmp_path, "X") == []


def test_an_old_copy_whose_files_fail_their_checksums_is_deleted_not_restored(tmp_path, kuka):
    out = generate_dataset(kuka, 50, tmp_path / "d", progress=False, fsync=False)
    aside = tmp_path / ".d.old-999999999-dead"
    os.rename(out, aside)
    data = bytearray((aside / "pose.npy").read_bytes())
    data[-1] ^= 1
    (aside / "pose.npy").write_bytes(bytes(data))
    AtomicDirectory(out).cleanup_stale()
    assert not out.exists() and _siblings(tmp_path, "d") == []


@pytest.mark.parametrize("what", ["generate", "merge"])
def test_a_kill_at_any_instant_leaves_the_old_or_the_new_dataset_whole(tmp_path, kuka, kill_at, monkeypatch, what):
    # fault injection: the run dies before its k-th filesystem operation, for every k until one completes; then
    # the next run's clean-up must find the old or the new dataset whole, and a further overwrite must work
    from nik.data import merge_shards, storage

    out = tmp_path / "d"
    shards = {}
    if what == "merge":
        for seed in (1, 2):
            shards[seed] = [
                generate_dataset(
                    kuka, 60, tmp_path / f"s{seed}{i}", seed=seed, shard=(i, 2), sampling=Sampling(block_size=30)
                )
                for i in range(2)
            ]

    def run(seed):
        if what == "merge":
            return merge_shards(out, shards[seed], overwrite=True)
        return generate_dataset(
            kuka, 60, out, seed=seed, overwrite=True, progress=False, sampling=Sampling(block_size=30)
        )

    run(1)
    old = _arrays(out)[0]
    run(2)
    new = _arrays(out)[0]
    assert not torch.equal(old, new)
    for k in range(200):
        run(1)
        counter = kill_at(k)
        try:
            run(2)
        except BaseException as err:  # noqa: B036 - the simulated kill is a BaseException
            assert type(err).__name__ == "Killed", err
        counter.undo()
        if not counter.killed:
            break
        with monkeypatch.context() as m:
            m.setattr(storage, "_pid_alive", lambda pid: False)  # the killed run's process is gone
            AtomicDirectory(out).cleanup_stale()  # what the next run does first
        q = _arrays(out)[0]  # whole: every checksum verified
        assert torch.equal(q, old) or torch.equal(q, new), k
        assert _siblings(tmp_path, "d") == [], k
        run(2)
        assert torch.equal(_arrays(out)[0], new) and _siblings(tmp_path, "d") == []
    assert k > 5 and not counter.killed  # every instant up to a whole run was tried


@pytest.mark.long
def test_a_generate_whose_process_dies_between_its_renames_leaves_the_old_dataset_for_the_next_process(tmp_path):
    # a real death (os._exit in a subprocess): the old dataset moved aside, the new one not yet in its place
    out = generate_dataset("kuka_kr", 100, tmp_path / "d", seed=1, progress=False, fsync=False)
    old = _arrays(out)[0]
    script = (
        "import os\n"
        "rename = os.rename\n"
        "def dying(a, b):\n"
        "    if '.tmp-' in str(a):\n"
        "        os._exit(9)  # the old one is aside; the new one would take its name now\n"
        "    rename(a, b)\n"
        "os.rename = dying\n"
        "from nik.cli import main\n"
        f"main(['generate', '--robot', 'kuka_kr', '--n', '100', '--seed', '2', '--out', {str(out)!r}, "
        "'--overwrite', '--no-progress'])\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 9, proc.stderr
    assert not out.exists() and sorted(n.split("-")[0] for n in _leftovers(tmp_path, "d")) == [".d.old", ".d.tmp"]
    assert torch.equal(load_dataset(out).q, old)  # the next process puts the old one back
    generate_dataset("kuka_kr", 100, out, seed=2, overwrite=True, progress=False, fsync=False)
    assert _leftovers(tmp_path, "d") == []


def test_the_generator_takes_grouped_options(tmp_path, kuka):
    """``generate_dataset`` groups what is drawn (``Sampling``) and where it computes (``Compute``), and its writer
    takes one resolved job (``_Job``): at most 12 parameters each (issue 46, item 4). The groups carry the options:
    Sobol rows differ from uniform ones, and a small chunk changes nothing."""
    import inspect

    from nik.data.generate import _generate

    assert len(inspect.signature(_generate).parameters) <= 12
    assert len(inspect.signature(generate_dataset).parameters) <= 12
    kw = dict(seed=3, progress=False, fsync=False)
    plain = _arrays(generate_dataset(kuka, 300, tmp_path / "u", **kw))
    chunked = _arrays(generate_dataset(kuka, 300, tmp_path / "c", compute=Compute(chunk_size=64), **kw))
    sobol = _arrays(generate_dataset(kuka, 300, tmp_path / "s", sampling=Sampling(sampler="sobol"), **kw))
    assert torch.equal(plain[0], chunked[0]) and torch.equal(plain[1], chunked[1])
    assert not torch.equal(plain[0], sobol[0])
    assert load_dataset(tmp_path / "s").meta["sampler"] == "sobol"
