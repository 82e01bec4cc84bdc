"""nik.collision.sdf: the static links' grids of signed distances (conservative against the exact distance, the
compiled rows against torch and finite differences, tight beside a flat face, checked by coal on the meshes)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import nik
from nik.collision import CollisionModel, collides, collision_model, signed_distances
from nik.collision.compiled import kernel_arguments, signed_distances_compiled
from nik.collision.sdf import BAND, grid_values, static_grid
from nik.collision.shapes import box_triangles

pytest.importorskip("scipy", reason="the distance grid needs scipy")

# a thin plate on the base (static) and a ball on a prismatic joint along z, then a revolute one: the ball's
# height above the plate is q[0] - 0.01 - 0.03 (the plate's top face at z = 0.01, the ball's radius 0.03); the
# slider's small ball (30 cm up) keeps the plate and the ball from being adjacent
URDF = """<?xml version="1.0"?>
<robot name="plate">
  <link name="plate"><collision><geometry><box size="0.6 0.6 0.02"/></geometry></collision></link>
  <link name="slider"><collision><origin xyz="0 0 0.3"/><geometry><sphere radius="0.01"/></geometry></collision>
  </link>
  <link name="ball"><collision><origin xyz="0.1 0 0"/><geometry><sphere radius="0.03"/></geometry></collision></link>
  <joint name="lift" type="prismatic"><parent link="plate"/><child link="slider"/><axis xyz="0 0 1"/>
    <limit lower="0.0" upper="0.4" effort="1" velocity="1"/></joint>
  <joint name="turn" type="revolute"><parent link="slider"/><child link="ball"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""

PITCH = 0.005


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


@pytest.fixture
def plate(tmp_path):
    path = tmp_path / "plate.urdf"
    path.write_text(URDF)
    return nik.load_robot(path, end_link="ball"), path


def _box_sdf(p, half):
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def test_grid_values_never_exceed_the_exact_signed_distance_of_a_rotated_box():
    half = np.array([0.15, 0.04, 0.08])
    a = 0.5
    R = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    centre = np.array([0.1, -0.2, 0.3])
    tri = box_triangles(2 * half) @ R.T + centre
    grid = static_grid(tri, 0.01)
    rows, flat = grid.row(0)[None], grid.values.ravel()
    rng = np.random.default_rng(3)
    p = centre + rng.uniform(-0.3, 0.3, size=(20000, 3))
    exact = _box_sdf((p - centre) @ R, half)
    v = grid_values(rows, flat, 0, p)
    assert (v <= exact + 1e-9).all()
    within = ((p >= grid.origin) & (p <= grid.origin + grid.pitch * (np.array(grid.values.shape) - 1))).all(axis=1)
    within &= np.abs(exact) < BAND - 0.01  # the band of the k-d tree (farther: lower by half a cell's diagonal more)
    assert within.sum() > 1000 and (exact - v)[within].max() <= grid.bound + 1e-9
    assert (v[exact < -0.02] < 0).all()  # deep inside is inside
    near_face = (np.abs(exact) < 0.05) & (exact > 0)
    assert np.median((exact - v)[near_face]) < 0.012  # a centimetre pitch loses about a centimetre


def test_the_interpolation_bound_holds_in_a_cell():
    rng = np.random.default_rng(0)
    t = rng.uniform(size=(50000, 3))
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    w = np.prod(np.where(corners[None] == 1, t[:, None], 1 - t[:, None]), axis=2)
    reach = (w * np.linalg.norm(t[:, None] - corners[None], axis=2)).sum(axis=1)
    assert reach.max() <= math.sqrt(3) / 2 + 1e-12


def test_a_static_plate_gets_a_grid_that_saves_and_loads(plate, tmp_path):
    robot, _ = plate
    model = collision_model(robot, grid_pitch=PITCH)
    assert set(model.grids) == {"plate"}
    assert model.gaps[model.links.index("plate")] == pytest.approx(model.grids["plate"].bound)
    assert ("plate", "ball") in model.pair_names()
    back = CollisionModel.load(model.save(tmp_path / "m.json"), robot)
    assert np.array_equal(back.grids["plate"].values, model.grids["plate"].values)
    q = torch.tensor([[0.05, 0.3], [0.03, -1.0]], dtype=torch.float64)
    assert torch.equal(signed_distances(robot, q, model=back), signed_distances(robot, q, model=model))
    assert collision_model(robot, grid_pitch=None).grids is None


