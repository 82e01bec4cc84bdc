"""nik.ik.backends.one_pose: one pose in one kernel call answers exactly as the general path (every field's kind,
dtype, device, shape and value, numpy and torch poses), refuses bad input with the same line, and steps aside
wherever it does not apply (a setting changed, a collision check, another form of pose)."""

from __future__ import annotations

import copy
import dataclasses
import pickle
import warnings
import weakref

import numpy as np
import pytest
import torch

import nik
from nik.ik.result import IKResult, TensorResult

FIELDS = ("q", "pos_err", "rot_err", "success", "iterations", "reachable")
OTHERS = ("source", "path", "collision_free", "axis_err", "collisions")


def _poses(robot, n, seed):
    q = robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return robot.fk(q)


def _assert_same(a, b):
    """Every field of two results: the same kind, dtype, device, shape and values (bit for bit)."""
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert type(x) is type(y), name
        assert x.dtype == y.dtype and tuple(x.shape) == tuple(y.shape), name
        if isinstance(x, torch.Tensor):
            assert x.device == y.device, name
            assert torch.equal(x, y), name
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)
    for name in OTHERS:
        assert getattr(a, name) == getattr(b, name), name


def _general(solver, T, **kw):
    """The same call through the general path (``representation`` given: the one-pose path steps aside)."""
    return solver.solve(T, representation="matrix", **kw)


@pytest.mark.parametrize(
    "name, checkpoint", [("ur5", "auto"), ("panda", "auto"), ("panda", None)], ids=["analytic", "network", "multistart"]
)
def test_one_pose_answers_as_the_general_path_for_every_kind_of_pose(name, checkpoint):
    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot, checkpoint=checkpoint)
    T = _poses(robot, 6, seed=4)
    sources = set()
    for i in range(T.shape[0]):
        t = T[i]
        for pose in (t, t[None], t.numpy().copy(), t.numpy()[None].copy(), t.float(), t.numpy().astype(np.float32)):
            fast = solver.solve(pose, seed=2)
            assert isinstance(fast, TensorResult) == isinstance(pose, torch.Tensor)  # the one-pose path answered
            _assert_same(fast, _general(solver, pose, seed=2))
            sources.add(fast.source)
            assert bool(fast.success.all()) and bool(robot.within_limits(torch.as_tensor(fast.q)).all())
        assert fast.q.shape == (1, robot.dof)
    assert sources == {"analytic" if name == "ur5" else "network" if checkpoint else "multistart"}


def test_one_pose_answers_as_the_general_path_with_a_branch_network_in_the_arms_frame():
    robot = nik.load_robot("ur5")  # a flange (tool0): the single-pose branch network guesses in the bare arm's frame
    solver = nik.IKSolver(robot, analytic=False)
    assert solver.single_pose_net is not None and solver.plan(backend="compiled").net_in_arm_frame
    T = _poses(robot, 4, seed=8)
    for i in range(T.shape[0]):
        for pose in (T[i], T[i].numpy().copy()):
            fast = solver.solve(pose, seed=1)
            assert isinstance(fast, TensorResult) == isinstance(pose, torch.Tensor)
            _assert_same(fast, _general(solver, pose, seed=1))
            assert fast.source == "network" and bool(fast.success.all())


def test_tolerances_and_seed_reach_the_one_pose_path():
    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot, checkpoint=None)  # multistart: the seed chooses the answer
    t = _poses(robot, 1, seed=5)[0].numpy()
    answers = {}
    for seed in (0, 1):
        for tol in (1e-4, 1e-7):
            res = solver.solve(t, tol_pos=tol, tol_rot=tol, seed=seed)
            _assert_same(res, _general(solver, t, tol_pos=tol, tol_rot=tol, seed=seed))
            answers[seed, tol] = res
    assert not np.array_equal(answers[0, 1e-4].q, answers[1, 1e-4].q)
    assert answers[0, 1e-7].pos_err[0] <= 1e-7 and answers[1, 1e-7].success[0]


def _bad_poses():
    T = torch.eye(4, dtype=torch.float64)
    nan, skew, row, scaled = T.clone(), T.clone(), T.clone(), T.clone()
    nan[0, 3] = float("nan")
    skew[0, 1] = 0.3
    row[3, 0] = 1.0
    scaled[:3, :3] *= 2.0
    return {"nan": nan, "not_orthonormal": skew, "bottom_row": row, "scaled": scaled}


@pytest.mark.parametrize("kind", ["nan", "not_orthonormal", "bottom_row", "scaled"])
@pytest.mark.parametrize("as_numpy", [False, True], ids=["torch", "numpy"])
def test_a_bad_pose_gets_the_general_paths_one_line_error(kind, as_numpy):
    solver = nik.IKSolver("ur5")
    solver.solve(_poses(solver.robot, 1, seed=0)[0])  # the one-pose entry exists
    T = _bad_poses()[kind]
    T = T.numpy() if as_numpy else T
    with pytest.raises(ValueError) as general:
        _general(solver, T)
    with pytest.raises(ValueError) as fast:
        solver.solve(T)
    assert str(fast.value) == str(general.value)
    assert "\n" not in str(fast.value) and "T_target" in str(fast.value)


