"""nik.kernels: the compiled one-pose kernels agree with the torch reference and solve by FK round trip.

The kernels compile on first use (a cold cache costs seconds once per session); nothing here needs
numba's cache to be warm.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import nik
from nik.kernels import chain_model, fk, fk_batch, fk_jacobian, lm_options, lm_solve, pose_errors, seed_state
from nik.kernels.cache import choose_cache, user_cache_folder
from nik.kernels.lm import uniform_configurations
from nik.kernels.mlp import ACTIVATIONS, mlp_forward, mlp_pack, mlp_work
from nik.kinematics import FKKernel
from nik.robots.joints import wrap_mask

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ["panda", "ur5", "kuka_kr", "stanford"]  # stanford: joint 3 prismatic


def _model(robot):
    return chain_model(robot.G, robot.offsets, robot.limits, robot.prismatic)


def _configurations(robot, n, seed):
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


# ---------------------------------------------------------------------------
# FK and Jacobian against the torch kernels of nik.kinematics
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ROBOTS)
def test_fk_of_one_configuration_and_of_a_batch_match_robot_fk(name):
    robot = nik.load_robot(name)
    G, joints = _model(robot)
    q = _configurations(robot, 6, seed=1)
    ref = robot.fk(q).numpy()
    T = np.empty((4, 4))
    for i in range(6):
        fk(G, joints, q[i].numpy(), T)
        np.testing.assert_allclose(T, ref[i], atol=1e-12, rtol=0)
    Tb = np.empty((6, 4, 4))
    fk_batch(G, joints, q.numpy(), Tb)
    np.testing.assert_allclose(Tb, ref, atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", ROBOTS)
def test_fk_jacobian_matches_the_torch_jacobian(name):
    robot = nik.load_robot(name)
    G, joints = _model(robot)
    q = _configurations(robot, 4, seed=2)
    T_ref, J_ref = robot.fk_and_jacobian(q)
    T, J = np.empty((4, 4)), np.empty((6, robot.dof))
    for i in range(4):
        fk_jacobian(G, joints, q[i].numpy(), T, J)
        np.testing.assert_allclose(T, T_ref[i].numpy(), atol=1e-12, rtol=0)
        np.testing.assert_allclose(J, J_ref[i].numpy(), atol=1e-12, rtol=0)


def _fd_jacobian(G, joints, q, h=1e-6):
    """Geometric Jacobian by central differences of the kernel FK: linear rows from dp, angular from dR R^T."""
    n = q.shape[0]
    T = np.empty((4, 4))
    fk(G, joints, q, T)
    R = T[:3, :3].copy()
    out = np.empty((6, n))
    Tp, Tm = np.empty((4, 4)), np.empty((4, 4))
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = h
        fk(G, joints, q + dq, Tp)
        fk(G, joints, q - dq, Tm)
        dT = (Tp - Tm) / (2 * h)
        W = dT[:3, :3] @ R.T  # skew matrix of the angular velocity
        out[:3, j] = dT[:3, 3]
        out[3:, j] = [W[2, 1], W[0, 2], W[1, 0]]
    return out


@pytest.mark.parametrize("name", ["panda", "stanford"])
def test_jacobian_matches_finite_differences(name):
    robot = nik.load_robot(name)
    G, joints = _model(robot)
    J = np.empty((6, robot.dof))
    for q in _configurations(robot, 3, seed=3).numpy():
        fk_jacobian(G, joints, q, np.empty((4, 4)), J)
        np.testing.assert_allclose(J, _fd_jacobian(G, joints, q), atol=1e-8, rtol=0)


def test_a_prismatic_joint_is_a_slide_along_z_of_its_frame():
    # T = G0 Rz(q1) G1 Tz(q2 + o2) G2, written as a plain matrix product
    G = np.tile(np.eye(4), (3, 1, 1))
    G[0, :3, 3] = [0.1, 0.0, 0.2]
    G[1, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # the slide axis turned to -y of the base
    G[1, :3, 3] = [0.3, 0.0, 0.0]
    G[2, :3, 3] = [0.0, 0.05, 0.1]
    Gm, joints = chain_model(G, [0.0, 0.02], [[-3.0, 3.0], [0.0, 0.5]], [False, True])
    q = np.array([0.7, 0.23])
    c, s = math.cos(0.7), math.sin(0.7)
    Rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    Tz = np.eye(4)
    Tz[2, 3] = 0.23 + 0.02
    T, J = np.empty((4, 4)), np.empty((6, 2))
    fk_jacobian(Gm, joints, q, T, J)
    np.testing.assert_allclose(T, G[0] @ Rz @ G[1] @ Tz @ G[2], atol=1e-14)
    axis = (G[0] @ Rz @ G[1])[:3, 2]
    np.testing.assert_allclose(J[:, 1], np.concatenate([axis, np.zeros(3)]), atol=1e-14)
    np.testing.assert_allclose(J, _fd_jacobian(Gm, joints, q), atol=1e-8)
    assert joints[1, 4] == 0.0  # a prismatic joint never wraps


def test_chain_model_marks_the_same_wrapping_joints_as_wrap_mask():
    for name in ROBOTS:
        robot = nik.load_robot(name)
        _, joints = _model(robot)
        expected = wrap_mask(robot.limits, prismatic=robot.prismatic).numpy()
        assert np.array_equal(joints[:, 4] != 0.0, expected), name


# ---------------------------------------------------------------------------
# Levenberg-Marquardt
# ---------------------------------------------------------------------------
def _solve(robot, T, seed, *, q0=None, restarts=2, **kw):
    """One target through the batch kernel: ``(q, iterations, converged, pos, rot)``."""
    G, joints = _model(robot)
    opts, iopts = lm_options(**kw)
    q0 = np.zeros((1, robot.dof)) if q0 is None else np.asarray(q0, dtype=np.float64).reshape(1, -1)
    restarts = np.array([restarts], dtype=np.int64)
    out = _outputs(1, robot.dof)
    lm_solve(G, joints, T[None], q0, opts, iopts, restarts, seed_state(seed), tuple(out))
    q, it, conv, pos, rot = out
    return q[0], int(it[0]), bool(conv[0]), pos[0], rot[0]


def _outputs(B, n):
    """The kernel's output arrays: q, iterations, converged, pos, rot."""
    return np.empty((B, n)), np.empty(B, dtype=np.int64), np.empty(B, dtype=bool), np.empty(B), np.empty(B)


