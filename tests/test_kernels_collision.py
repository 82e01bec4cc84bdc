"""The arguments of the collision kernels (nik/kernels/collision.py, nik/kernels/collision_lm.py): the arrays travel
as a few named groups, and the rows computed through them are the torch reference's."""

from __future__ import annotations

import inspect

import numpy as np
import pytest
import torch

import nik
import nik.kernels.collision as kc
import nik.kernels.collision_lm as clm
from nik.collision import collision_model, collision_residual
from nik.collision.compiled import kernel_arguments


def _world() -> nik.World:
    world = nik.World().add_box([0.45, 0.2, 0.35], [0.12, 0.12, 0.12]).add_sphere([0.35, -0.3, 0.5], 0.06)
    return world.add_box([0.0, 0.0, -0.05], [2.0, 2.0, 0.1])


@pytest.mark.parametrize("module", [kc, clm], ids=["collision", "collision_lm"])
def test_every_collision_kernel_takes_at_most_twelve_parameters(module):
    counts = {}
    for name, obj in vars(module).items():
        fn = getattr(obj, "py_func", obj)  # a kernel is a numba dispatcher over its Python function
        if inspect.isfunction(fn) and fn.__module__ == module.__name__:
            counts[name] = len(inspect.signature(fn).parameters)
    assert len(counts) >= 6  # the module's functions were found
    over = {name: k for name, k in counts.items() if k > 12}
    assert not over, f"more than 12 parameters: {over}"


def test_the_groups_hold_the_models_and_the_worlds_arrays_in_the_kernels_order():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    world = _world()
    (G, joints), (arm, scene) = kernel_arguments(robot, model, world, self_collision=False)
    assert isinstance(arm, kc.ArmSpheres) and isinstance(scene, kc.Scene)
    for got, want in zip(arm[:4], model.arrays(), strict=True):
        np.testing.assert_array_equal(got, want)
    assert arm.self_on is False
    for got, want in zip(scene, world.packed(), strict=True):
        np.testing.assert_array_equal(got, want)
    assert scene.spheres.shape == (1, 4) and scene.boxes.shape == (2, 15) and scene.capsules.shape[0] == 0
    assert G.shape == (robot.dof + 1, 4, 4) and joints.shape[0] == robot.dof


@pytest.mark.parametrize("self_collision", [True, False])
def test_the_residual_through_the_groups_is_the_torch_references(self_collision):
    """:func:`nik.kernels.collision.collision_residual` given ``(arm, scene)`` against the torch rows
    ``max(0, margin - d)`` of :func:`nik.collision.collision_residual`, the Jacobian against central differences."""
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    world = _world()
    q = robot.sample(6, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    ref = collision_residual(robot, q, world, margin=0.05, model=model, self_collision=self_collision).numpy()
    (G, joints), rest = kernel_arguments(robot, model, world, self_collision=self_collision)
    R = len(model.pairs) + len(model.links)
    assert ref.shape == (6, R) and (ref > 0).any()  # some rows within the margin: the test bites
    for b, q0 in enumerate(q.numpy()):
        r, J = np.empty(R), np.empty((R, robot.dof))
        kc.collision_residual(G, joints, q0, *rest, 0.05, r, J)
        np.testing.assert_allclose(r, ref[b], atol=1e-9)
        for k in range(robot.dof):
            e = np.zeros(robot.dof)
            e[k] = 1e-6
            rp, rm, scratch = np.empty(R), np.empty(R), np.empty((R, robot.dof))
            kc.collision_residual(G, joints, q0 + e, *rest, 0.05, rp, scratch)
            kc.collision_residual(G, joints, q0 - e, *rest, 0.05, rm, scratch)
            smooth = ((r > 1e-4) & (rp > 0) & (rm > 0)) | ((r == 0) & (rp == 0) & (rm == 0))  # off the hinge
            np.testing.assert_allclose(J[smooth, k], ((rp - rm) / 2e-6)[smooth], atol=1e-5)