@pytest.mark.parametrize("tol", [-1.0, float("nan"), "a"])
def test_a_bad_tolerance_gets_the_same_one_line_error(tol):
    solver = nik.IKSolver("ur5")
    t = _poses(solver.robot, 1, seed=0)[0]
    with pytest.raises(ValueError, match="tol_pos: expected a number >= 0"):
        solver.solve(t, tol_pos=tol)
    with pytest.raises(ValueError, match="tol_pos: expected a number >= 0"):
        solver.solve(t, tol_pos=tol)  # the second time too: a refused tolerance is not kept


def test_an_unreachable_pose_warns_as_the_general_path():
    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    t = _poses(robot, 1, seed=3)[0].clone()
    t[:3, 3] += torch.tensor([3.0, 0.0, 0.0], dtype=t.dtype)
    with pytest.warns(UserWarning, match="beyond the reach") as fast_w:
        fast = solver.solve(t)
    with pytest.warns(UserWarning, match="beyond the reach") as general_w:
        general = _general(solver, t)
    assert [str(w.message) for w in fast_w] == [str(w.message) for w in general_w]
    assert fast_w[0].filename == __file__  # pointed at the caller's line
    _assert_same(fast, general)
    assert not bool(fast.reachable[0]) and not bool(fast.success[0])


@pytest.mark.long
def test_odd_tensors_and_arrays_answer_as_the_general_path():
    robot = nik.load_robot("ur5")
    solver = nik.IKSolver(robot)
    t = _poses(robot, 1, seed=6)[0]
    grad = t.clone().requires_grad_(True)
    strided = t.T.contiguous().T  # the same pose, not contiguous
    readonly = t.numpy().copy()
    readonly.setflags(write=False)
    fortran = np.asfortranarray(t.numpy())
    for pose in (grad, strided, readonly, fortran, t.tolist(), t.numpy().astype(np.int64) * 0 + np.eye(4, dtype=int)):
        _assert_same(solver.solve(pose), _general(solver, pose))


def test_a_changed_setting_reaches_the_next_one_pose_call():
    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    t = _poses(robot, 1, seed=2)[0]
    assert solver.solve(t).source == "network"
    solver.net = None
    res = solver.solve(t)
    assert res.source == "multistart"
    _assert_same(res, _general(solver, t))
    solver.backend = "torch"
    res = solver.solve(t)
    assert type(res) is IKResult and res.source == "multistart"


def test_a_collision_check_takes_the_general_path():
    robot = nik.load_robot("ur5")
    solver = nik.IKSolver(robot)
    t = _poses(robot, 1, seed=2)[0]
    assert solver.solve(t).collision_free is None
    solver.world = nik.World().add_box([5.0, 5.0, 5.0], [0.1, 0.1, 0.1])  # far away: answers stay free
    res = solver.solve(t)
    assert res.collision_free is not None and bool(res.collision_free[0])


def test_a_tensor_result_behaves_as_a_plain_one():
    robot = nik.load_robot("ur5")
    solver = nik.IKSolver(robot)
    t = _poses(robot, 1, seed=9)[0]
    res = solver.solve(t)
    plain = _general(solver, t)
    assert isinstance(res, TensorResult) and isinstance(res, IKResult) and len(res) == 1
    assert res.q is res.q  # made once, then kept
    assert res.q.data_ptr() == res.__dict__["_arrays"][0].ctypes.data  # shares the kernel's memory
    for other in (pickle.loads(pickle.dumps(res)), copy.deepcopy(res), dataclasses.replace(res), res.to("cpu")):
        _assert_same(other, plain)
    _assert_same(res.numpy(), plain.numpy())
    assert repr(res).replace("TensorResult", "IKResult") == repr(plain)
    res.q = torch.zeros(1, robot.dof, dtype=torch.float64)  # a field set by hand stays set
    assert torch.equal(res.q, torch.zeros(1, robot.dof, dtype=torch.float64))


def test_threads_share_a_solver_on_the_one_pose_path():
    from concurrent.futures import ThreadPoolExecutor

    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    T = _poses(robot, 16, seed=12)
    alone = [solver.solve(T[i]).q for i in range(16)]
    with warnings.catch_warnings(), ThreadPoolExecutor(2) as pool:
        together = list(pool.map(lambda i: solver.solve(T[i]).q, range(16)))
    assert all(torch.equal(a, b) for a, b in zip(alone, together, strict=True))