@pytest.mark.parametrize("name", ["panda", "ur5", "stanford"])
def test_lm_from_uniform_starts_solves_by_fk_round_trip_inside_the_limits(name):
    robot = nik.load_robot(name)
    targets = robot.fk(_configurations(robot, 20, seed=4)).numpy()
    lo, hi = robot.limits[:, 0].numpy(), robot.limits[:, 1].numpy()
    for k, T in enumerate(targets):
        # solved to the tolerance asserted below (the kernel's default rotation tolerance is 0.1 deg = 1.7e-3 rad)
        q, it, conv, pos, rot = _solve(robot, T, seed=k, first_starts=8, restarts=100, tol_pos=1e-4, tol_rot=1e-3)
        assert conv, (name, k, pos, rot)
        assert np.all(q >= lo) and np.all(q <= hi)
        # the errors it reports are those of the torch FK of its answer
        tpos, trot = nik.pose_error(torch.from_numpy(T)[None], robot.fk(torch.from_numpy(q))[None])
        assert float(tpos) <= 1e-4 and float(trot) <= 1e-3
        assert abs(float(tpos) - pos) < 1e-12 and abs(float(trot) - rot) < 1e-9


def test_lm_from_a_nearby_start_converges_in_few_iterations():
    robot = nik.load_robot("panda")
    q_true = _configurations(robot, 1, seed=5)[0]
    T = robot.fk(q_true).numpy()
    q0 = robot.clamp(q_true + 0.05).numpy()
    q, it, conv, _, _ = _solve(robot, T, seed=0, q0=q0, restarts=0)
    assert conv and it <= 10


