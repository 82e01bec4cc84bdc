"""Distances between the real collision meshes as LM rows (nik/collision/mesh_distance.py, nik/costs/mesh.py):
the rows' Jacobian against finite differences, apart and overlapping, and the distances against coal's verdict."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nik
from nik.collision import collision_model


@pytest.fixture(scope="module")
def panda_check():
    """The built-in panda and the mesh check of example-robot-data's panda (coal)."""
    pytest.importorskip("coal", reason="the mesh distances need coal (pip install 'nik-ik[collision-check]')")
    from nik.collision.meshcheck import fitted_urdf, mesh_check

    robot = nik.load_robot("panda")
    model = collision_model(robot)
    if fitted_urdf(model) is None:
        pytest.skip("example-robot-data's panda (with meshes) is not installed")
    return robot, mesh_check(robot, model, required=True)


def _fd_rows(md, q: np.ndarray, margin: float, eps: float = 1e-6) -> np.ndarray:
    """``(M, dof)`` central differences of the rows at ``q: (dof,)``."""
    out = np.zeros((len(md), q.size))
    for j in range(q.size):
        qp, qm = q.copy(), q.copy()
        qp[j] += eps
        qm[j] -= eps
        out[:, j] = (md.rows_at(qp[None], margin)[0][0] - md.rows_at(qm[None], margin)[0][0]) / (2 * eps)
    return out


def test_mesh_rows_jacobian_matches_finite_differences_apart_and_overlapping(panda_check):
    from nik.collision.mesh_distance import MeshDistance

    robot, check = panda_check
    q = robot.sample(6, generator=torch.Generator().manual_seed(0), dtype=torch.float64).numpy()
    hand = check.links.index("panda_hand")
    tf = check._transforms(q[0])[hand]
    vertex = np.asarray(check._geoms[hand].vertices())[0]
    out = vertex - np.asarray(check._geoms[hand].vertices()).mean(0)  # outwards from the hand's middle
    centre = np.asarray(tf.getRotation()) @ (vertex + 0.01 * out / np.linalg.norm(out)) + np.asarray(
        tf.getTranslation()
    )
    world = nik.World().add_sphere(centre, 0.03)  # 1 cm outside the hand's surface at q[0], overlapping
    md = MeshDistance(check, world)
    r, J, d = md.rows_at(q, 0.15)
    m = md.names.index("panda_hand|sphere 0")
    assert d[0, m] < 0 and r[0, m] > 0.15  # overlapping: the hulls' penetration, pushing
    assert check.collides(q[:1], world)[0]
    rows = 0
    for i in range(len(q)):
        active = r[i] > 0
        rows += int(active.sum())
        np.testing.assert_allclose(J[i][active], _fd_rows(md, q[i], 0.15)[active], atol=1e-6)
    assert rows >= 6


def test_mesh_distances_agree_with_coal_verdict(panda_check):
    from nik.collision.mesh_distance import MeshDistance

    robot, check = panda_check
    world = nik.World().add_box([0.45, 0.0, 0.3], [0.2, 0.2, 0.2]).add_sphere([0.0, 0.45, 0.5], 0.1)
    q = robot.sample(40, generator=torch.Generator().manual_seed(1), dtype=torch.float64).numpy()
    d = MeshDistance(check, world).rows_at(q, 0.005)[2]
    hit = check.collides(q, world)
    assert 0 < hit.sum() < len(q)
    np.testing.assert_array_equal(d.min(1) <= 1e-9, hit)


def test_mesh_term_autograd_matches_its_rows_and_checks_by_the_meshes(panda_check):
    from nik.costs.mesh import mesh_collision

    robot, check = panda_check
    world = nik.World().add_box([0.45, 0.0, 0.3], [0.2, 0.2, 0.2])
    term = mesh_collision(robot, world, margin=0.1, check=check)
    q = robot.sample(8, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    r, J = term.evaluate(q)
    x = q.clone().requires_grad_(True)
    w = torch.randn(r.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    (term.residual(x) * w).sum().backward()
    torch.testing.assert_close(x.grad, (w[:, None, :] @ J)[:, 0, :])
    np.testing.assert_array_equal(term.check(q).numpy(), ~check.collides(q.numpy(), world))
    with pytest.raises(ValueError, match="margin must be"):
        mesh_collision(robot, world, margin=-1.0, check=check)


def test_distance_asked_only_of_pairs_within_the_margin(panda_check, monkeypatch):
    """coal's collision query with the margin as security margin screens the pairs: the distance with its nearest
    points is asked only of those within the margin, and the rows, Jacobians and the verdict are those of coal's
    distance on every pair (a pair left out reports a lower bound at or above the margin)."""
    import coal

    from nik.collision.mesh_distance import MeshDistance

    robot, check = panda_check
    world = nik.World().add_box([0.45, 0.0, 0.3], [0.2, 0.2, 0.2]).add_sphere([0.0, 0.45, 0.5], 0.1)
    md = MeshDistance(check, world)
    q = robot.sample(30, generator=torch.Generator().manual_seed(5), dtype=torch.float64).numpy()
    margin = 0.02
    exact = np.empty((len(q), len(md)))  # the reference: coal's distance of every row
    for i, x in enumerate(q):
        tf = check._transforms(x)
        for m, (a, b) in enumerate(md.rows):
            gb, tb = (check._geoms[b], tf[b]) if b >= 0 else md._obstacles[-1 - b][:2]
            exact[i, m] = coal.distance(check._geoms[a], tf[a], gb, tb, coal.DistanceRequest(), coal.DistanceResult())
    asked = []
    pair = MeshDistance._pair
    monkeypatch.setattr(MeshDistance, "_pair", lambda self, *a: asked.append(1) or pair(self, *a))
    r, J, d = md.rows_at(q, margin)
    near = exact < margin
    assert len(asked) == near.sum() > 0  # the distance query of the near pairs only
    apart = near & (exact > 1e-9)
    np.testing.assert_allclose(d[apart], exact[apart], atol=1e-6)
    np.testing.assert_allclose(r[apart], margin - exact[apart], atol=1e-6)
    assert (d[~near] >= margin).all() and (r[~near] == 0).all() and (J[~near] == 0).all()
    np.testing.assert_array_equal(d.min(1) <= 1e-9, check.collides(q, world))