def _kept_ways():
    """Ways a caller keeps something of a tensor pose's result: each takes the result and returns what is kept."""
    return {
        "result": lambda r: r,
        "q": lambda r: r.q,
        "success": lambda r: r.success,
        "slice": lambda r: r.q[:, :3],
        "view": lambda r: r.q.view(-1),
        "detach": lambda r: r.q.detach(),
        "data": lambda r: r.q.data,
        "numpy": lambda r: r.q.numpy(),
        "asarray": lambda r: np.asarray(r.success),
        "storage": lambda r: r.q.untyped_storage(),
        "from_dlpack": lambda r: torch.from_dlpack(r.q),
        "np_from_dlpack": lambda r: np.from_dlpack(r.q),
        "dlpack_capsule": lambda r: torch.utils.dlpack.from_dlpack(torch.utils.dlpack.to_dlpack(r.q)),
        "pos_err": lambda r: r.pos_err,
        "iterations_slice": lambda r: r.iterations[:1],
        "reachable_numpy": lambda r: r.reachable.numpy(),
        "replace": lambda r: dataclasses.replace(r),
        "as_numpy": lambda r: r.numpy(),
        "list": lambda r: [r],
        "weakref": lambda r: weakref.ref(r.q),
    }


def _values(kept):
    """A copy of the values of something kept from a result."""
    if isinstance(kept, IKResult):
        return np.asarray(kept.q).copy(), np.asarray(kept.success).copy()
    if isinstance(kept, list):
        return [_values(k) for k in kept]
    if isinstance(kept, weakref.ref):
        return _values(kept())
    if isinstance(kept, torch.UntypedStorage):
        return kept.tolist()
    if isinstance(kept, torch.Tensor):
        return kept.detach().clone().numpy()
    return np.array(kept, copy=True)


def _same_values(a, b):
    if isinstance(a, list):
        return len(a) == len(b) and all(_same_values(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, tuple):
        return all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    return np.array_equal(a, b)


@pytest.mark.parametrize("way", list(_kept_ways()))
def test_what_a_caller_keeps_of_a_tensor_result_never_changes_after_later_calls(way):
    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    T = _poses(robot, 10, seed=13)
    T[1:9, 0, 3] += 3.0  # the later poses out of reach: every field of their answers differs (LM's best effort)
    solver.solve(T[9])  # the entry made
    kept = _kept_ways()[way](solver.solve(T[0]))
    then = _values(kept)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        for i in range(1, 9):  # later calls, their results dropped
            res = solver.solve(T[i])
            _assert_same(res, _general(solver, T[i]))
            del res
    assert _same_values(_values(kept), then)


_CHANGES = {  # what a caller may do to a result's q and success before dropping it
    "squeeze_": lambda q, ok: q.squeeze_(0),
    "unsqueeze_success": lambda q, ok: ok.unsqueeze_(0),
    "transpose_": lambda q, ok: q.transpose_(0, 1),
    "as_strided_": lambda q, ok: q.as_strided_((1, q.shape[1] - 1), (q.shape[1], 1), 1),
    "requires_grad_": lambda q, ok: q.requires_grad_(True),
    "grad": lambda q, ok: setattr(q, "grad", torch.ones_like(q)),
    "success_grad": lambda q, ok: setattr(ok, "grad", torch.ones_like(ok)),
    "share_memory_": lambda q, ok: q.share_memory_(),
    "set_": lambda q, ok: q.set_(torch.zeros(q.shape, dtype=torch.float64)),
    "mul_": lambda q, ok: q.mul_(0.0),
}


@pytest.mark.parametrize("change", list(_CHANGES))
def test_a_dropped_tensor_result_changed_by_its_caller_leaves_later_results_as_made(change):
    robot = nik.load_robot("ur5")
    solver = nik.IKSolver(robot)
    T = _poses(robot, 8, seed=14)
    solver.solve(T[7])
    res = solver.solve(T[0])
    _CHANGES[change](res.q, res.success)
    del res
    for i in range(1, 7):
        res = solver.solve(T[i])
        _assert_same(res, _general(solver, T[i]))
        assert not res.q.requires_grad and res.q.grad is None and res.success.grad is None
        assert res.q.is_contiguous() and res.success.shape == (1,)
        del res


def test_a_loop_keeping_its_previous_result_gets_fresh_answers():
    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    T = _poses(robot, 12, seed=15)
    res, previous = solver.solve(T[11]), []
    for i in range(11):
        prev = res
        res = solver.solve(T[i])  # the previous result is held while this call runs
        assert res.q.data_ptr() != prev.q.data_ptr()
        previous.append((prev, prev.q.clone()))
        _assert_same(res, _general(solver, T[i]))
    assert all(torch.equal(p.q, v) for p, v in previous)


def test_one_pose_uses_no_private_torch_api():
    import inspect

    from nik.ik.backends import one_pose

    src = inspect.getsource(one_pose)
    assert "torch._C" not in src and "getrefcount" not in src and "_storage_Use_Count" not in src


def test_threads_calling_at_once_get_their_own_answers():
    from concurrent.futures import ThreadPoolExecutor

    robot = nik.load_robot("panda")
    solver = nik.IKSolver(robot)
    T = _poses(robot, 24, seed=16)
    expected = [solver.solve(T[i]).q.clone() for i in range(24)]

    def run(start):
        wrong = 0
        for k in range(48):
            i = (start + k) % 24
            res = solver.solve(T[i])  # dropped at once
            wrong += not torch.equal(res.q, expected[i])
            del res
        return wrong

    with ThreadPoolExecutor(3) as pool:
        assert list(pool.map(run, (0, 8, 16))) == [0, 0, 0]