def test_same_seed_same_answer_and_the_seed_matters():
    robot = nik.load_robot("panda")
    T = robot.fk(_configurations(robot, 1, seed=6)[0]).numpy()
    a = _solve(robot, T, seed=11, first_starts=8, restarts=50)
    b = _solve(robot, T, seed=11, first_starts=8, restarts=50)
    c = _solve(robot, T, seed=12, first_starts=8, restarts=50)
    assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]
    assert not np.array_equal(a[0], c[0])  # a 7-joint arm: another start lands elsewhere on the self-motion


def test_a_target_out_of_reach_returns_the_best_effort_inside_the_limits():
    robot = nik.load_robot("ur5")
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.5]  # metres: beyond the reach of a UR5 (about 0.95 m)
    q, it, conv, pos, rot = _solve(robot, T, seed=0, first_starts=8, restarts=3)
    assert not conv
    assert pos > 1.5  # honest error, not the tolerance
    assert np.all(q >= robot.limits[:, 0].numpy()) and np.all(q <= robot.limits[:, 1].numpy())
    Tq = robot.fk(torch.from_numpy(q)).numpy()
    assert abs(np.linalg.norm(Tq[:3, 3] - T[:3, 3]) - pos) < 1e-12


def test_a_solution_on_a_joint_limit_is_found_and_the_limits_hold():
    robot = nik.load_robot("panda")
    q_true = _configurations(robot, 1, seed=7)[0]
    q_true[3] = robot.limits[3, 1]  # joint 4 exactly on its upper limit
    q_true[5] = robot.limits[5, 0]  # joint 6 exactly on its lower limit
    T = robot.fk(q_true).numpy()
    # start just outside the limits on those joints, near the solution: clamped, then held by the active set
    q0 = q_true.numpy() + np.array([0.03, -0.02, 0.02, 0.2, -0.02, -0.2, 0.03])
    q, it, conv, _, _ = _solve(robot, T, seed=0, q0=q0, restarts=0)
    assert conv
    lo, hi = robot.limits[:, 0].numpy(), robot.limits[:, 1].numpy()
    assert np.all(q >= lo) and np.all(q <= hi)


def test_a_wrapping_joint_moves_by_whole_turns_into_its_range():
    robot = nik.load_robot("ur5")  # joints of +-2 pi wrap
    _, joints = _model(robot)
    assert joints[:, 4].all()
    q_true = _configurations(robot, 1, seed=8)[0].numpy()
    T = robot.fk(torch.from_numpy(q_true)).numpy()
    q0 = q_true.copy()
    q0[0] += 6 * math.pi  # three turns past the range: the same pose
    q, it, conv, _, _ = _solve(robot, T, seed=0, q0=q0, restarts=0)
    assert conv and it == 0
    assert robot.limits[0, 0] <= q[0] <= robot.limits[0, 1]


def test_uniform_configurations_cover_the_limits_reproducibly():
    robot = nik.load_robot("stanford")
    _, joints = _model(robot)
    a, b = np.empty((2000, robot.dof)), np.empty((2000, robot.dof))
    uniform_configurations(joints, seed_state(3), a)
    uniform_configurations(joints, seed_state(3), b)
    assert np.array_equal(a, b)
    lo, hi = robot.limits[:, 0].numpy(), robot.limits[:, 1].numpy()
    assert np.all(a >= lo) and np.all(a <= hi)
    u = (a - lo) / (hi - lo)  # uniform on [0, 1): mean 1/2, sd of the mean 0.0065
    np.testing.assert_allclose(u.mean(0), 0.5, atol=0.03)
    assert np.abs(np.corrcoef(u.T) - np.eye(robot.dof)).max() < 0.1