def test_touching_the_plate_collides_and_15_mm_above_its_face_is_free(plate):
    robot, _ = plate
    q = np.array([[0.035, 0.4], [0.04 + 0.015, 0.4], [0.2, 0.0]])  # 5 mm into the plate, 15 mm above, far
    model = collision_model(robot, grid_pitch=PITCH)
    assert collides(robot, q, model=model).tolist() == [True, False, False]
    assert collides(robot, torch.as_tensor(q), model=model, compiled=False).tolist() == [True, False, False]
    spheres_only = collision_model(robot, grid_pitch=None)
    assert collides(robot, q, model=spheres_only).tolist() == [True, True, False]  # the plate's spheres reach out
    g = torch.Generator().manual_seed(2)
    qs = torch.rand(200, 2, generator=g, dtype=torch.float64) * torch.tensor([0.2, 6.0]) + torch.tensor([0.0, -3.0])
    with_grid, without = signed_distances(robot, qs, model=model), signed_distances(robot, qs, model=spheres_only)
    assert (with_grid >= without).all() and (with_grid > without + 0.005).any()  # the larger of two lower bounds


def test_compiled_rows_and_jacobian_match_torch_and_finite_differences_on_a_grid(plate):
    robot, _ = plate
    model = collision_model(robot, grid_pitch=PITCH)
    p = model.pair_names().index(("plate", "ball"))
    g = torch.Generator().manual_seed(5)
    q = torch.stack([torch.rand(40, generator=g, dtype=torch.float64) * 0.2,
                     torch.rand(40, generator=g, dtype=torch.float64) * 6 - 3], dim=1)  # fmt: skip
    q[:, 0] = q[:, 0] + 1e-4
    ours = signed_distances_compiled(robot, q.numpy(), model=model)
    ref = signed_distances(robot, q, model=model).numpy()
    assert np.allclose(ours, ref, atol=1e-9)
    assert (ref[:, p] < 0).any() and (ref[:, p] > 0).any()
    from nik.kernels.collision import collision_distances

    (G, joints), rest = kernel_arguments(robot, model)
    R = len(model.pairs) + len(model.links)
    eps = 1e-6
    for qi in q.numpy()[:10]:
        d, J = np.empty(R), np.empty((R, robot.dof))
        collision_distances(G, joints, qi, *rest, d, J)
        for m in range(robot.dof):
            step = np.zeros(robot.dof)
            step[m] = eps
            hi, lo = np.empty(R), np.empty(R)
            collision_distances(G, joints, qi + step, *rest, hi, np.empty((R, robot.dof)))
            collision_distances(G, joints, qi - step, *rest, lo, np.empty((R, robot.dof)))
            assert J[p, m] == pytest.approx((hi[p] - lo[p]) / (2 * eps), abs=1e-5)
    qt = q[:10].clone().requires_grad_(True)
    signed_distances(robot, qt, model=model)[:, p].sum().backward()
    d, J = np.empty(R), np.empty((R, robot.dof))
    for b in range(10):
        collision_distances(G, joints, q.numpy()[b], *rest, d, J)
        assert np.allclose(qt.grad[b].numpy(), J[p], atol=1e-9)


def test_the_grid_never_calls_free_what_the_meshes_call_colliding(plate):
    pytest.importorskip("coal", reason="the mesh check needs coal (extra collision-check)")
    from nik.collision.meshcheck import MeshCheck

    robot, path = plate
    model = collision_model(robot, grid_pitch=PITCH)
    g = torch.Generator().manual_seed(7)
    q = torch.stack([torch.rand(400, generator=g, dtype=torch.float64) * 0.1,
                     torch.rand(400, generator=g, dtype=torch.float64) * 6 - 3], dim=1).numpy()  # fmt: skip
    theirs = MeshCheck(robot, path).collides(q, None)
    ours = collides(robot, q, model=model)
    assert theirs.any() and (~ours).any()
    assert not (theirs & ~ours).any()
