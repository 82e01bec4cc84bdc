"""The built-in arms' collision models (nik/collision/builtin.py): shipped spheres fitted to the vendors' meshes,
conservative against them by coal; capsules, with a warning, where an arm has no meshes."""

from __future__ import annotations

import hashlib
import json
import shutil
import warnings

import numpy as np
import pytest
import torch

import nik
from nik.collision import builtin as shipped
from nik.collision import collides, collision_model, sphere_centers
from nik.errors import CollisionModelWarning

WITH_MESHES = ["panda", "ur5", "xarm7"]


def _scene(seed: int) -> nik.World:
    """A table under the arm (its top at z = 0) and 10 seeded boxes, spheres and capsules around it."""
    rng = np.random.default_rng(seed)
    world = nik.World().add_box([0.45, 0.0, -0.05], [0.9, 1.2, 0.1])
    for i in range(10):
        angle, r = rng.uniform(-np.pi, np.pi), rng.uniform(0.35, 0.7)
        c = np.array([r * np.cos(angle), r * np.sin(angle), rng.uniform(0.1, 0.8)])
        if i % 3 == 0:
            world.add_box(c, rng.uniform(0.05, 0.15, size=3))
        elif i % 3 == 1:
            world.add_sphere(c, rng.uniform(0.03, 0.08))
        else:
            world.add_capsule(c, c + rng.normal(size=3) * 0.1, rng.uniform(0.02, 0.05))
    return world


@pytest.mark.parametrize("name", WITH_MESHES)
def test_a_builtin_with_vendor_meshes_gets_its_shipped_sphere_model(name):
    robot = nik.load_robot(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CollisionModelWarning)  # no capsule warning: the model is the meshes'
        model = collision_model(robot)
    assert model.source == f"example-robot-data:{shipped.BUILTIN_MESHES[name][0]}"
    assert model.robot_hash == robot.definition_hash and model.options["builtin"] == name
    assert len(model.pairs) > 0 and np.isfinite(model.gaps).all()
    path = shipped.MODEL_DIR / f"{name}.collision.json"
    assert hashlib.sha256(path.read_bytes()).hexdigest() == shipped.CHECKSUMS[name]
    assert path.stat().st_size < 200_000  # small data
    # the same arm with another end link and a base keeps it, its base-link spheres carried by the base
    base = np.eye(4)
    base[:3, 3] = [0.3, -0.2, 0.1]
    moved = nik.load_robot(name, base=base)
    q = robot.sample(5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    there = sphere_centers(collision_model(moved), moved, q)
    here = sphere_centers(model, robot, q)
    np.testing.assert_allclose(there.numpy(), here.numpy() + base[:3, 3], atol=1e-9)


def test_pair_options_find_the_pairs_again_on_the_shipped_spheres():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    assert any(v.startswith("srdf: ") for v in model.left_out.values())  # MoveIt's SRDF of the vendor's arm
    every = collision_model(robot, srdf=False, samples=0)  # all pairs but adjacent and same frame
    np.testing.assert_array_equal(every.radii, model.radii)
    assert len(every.pairs) > len(model.pairs)
    assert not any(v.startswith("srdf") for v in every.left_out.values())
    again = collision_model(robot, samples=0)  # the SRDF's pairs still left out
    assert {k for k, v in again.left_out.items() if v.startswith("srdf")} == {
        k for k, v in model.left_out.items() if v.startswith("srdf")
    }


def test_a_changed_shipped_file_is_refused(tmp_path, monkeypatch):
    folder = tmp_path / "collision"
    shutil.copytree(shipped.MODEL_DIR, folder)
    data = json.loads((folder / "ur5.collision.json").read_text())
    data["radii"][0] *= 0.5  # a shrunken sphere: no longer conservative
    (folder / "ur5.collision.json").write_text(json.dumps(data))
    monkeypatch.setattr(shipped, "MODEL_DIR", folder)
    monkeypatch.setattr(shipped, "_SHIPPED", {})
    with pytest.raises(ValueError, match="ur5.collision.json: checksum .* is not the one recorded"):
        collision_model(nik.load_robot("ur5"))


@pytest.mark.parametrize("name", ["kuka_kr", "puma560"])
def test_an_arm_without_meshes_keeps_capsules_and_says_so_once(name):
    robot = nik.load_robot(name)
    with pytest.warns(CollisionModelWarning, match=r"capsules of 50 mm .* an approximation .* radius=.* meshes"):
        model = collision_model(robot)
    assert model.source == "capsules"
    with warnings.catch_warnings():
        warnings.simplefilter("error", CollisionModelWarning)
        collision_model(robot)  # once per robot
        collision_model(nik.load_robot(name), radius=0.08)  # radii given: no warning
        collision_model(nik.load_robot(name), source="capsules")  # capsules asked for
    with pytest.raises(ValueError, match="no shipped collision model"):
        collision_model(robot, source="builtin")


@pytest.mark.parametrize("name", WITH_MESHES)
def test_the_shipped_model_calls_nothing_free_that_the_vendor_meshes_call_colliding(name):
    pytest.importorskip("coal", reason='coal not installed (pip install -e ".[collision-check]")')
    pytest.importorskip("trimesh", reason='trimesh not installed (pip install -e ".[collision-check]")')
    urdf = shipped.erd_path(shipped.BUILTIN_MESHES[name][0])
    if urdf is None:
        pytest.skip('example-robot-data not installed (pip install -e ".[urdf-tests]")')
    from nik.collision.meshcheck import mesh_check

    robot = nik.load_robot(name)
    model = collision_model(robot)
    mesh = mesh_check(robot, model, required=True)  # the meshes the model names, MoveIt's pairs
    assert mesh.links == model.links
    q = robot.sample(300, generator=torch.Generator().manual_seed(7), dtype=torch.float64).numpy()
    for label, world in (("self", None), ("scene", _scene(7))):
        ours, theirs = collides(robot, q, world), mesh.collides(q, world)
        free = ~theirs
        assert not (~ours & theirs).any(), f"{name} {label}: called free, colliding by the meshes"
        assert free.sum() >= 30  # enough free configurations to say something
        share = (ours & free).sum() / free.sum()
        print(f"{name} {label}: {free.sum()} of {len(q)} free by the meshes, {share:.1%} of them called colliding")
        assert share < 0.5  # tight enough to be of use (the shares measured are in docs/collisions.md)