def test_a_batch_gives_each_target_the_answer_it_gets_alone_and_its_own_restart_budget():
    robot = nik.load_robot("ur5")
    G, joints = _model(robot)
    T = robot.fk(_configurations(robot, 5, seed=13)).numpy()
    T[3, :3, 3] = [3.0, 0.0, 0.5]  # out of reach: given no restarts
    opts, iopts = lm_options(first_starts=8)
    restarts = np.array([50, 50, 50, 0, 50], dtype=np.int64)
    out = _outputs(5, robot.dof)
    lm_solve(G, joints, T, np.zeros((5, robot.dof)), opts, iopts, restarts, seed_state(4), tuple(out))
    q, it, conv, pos, rot = out
    assert conv[[0, 1, 2, 4]].all() and not conv[3]
    assert it[3] <= 25  # one start of at most first_iters iterations
    for b in (0, 2, 4):  # target b alone, as row b of its own call: the same stream, the same answer
        rows = np.repeat(T[b : b + 1], b + 1, axis=0)
        alone = _outputs(b + 1, robot.dof)
        budget = np.full(b + 1, 50, dtype=np.int64)
        lm_solve(G, joints, rows, np.zeros((b + 1, 6)), opts, iopts, budget, seed_state(4), tuple(alone))
        assert np.array_equal(alone[0][b], q[b])
    errors = np.empty(5), np.empty(5)
    pose_errors(G, joints, T, q, *errors)
    np.testing.assert_allclose(errors[0], pos, atol=1e-15)
    np.testing.assert_allclose(errors[1], rot, atol=1e-15)


def test_lm_options_refuse_negative_counts():
    with pytest.raises(ValueError, match="iteration counts"):
        lm_options(first_starts=-1)


# ---------------------------------------------------------------------------
# MLP forward pass
# ---------------------------------------------------------------------------
_TORCH_ACTS = {
    "tanh": torch.tanh,
    "relu": torch.relu,
    "silu": torch.nn.functional.silu,
    "gelu": torch.nn.functional.gelu,
    "elu": torch.nn.functional.elu,
    "softplus": torch.nn.functional.softplus,
}


@pytest.mark.parametrize("activation", sorted(ACTIVATIONS))
@pytest.mark.parametrize("rows", [1, 6])  # 6: one block of four rows and two single rows
def test_mlp_forward_matches_torch_in_float64(activation, rows):
    g = torch.Generator().manual_seed(9)
    sizes = [9, 33, 17, 7]
    layers = [torch.nn.Linear(a, b, dtype=torch.float64) for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
    for layer in layers:
        torch.nn.init.normal_(layer.weight, std=0.5, generator=g)
        torch.nn.init.normal_(layer.bias, std=2.0, generator=g)  # reaches softplus' threshold of 20
    x = torch.randn(rows, 9, generator=g, dtype=torch.float64) * 3
    with torch.no_grad():
        ref = x
        for layer in layers[:-1]:
            ref = _TORCH_ACTS[activation](layer(ref))
        ref = layers[-1](ref).numpy()
    flat, layout = mlp_pack([(layer.weight.detach(), layer.bias.detach()) for layer in layers])
    y = np.empty((rows, 7))
    mlp_forward(flat, layout, ACTIVATIONS[activation], x.numpy(), y, mlp_work(layout, rows))
    np.testing.assert_allclose(y, ref, atol=1e-10, rtol=1e-10)
    own = np.empty((rows, 7))  # without a caller's scratch: the kernel allocates its own
    mlp_forward(flat, layout, ACTIVATIONS[activation], x.numpy(), own)
    np.testing.assert_allclose(own, ref, atol=1e-10, rtol=1e-10)


def test_mlp_pack_refuses_layers_that_do_not_chain():
    with pytest.raises(ValueError, match="takes 5 inputs"):
        mlp_pack([(np.zeros((4, 3)), np.zeros(4)), (np.zeros((2, 5)), np.zeros(2))])


# ---------------------------------------------------------------------------
# cache folder and light imports
# ---------------------------------------------------------------------------
def test_cache_folder_is_numbas_setting_then_the_package_then_the_user_folder(tmp_path):
    pkg = tmp_path / "pkg"
    env = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert choose_cache(environ={**env, "NUMBA_CACHE_DIR": "/somewhere"}, package_dir=pkg).mode == "numba"
    assert choose_cache(environ=env, package_dir=pkg).folder == pkg / "__pycache__"

    def read_only_package(folder):
        return not str(folder).startswith(str(pkg))

    choice = choose_cache(environ=env, package_dir=pkg, is_writable=read_only_package)
    assert choice.mode == "user" and choice.folder == tmp_path / "xdg" / "nik" / "numba"
    assert user_cache_folder({}) == Path("~/.cache/nik/numba").expanduser()
    nothing = choose_cache(environ=env, package_dir=pkg, is_writable=lambda folder: False)
    assert nothing.mode == "none" and not nothing.cache


def test_every_cached_kernel_is_stamped_with_every_source_file_of_the_kernels_room():
    # numba stamps a kernel's cache with its own file only; a building block changed in another file would leave
    # its callers' cached machine code stale. nik stamps each cache with every source file of the room.
    from pathlib import Path

    from nik.kernels import _jit, collision_lm, lm

    room = sorted(p.name for p in Path(lm.__file__).parent.glob("*.py"))
    assert [name for name, _, _ in _jit.ROOM_STAMP] == room
    for dispatcher in (lm.lm_solve, collision_lm.collision_lm):
        assert dispatcher._cache._cache_file._source_stamp == _jit.ROOM_STAMP


_LIGHT = """
import sys
import torch
import nik
robot = nik.load_robot("panda")
q = robot.sample(3, dtype=torch.float64).requires_grad_(True)
robot.fk(q).sum().backward()  # a gradient is wanted: the torch path
print("numba" in sys.modules, "nik.kernels.chain" in sys.modules)
robot.fk(q.detach()[0])  # one configuration, no gradient: the compiled path
print("numba" in sys.modules)
"""


@pytest.mark.long
def test_import_nik_does_not_import_numba_until_a_compiled_path_runs():
    done = subprocess.run([sys.executable, "-c", _LIGHT], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["False", "False", "True"]


_CACHED = """
import json, sys
import torch
import nik
robot = nik.load_robot("panda")
T = robot.fk(torch.linspace(-1.0, 1.0, 7, dtype=torch.float64))  # the compiled path: the kernel from the cache
print(json.dumps(["scipy.linalg" in sys.modules, T.tolist()]))
"""


@pytest.mark.long
def test_a_cached_kernel_loads_without_numbas_whole_compiler_context():
    from nik.kernels import CACHE

    if not CACHE.cache:
        pytest.skip("no cache folder: every process compiles")
    runs = [  # the first run compiles the kernel if the cache is cold; the second loads it
        subprocess.run([sys.executable, "-c", _CACHED], cwd=ROOT, capture_output=True, text=True, timeout=300)
        for _ in range(2)
    ]
    assert all(run.returncode == 0 for run in runs), runs[-1].stderr[-2000:]
    scipy_linalg, T = json.loads(runs[-1].stdout.strip().splitlines()[-1])
    assert not scipy_linalg  # numba's full target (which imports scipy.linalg) was not set up to load it
    q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64).requires_grad_(True)  # the torch path, the reference
    torch.testing.assert_close(torch.tensor(T, dtype=torch.float64), nik.load_robot("panda").fk(q).detach())


# numba's own load when its private cache API is not the one nik expects (nik/kernels/_jit.py): the patch runs
# before nik's kernels are decorated, in a fresh process; numba's own loads are counted
_FALLBACK = """
import json, sys
import numba.core.caching as caching
import torch

numba_load, numba_private_load = caching.Cache.load_overload, caching.Cache._load_overload
calls = {"numba": 0}


def counted_load(self, sig, target_context):  # numba's own load (it refreshes the target first)
    calls["numba"] += 1
    calls["inside"] = True
    try:
        return numba_load(self, sig, target_context)
    finally:
        calls["inside"] = False


if sys.argv[1] == "missing":  # a numba without the private guard nik calls (its own load and save do without it)
    del caching.Cache._guard_against_spurious_io_errors

    def counted_load(self, sig, target_context):
        calls["numba"] += 1
        target_context.refresh()
        return numba_private_load(self, sig, target_context)

    def save_without_guard(self, sig, data):  # a cold cache compiles, then saves
        self._save_overload(sig, data)

    caching.Cache.save_overload = save_without_guard
else:  # the private load raises when called outside numba's own load

    def raising_private_load(self, sig, target_context):
        if not calls.get("inside"):
            raise RuntimeError("not the private API nik expects")
        return numba_private_load(self, sig, target_context)

    caching.Cache._load_overload = raising_private_load
caching.Cache.load_overload = counted_load

import nik

robot = nik.load_robot("panda")
T = robot.fk(torch.linspace(-1.0, 1.0, 7, dtype=torch.float64))
print(json.dumps([calls["numba"], T.tolist()]))
"""


@pytest.mark.long
@pytest.mark.parametrize("private_api", ["missing", "raising"])
def test_kernels_load_through_numbas_own_load_when_its_private_cache_api_differs(private_api):
    done = subprocess.run(
        [sys.executable, "-c", _FALLBACK, private_api], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    numba_loads, T = json.loads(done.stdout.strip().splitlines()[-1])
    assert numba_loads >= 1  # numba's own load served
    q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64).requires_grad_(True)  # the torch path, the reference
    torch.testing.assert_close(torch.tensor(T, dtype=torch.float64), nik.load_robot("panda").fk(q).detach())


def test_a_dispatcher_numba_does_not_know_is_left_as_it_is():
    from types import SimpleNamespace

    from nik.kernels._jit import _cached_loads_without_refresh

    unknown = SimpleNamespace(_cache=SimpleNamespace(load_overload=print))  # no private load, no guard
    assert _cached_loads_without_refresh(unknown) is unknown and unknown._cache.load_overload is print


# a cache entry of nik.kernels.poses.poses_ok (a small kernel: under a second to compile) in a process of its own, on
# poses laid out in memory as the argument says: "contiguous" two identity poses, "strided" the same two read every
# other slot of an array whose slots between hold 7.0 everywhere (a pose that fails), "kill" as "strided" but the
# process dies (os._exit) right after the first file of the new cache entry is complete
_ENTRY = """
import os, sys
import numpy as np
from nik.kernels import poses
big = np.full((4, 4, 4), 7.0)
big[::2] = np.eye(4)
T = np.ascontiguousarray(big[::2]) if sys.argv[1] == "contiguous" else big[::2]
if sys.argv[1] == "kill":
    replace = os.replace

    def replace_then_die(src, dst):
        replace(src, dst)
        os._exit(9)

    os.replace = replace_then_die
print(bool(poses.poses_ok(T, 1e-9)))
"""


def _entry(cache, layout):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-c", _ENTRY, layout], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )


def _poses_ok_index(cache):
    (index,) = Path(cache).rglob("poses.poses_ok-*.nbi")
    return index


@pytest.mark.long
def test_a_process_killed_between_the_two_files_of_a_cache_entry_leaves_a_cache_the_next_one_uses(tmp_path):
    # numba writes an entry's index before its data: killed between the two, the index would name a data file that
    # the entry did not write, here one left by an older source for another memory layout (numba numbers its files
    # from 1 again when the index is stale)
    import pickle

    from numba.core.serialize import dumps

    first = _entry(tmp_path, "contiguous")
    assert first.returncode == 0 and first.stdout.split() == ["True"], first.stderr[-2000:]
    index = _poses_ok_index(tmp_path)
    with open(index, "rb") as f:  # the cache as an older source of the kernels left it: its stamp differs
        version = pickle.load(f)
        _, overloads = pickle.loads(f.read())
    with open(index, "wb") as f:
        pickle.dump(version, f, protocol=-1)
        f.write(dumps((("an older source",), overloads)))
    killed = _entry(tmp_path, "kill")
    assert killed.returncode == 9, killed.stderr[-2000:]
    after = _entry(tmp_path, "strided")
    assert after.returncode == 0, after.stderr[-2000:]
    assert after.stdout.split() == ["True"]  # both poses are identities, read with their strides


@pytest.mark.long
@pytest.mark.parametrize("damage", ["data truncated", "index garbled"])
def test_a_damaged_cache_entry_is_compiled_again_instead_of_failing_the_call(tmp_path, damage):
    first = _entry(tmp_path, "contiguous")
    assert first.returncode == 0 and first.stdout.split() == ["True"], first.stderr[-2000:]
    index = _poses_ok_index(tmp_path)
    if damage == "data truncated":
        for data in index.parent.glob("poses.poses_ok-*.nbc"):
            data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    else:
        index.write_bytes(index.read_bytes()[:12] + b"not a pickle")
    again = _entry(tmp_path, "contiguous")
    assert again.returncode == 0, again.stderr[-2000:]
    assert again.stdout.split() == ["True"]
    assert "nik: compiling kernels" in again.stderr  # compiled again, and said so
    third = _entry(tmp_path, "contiguous")  # and saved anew: the next process loads it
    assert third.returncode == 0 and third.stdout.split() == ["True"], third.stderr[-2000:]
    assert "nik: compiling kernels" not in third.stderr


# a new compile (a function numba has never seen, typing np.linalg, calling a kernel loaded without the refresh)
# after the cached kernels were loaded without refreshing numba's target
_COMPILE_AFTER_LOAD = """
import json, sys
import numba
import numpy as np
import torch
import nik
from nik.kernels import chain

robot = nik.load_robot("panda")
q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64)
robot.fk(q)  # loads the cached kernel without refreshing numba's target
refreshed = "scipy.linalg" in sys.modules  # numba's refresh imports it


@numba.njit
def position_norm(G, joints, q):
    T = np.empty((4, 4))
    chain.fk(G, joints, q, T)
    return np.linalg.norm(T[:3, 3])


G, joints = robot.chain_arrays()
print(json.dumps([refreshed, position_norm(G, joints, q.numpy())]))
"""


@pytest.mark.long
def test_a_new_signature_compiles_after_kernels_were_loaded_without_the_refresh():
    from nik.kernels import CACHE

    if not CACHE.cache:
        pytest.skip("no cache folder: every process compiles")
    runs = [  # the first run compiles the kernel if the cache is cold; the second loads it, then compiles
        subprocess.run(
            [sys.executable, "-c", _COMPILE_AFTER_LOAD], cwd=ROOT, capture_output=True, text=True, timeout=300
        )
        for _ in range(2)
    ]
    assert all(run.returncode == 0 for run in runs), runs[-1].stderr[-2000:]
    refreshed, norm = json.loads(runs[-1].stdout.strip().splitlines()[-1])
    assert not refreshed  # loaded without the refresh; the compile after it did its own
    q = torch.linspace(-1.0, 1.0, 7, dtype=torch.float64).requires_grad_(True)
    assert norm == pytest.approx(float(nik.load_robot("panda").fk(q)[:3, 3].norm().detach()), abs=1e-12)


# ---------------------------------------------------------------------------
# Robot.fk takes the compiled path for a few CPU configurations
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_robot_fk_compiled_path_matches_the_torch_kernel_in_every_shape(dtype):
    robot = nik.load_robot("stanford")
    q = _configurations(robot, 6, seed=10).to(dtype)
    torch_fk = FKKernel(robot.G.numpy(), robot.offsets.numpy(), prismatic=robot.prismatic.tolist())
    atol = 1e-12 if dtype == torch.float64 else 1e-5
    strided = torch.stack([q, -q], dim=-1)[..., 0]  # the values of q, not contiguous
    for shaped in (q[0], q[4], q[:1], q[2:5], q, q.reshape(2, 3, robot.dof), strided, strided[1]):
        T = robot.fk(shaped)
        assert T.dtype == dtype and T.shape == (*shaped.shape[:-1], 4, 4)
        torch.testing.assert_close(T, torch_fk(shaped.reshape(-1, robot.dof)).reshape(T.shape), atol=atol, rtol=0)


def test_robot_fk_without_gradient_mode_takes_a_tensor_that_requires_grad():
    robot = nik.load_robot("panda")
    q = _configurations(robot, 3, seed=12).requires_grad_(True)
    with torch.no_grad():
        T = robot.fk(q[1])
    assert not T.requires_grad
    torch.testing.assert_close(T, robot.fk(q[1].detach().clone()), atol=0, rtol=0)
    torch.testing.assert_close(T, robot.fk(q)[1].detach(), atol=1e-12, rtol=0)  # the torch path, with gradients


def test_robot_fk_refuses_nan_on_the_compiled_path_and_keeps_gradients_on_the_torch_path():
    robot = nik.load_robot("panda")
    q = _configurations(robot, 1, seed=11)[0]
    bad = q.clone()
    bad[2] = float("nan")
    with pytest.raises(ValueError, match="NaN or inf"):
        robot.fk(bad)
    q.requires_grad_(True)
    robot.fk(q)[0, 3].backward()
    assert q.grad is not None and bool(torch.isfinite(q.grad).all())


# ---------------------------------------------------------------------------
# the closed forms (spherical wrist, three parallel axes)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["kuka_kr", "puma560", "rebot_v_6r", "ur5"])
def test_closed_form_solutions_match_nik_analytic_solve(name):
    from nik.analytic import solve
    from nik.analytic.solve import closed_form
    from nik.kernels.closed import closed_form_array, solutions

    robot = nik.load_robot(name)
    G, joints = _model(robot)
    T = robot.fk(_configurations(robot, 12, seed=40))
    T[0, :3, 3] += 3.0  # out of reach: no valid solution
    ref_q, ref_valid = solve(robot, T)
    q, valid = np.empty((12, 8, 6)), np.empty((12, 8), dtype=bool)
    solutions(closed_form_array(closed_form(robot)), G, joints, 1e-9, 1e-9, T.numpy(), q, valid)
    assert np.array_equal(valid, ref_valid.numpy()) and not valid[0].any() and valid[1:].any(axis=1).all()
    diff = np.remainder(q - ref_q.numpy() + math.pi, 2 * math.pi) - math.pi  # the same angle, up to whole turns
    assert np.abs(diff[valid]).max() < 1e-9
    Tq = np.empty((4, 4))
    for b, s in zip(*np.nonzero(valid), strict=True):  # every valid solution reaches its target (own FK)
        fk(G, joints, q[b, s], Tq)
        np.testing.assert_allclose(Tq, T[b].numpy(), atol=1e-9)


def _n_params(fn) -> int:
    """Parameters of ``fn`` (a numba dispatcher: its Python function), as the issue's reviewer counts them."""
    import inspect

    return len(inspect.signature(getattr(fn, "py_func", fn)).parameters)


def test_seeded_and_closed_form_kernels_take_grouped_arrays():
    """The network, the answers, the refined rows and the outputs travel as tuples of arrays: at most 12
    parameters per kernel (issue 46, item 4)."""
    from nik.kernels import closed, seeded

    for fn in (seeded.ranked_hypotheses, seeded.merge, closed.guess):
        assert _n_params(fn) <= 12, fn.__name__


def test_merge_takes_the_better_refined_row_and_adds_its_iterations():
    """``merge(answers, idx, refined, strict, tol_pos, tol_rot)`` in place, against the rule worked by hand: target
    ``idx[i]`` takes refined row ``i`` where its score (m + 0.1 rad) is lower (``strict``) or not higher, keeps
    ``ok`` equal to both errors within the tolerances, and counts the targets still failing."""
    from nik.kernels.seeded import merge

    q = np.zeros((3, 2))
    pos, rot = np.array([1e-3, 1e-3, 1e-6]), np.array([1e-2, 1e-2, 1e-6])
    its, ok = np.array([5, 5, 5], dtype=np.int64), np.array([False, False, True])
    rq = np.array([[1.0, 1.0], [2.0, 2.0]])
    rpos, rrot, rit = np.array([1e-6, 1e-3]), np.array([1e-6, 1e-2]), np.array([3, 4], dtype=np.int64)
    idx = np.array([0, 1], dtype=np.int64)
    failing = merge((q, pos, rot, its, ok), idx, (rq, rpos, rrot, rit), True, 1e-4, 1e-3)
    assert failing == 1  # target 1: the refined row ties and strict keeps the old one, still failing
    assert q[0].tolist() == [1.0, 1.0] and q[1].tolist() == [0.0, 0.0]
    assert ok.tolist() == [True, False, True] and its.tolist() == [8, 9, 5]
    failing = merge((q, pos, rot, its, ok), idx[1:], (rq[1:], rpos[1:], rrot[1:], rit[1:]), False, 1e-4, 1e-3)
    assert failing == 1 and q[1].tolist() == [2.0, 2.0]  # not strict: a tie takes the refined row
