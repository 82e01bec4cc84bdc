"""nik.collision: conservative spheres, pairs, the world, distances (torch vs compiled, finite differences), files,
and the mesh check (coal) on a small URDF of primitives."""

from __future__ import annotations

import json
import math
import os
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import nik
from nik.collision import (
    CollisionModel,
    World,
    collides,
    colliding_links,
    collision_model,
    collision_names,
    set_collision_model,
    signed_distances,
)
from nik.collision.compiled import kernel_arguments, signed_distances_compiled
from nik.collision.fit import fit_spheres
from nik.collision.shapes import box_triangles, cylinder_triangles, sphere_triangles

URDF = """<?xml version="1.0"?>
<robot name="prims">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.04" length="0.2"/></geometry>
  </collision></link>
  <link name="l2"><collision><origin xyz="0 0 0.15"/><geometry><box size="0.05 0.05 0.3"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0 0 0.1"/><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><origin xyz="0 0 0.2"/><geometry><capsule radius="0.03" length="0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2.9" upper="2.9" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


@pytest.fixture
def prims(tmp_path):
    path = tmp_path / "prims.urdf"
    path.write_text(URDF)
    return nik.load_robot(path, end_link="l3"), path


def _world():
    return (
        World()
        .add_sphere([0.3, 0.0, 0.3], 0.1)
        .add_box(np.array([0.5, 0.1, 0.2, 0.9, 0.2, 0.1, 0.3]), [0.2, 0.3, 0.1])
        .add_capsule([0.0, 0.5, 0.0], [0.0, 0.5, 1.0], 0.05)
    )


def _q(robot, n, seed):
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


# -- the spheres are conservative ---------------------------------------------------
def _inside(points, fit):
    d = np.linalg.norm(points[:, None] - fit.centers[None], axis=2) - fit.radii[None]
    return (d <= 1e-12).any(axis=1)


def test_spheres_hold_every_surface_point_of_a_box():
    rng = np.random.default_rng(0)
    size = np.array([0.3, 0.1, 0.05])
    fit = fit_spheres(box_triangles(size), seed=0)
    p = rng.uniform(-size / 2, size / 2, size=(20000, 3))
    face = rng.integers(3, size=len(p))
    p[np.arange(len(p)), face] = np.sign(rng.normal(size=len(p))) * size[face] / 2  # on the faces
    assert _inside(p, fit).all()
    assert fit.gap > 0 and fit.volume_ratio >= 1.0


def test_spheres_hold_every_surface_point_of_a_cylinder():
    rng = np.random.default_rng(1)
    r, length = 0.05, 0.2
    fit = fit_spheres(cylinder_triangles(r, length), tolerance=0.02, seed=0)
    a = rng.uniform(0, 2 * math.pi, 20000)
    z = rng.uniform(-length / 2, length / 2, 20000)
    side = np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)
    assert _inside(side, fit).all()


def test_a_urdf_sphere_is_held_by_one_ball_that_reaches_out_millimetres_not_centimetres():
    from nik.collision.model import _fit_link
    from nik.collision.urdf import Body

    tri = sphere_triangles(0.22) + np.array([0.1, -0.2, 0.7])  # Baxter's head ball, off the frame's origin
    many = fit_spheres(tri, seed=0)
    for frame in (0, 3):  # a static link and a moving one
        fit = _fit_link(Body("head", frame, tri), tolerance=0.005, max_spheres=16, seed=0)
        assert len(fit.radii) == 1 and fit.gap < 0.005 < many.gap
        assert _inside(tri.reshape(-1, 3), fit).all()  # still an exact cover: every corner inside


def test_refined_spheres_still_hold_every_surface_point_and_reach_out_less():
    rng = np.random.default_rng(3)
    size = np.array([0.3, 0.1, 0.05])
    greedy = fit_spheres(box_triangles(size), tolerance=0.01, max_spheres=8, seed=0)
    refined = fit_spheres(box_triangles(size), tolerance=0.01, max_spheres=8, seed=0, refine=6)
    p = rng.uniform(-size / 2, size / 2, size=(20000, 3))
    face = rng.integers(3, size=len(p))
    p[np.arange(len(p)), face] = np.sign(rng.normal(size=len(p))) * size[face] / 2  # on the faces
    assert _inside(p, refined).all()
    assert len(refined.radii) <= 8
    assert refined.volume_ratio < greedy.volume_ratio


def test_a_non_convex_body_is_not_held_by_balls_centred_outside_it():
    pytest.importorskip("scipy", reason="telling the inside of a body needs scipy")
    legs = [box_triangles([0.08, 0.08, 0.4]) + [x, 0.0, 0.0] for x in (-0.25, 0.25)]  # a table: two legs, a top
    table = np.concatenate([*legs, box_triangles([0.58, 0.08, 0.04]) + [0.0, 0.0, 0.22]])
    fit = fit_spheres(table, seed=0)
    assert _inside(table.reshape(-1, 3), fit).all()  # conservative: every corner held
    assert fit.gap < 0.1  # a ball centred between the legs, holding both, reaches 0.3 m past them


def test_capsule_model_holds_the_capsules(prims):
    robot = nik.load_robot("ur5")
    model = collision_model(robot, radius=0.04)
    rng = np.random.default_rng(2)
    G = robot.G.numpy()
    for link, frame in zip(model.links, model.frames, strict=True):
        c, rad = model.spheres(link)
        end = G[frame, :3, 3]
        t = rng.uniform(size=(3000, 1))
        n = rng.normal(size=(3000, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        pts = t * end + 0.04 * n  # points of the capsule's surface (and the caps)
        assert ((np.linalg.norm(pts[:, None] - c[None], axis=2) - rad[None]) <= 1e-12).any(axis=1).all()


# -- pairs --------------------------------------------------------------------
@pytest.mark.long
def test_adjacent_and_same_frame_pairs_are_left_out(prims):
    robot, _ = prims
    model = collision_model(robot)
    assert model.left_out["base|l1"] == "adjacent"
    assert model.left_out["l1|l2"] == "adjacent"
    names = model.pair_names()
    assert all(b not in ("l1",) or a != "base" for a, b in names)


@pytest.mark.long
def test_pairs_an_srdf_disables_are_left_out(prims):
    robot, path = prims
    assert ("base", "l3") in collision_model(robot).pair_names()
    path.with_suffix(".srdf").write_text(
        '<robot name="prims"><disable_collisions link1="l3" link2="base" reason="Never"/></robot>'
    )
    fresh = nik.load_robot(path, end_link="l3")
    model = collision_model(fresh)
    assert ("base", "l3") not in model.pair_names() and model.left_out["base|l3"] == "srdf: Never"
    assert ("base", "l3") in collision_model(fresh, srdf=False).pair_names()


def test_an_srdf_given_by_path_disables_its_pairs(prims, tmp_path):
    robot, path = prims
    srdf = tmp_path / "elsewhere" / "moveit_config.srdf"  # neither beside the URDF nor named as it
    srdf.parent.mkdir()
    srdf.write_text('<robot name="prims"><disable_collisions link1="l3" link2="base" reason="Never"/></robot>')
    assert ("base", "l3") in collision_model(robot).pair_names()  # the search does not find it
    given = nik.load_robot(path, end_link="l3", srdf=srdf)
    model = collision_model(given)
    assert ("base", "l3") not in model.pair_names() and model.left_out["base|l3"] == "srdf: Never"
    assert model.options["srdf_file"] == str(srdf)
    assert ("base", "l3") not in collision_model(robot, srdf=srdf).pair_names()  # or to collision_model
    assert ("base", "l3") in collision_model(given, srdf=False).pair_names()
    with pytest.raises(ValueError, match="SRDF file not found") as err:
        nik.load_robot(path, end_link="l3", srdf=tmp_path / "missing.srdf")
    assert "\n" not in str(err.value)


def test_the_srdf_search_takes_the_single_srdf_of_a_sibling_folder_and_says_so(tmp_path, caplog):
    pkg = tmp_path / "prims_description"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "srdf").mkdir()
    path = pkg / "urdf" / "prims.urdf"
    path.write_text(URDF)
    srdf = pkg / "srdf" / "prims_manipulation.srdf"  # Baxter's layout: not named as the URDF
    srdf.write_text('<robot name="prims"><disable_collisions link1="l3" link2="base" reason="Never"/></robot>')
    with caplog.at_level("INFO", logger="nik.collision"):
        model = collision_model(nik.load_robot(path, end_link="l3"))
    assert model.left_out["base|l3"] == "srdf: Never" and model.options["srdf_file"] == str(srdf)
    assert str(srdf) in caplog.text
    (pkg / "srdf" / "prims_other.srdf").write_text("<robot/>")  # two: none guessed, a warning names them
    with pytest.warns(nik.CollisionModelWarning, match="prims_manipulation.srdf, prims_other.srdf"):
        model = collision_model(nik.load_robot(path, end_link="l3"))
    assert ("base", "l3") in model.pair_names() and model.options["srdf_file"] is None


# two arms on a torso: the right arm is the robot's chain, the left one the rest of the robot
ARMS = (
    """<?xml version="1.0"?>
<robot name="twoarm">
  <link name="torso"><collision><origin xyz="0 0 0.25"/><geometry><box size="0.1 0.1 0.5"/></geometry></collision>
  </link>
"""
    + "".join(
        f'''  <link name="{s}_{part}"><collision><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.05 0.05"/></geometry>
  </collision></link>
'''
        for s in "rl"
        for part in ("upper", "fore")
    )
    + "".join(
        f'''  <joint name="{s}_s0" type="revolute"><parent link="torso"/><child link="{s}_upper"/>
    <origin xyz="0 {y} 0.6"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="{s}_e0" type="revolute"><parent link="{s}_upper"/><child link="{s}_fore"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
'''
        for s, y in (("r", -0.3), ("l", 0.3))
    )
    + """  <link name="r_hand"/>
  <joint name="r_hand_joint" type="fixed"><parent link="r_fore"/><child link="r_hand"/><origin xyz="0.4 0 0"/></joint>
</robot>
"""
)


def test_joint_values_bring_the_rest_of_the_robot_in(tmp_path):
    path = tmp_path / "twoarm.urdf"
    path.write_text(ARMS)
    away = nik.load_robot(path, end_link="r_hand")  # the left arm along x at y = +0.3, 0.6 m from the right one
    brought = nik.load_robot(path, end_link="r_hand", joint_values={"l_s0": -1.0})  # its forearm over the right's
    assert away.joint_names == ["r_s0", "r_e0"] and brought.joint_values == {"l_s0": -1.0}
    q = np.zeros((1, 2))  # the right arm straight along x at y = -0.3
    assert not collides(away, q)[0]
    assert collides(brought, q)[0]
    assert any(name.endswith("|l_fore") for name in collision_names(brought, q)[0])
    left = collision_model(brought).spheres("l_fore")[0]  # the left forearm's spheres where it stands
    c, s = math.cos(-1.0), math.sin(-1.0)
    elbow = np.array([0.4 * c, 0.3 + 0.4 * s, 0.6])
    hand = elbow + 0.4 * np.array([c, s, 0.0])
    t = np.clip((left - elbow) @ (hand - elbow) / 0.16, 0, 1)
    assert np.linalg.norm(left - (elbow + t[:, None] * (hand - elbow)), axis=1).max() < 0.05
    pytest.importorskip("coal", reason="the mesh check needs coal (extra collision-check)")
    from nik.collision.meshcheck import MeshCheck

    assert not MeshCheck(away, path).collides(q)[0] and MeshCheck(brought, path).collides(q)[0]


def test_baxters_left_arm_brought_in_meets_the_right_arm_on_the_meshes():
    pytest.importorskip("coal", reason="the mesh check needs coal (extra collision-check)")
    from nik.collision.builtin import erd_path
    from nik.collision.meshcheck import MeshCheck
    from nik.collision.model import find_srdf, srdf_disabled

    urdf = erd_path("baxter_description/urdf/baxter.urdf")
    if urdf is None:
        pytest.skip("Baxter's URDF comes with example-robot-data (extra urdf-tests)")
    srdf, _ = find_srdf(urdf)
    assert srdf is not None and srdf.name == "baxter_manipulation.srdf"  # the only one of ../srdf/
    skip = list(srdf_disabled(srdf))
    arm = {"root_link": "torso", "end_link": "right_hand_link"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nik.RobotDefinitionWarning)
        away = nik.load_robot(urdf, **arm)
        brought = nik.load_robot(urdf, **arm, joint_values={"left_s0": -0.8})  # the left arm swung in front
    q = _q(away, 100, 0).numpy()
    free_away = ~MeshCheck(away, urdf, skip=skip).collides(q)
    check = MeshCheck(brought, urdf, skip=skip)
    hit = check.collides(q)
    assert free_away.sum() >= 50 and (free_away & hit).sum() >= 2
    for names in check.collision_names(q[free_away & hit]):
        assert any("left_" in name for name in names)


_LARGE_FIT = """
import resource, sys
import nik
import nik.collision.model as cm
from nik.collision import collision_model
cm.PROGRESS_AFTER = 0.0  # a progress line from the start (a real fit says so after 2 s)
robot = nik.load_robot("panda")
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
model = collision_model(robot, source="capsules", radius=0.002, samples=1000, cache=False)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
n = {name: len(model.spheres(name)[1]) for name in model.links}
sampled = [k.split("|") for k, why in model.left_out.items() if why in ("always", "never")] + model.pair_names()
print(before, after, sum(n[a] * n[b] for a, b in sampled))
"""


def test_a_large_fit_samples_its_pairs_in_bounded_memory(tmp_path):
    import subprocess

    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "PYTHONPATH": str(Path(nik.__file__).parents[1])}
    run = subprocess.run([sys.executable, "-c", _LARGE_FIT], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    before, after, sphere_pairs = (int(x) for x in run.stdout.split())
    assert sphere_pairs * 1000 * 24 > 3e9  # one (samples, sphere pairs, 3) float64 array: what sampling at once took
    assert (after - before) * 1024 < 200e6  # ru_maxrss is in KiB on Linux
    assert "nik: collision model of 'panda': sampling 1000 configurations for the link pairs" in run.stderr


def test_links_whose_spheres_overreach_their_geometry_are_named_with_the_figure(prims, monkeypatch):
    import nik.collision.model as cm

    robot, _ = prims
    monkeypatch.setattr(cm, "OVERREACH_WARNING", 0.0)  # every link then counts (the prims' gaps are millimetres)
    with pytest.warns(nik.CollisionModelWarning, match="reach more than 0 mm past their meshes") as got:
        model = collision_model(robot)
    (msg,) = [str(w.message) for w in got if "past their meshes" in str(w.message)]
    assert "\n" not in msg
    for name, gap in zip(model.links, model.gaps, strict=True):
        assert f"{name} {1000 * gap:.0f} mm" in msg
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        collision_model(robot)  # said once per robot and model


PLATES = """<?xml version="1.0"?>
<robot name="plates">
  <link name="table"><collision><geometry><box size="0.5 0.5 0.02"/></geometry></collision></link>
  <link name="tray"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.3 0.3 0.01"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute"><parent link="table"/><child link="tray"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""


def _box_overreach(centers, radii, half) -> float:
    """The largest distance from a point of the union of spheres' boundary (4096 a sphere, those inside no other
    sphere) to the box of half sizes ``half`` centred at the origin: the analytic overreach."""
    from nik.collision.fit import _fibonacci

    pts = (centers[:, None] + radii[:, None, None] * _fibonacci(4096)[None]).reshape(-1, 3)
    out = ~(np.linalg.norm(pts[:, None] - centers[None], axis=2) < radii[None] - 1e-9).any(axis=1)
    return float(np.linalg.norm(np.maximum(np.abs(pts[out]) - half, 0.0), axis=1).max())


@pytest.mark.long  # 71 s: two fits of 16-256 spheres and their exact covers
def test_static_and_overreaching_links_get_more_spheres_and_stay_conservative(tmp_path):
    path = tmp_path / "plates.urdf"
    path.write_text(PLATES)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(path, end_link="tray")
        model = collision_model(robot, samples=0)
    rng = np.random.default_rng(3)
    for link, half, centre, frame in (("table", [0.25, 0.25, 0.01], [0, 0, 0], 0), ("tray", [0.15, 0.15, 0.005],
                                                                              [0, 0, 0.2], 1)):  # fmt: skip
        half, centre = np.array(half), np.array(centre, dtype=float)
        c, r = model.spheres(link)
        assert int(model.frames[model.links.index(link)]) == frame
        c = c - centre  # the box's frame (the tray's joint frame is the URDF link's: no rotation at q = 0)
        plain = fit_spheres(box_triangles(2 * half), max_spheres=16)  # what each link had: 16 spheres at most
        assert len(r) > 16
        assert _box_overreach(c, r, half) < 0.7 * _box_overreach(plain.centers, plain.radii, half)
        face = rng.uniform(-half, half, size=(4000, 3))  # points on the surface, each pushed to a face
        axis = rng.integers(0, 3, 4000)
        face[np.arange(4000), axis] = np.where(rng.random(4000) < 0.5, -1, 1) * half[axis]
        assert (np.linalg.norm(face[:, None] - c[None], axis=2) <= r[None] + 1e-9).any(axis=1).all()


def test_always_and_never_pairs_hold_on_fresh_samples():
    robot = nik.load_robot("ur5")
    model = collision_model(robot, source="capsules", samples=400, seed=0)  # the capsules' pairs: some always touch
    full = collision_model(robot, source="capsules", samples=0)
    q = _q(robot, 300, 7)
    d = signed_distances(robot, q, model=full)[:, : len(full.pairs)]
    for p, (a, b) in enumerate(full.pair_names()):
        reason = model.left_out.get(f"{a}|{b}")
        if reason == "always":
            assert (d[:, p] < 0).float().mean() > 0.9
        elif reason == "never":
            assert (d[:, p] > 0).all()
    assert "always" in model.left_out.values()


def test_pairs_can_be_added_and_removed():
    robot = nik.load_robot("ur5")
    model = collision_model(robot)
    a, b = model.pair_names()[0]
    fewer = model.with_pairs(remove=[(a, b)])
    assert (a, b) not in fewer.pair_names() and fewer.left_out[f"{a}|{b}"] == "removed"
    back = fewer.with_pairs(add=[(a, b)])
    assert (a, b) in back.pair_names()
    with pytest.raises(ValueError, match="unknown link 'nope'"):
        model.with_pairs(add=[("nope", a)])
    set_collision_model(robot, fewer)
    assert collision_model(robot) is fewer


# -- distances ------------------------------------------------------------------
@pytest.mark.long
def test_compiled_rows_match_torch_and_collides_agrees():
    robot = nik.load_robot("ur5")
    q = _q(robot, 200, 0)
    world = _world()
    d_torch = signed_distances(robot, q, world).numpy()
    d_comp = signed_distances_compiled(robot, q.numpy(), world)
    np.testing.assert_allclose(d_comp, d_torch, atol=1e-12)
    hit = collides(robot, q.numpy(), world, self_collision=False)
    assert hit.dtype == bool and 0 < hit.sum() < len(hit)
    np.testing.assert_array_equal(hit, collides(robot, q, world, self_collision=False, compiled=False).numpy())
    hit = collides(robot, q.numpy(), world)
    np.testing.assert_array_equal(hit, collides(robot, q, world, compiled=False).numpy())
    np.testing.assert_array_equal(hit, (d_torch < 0).any(axis=1))
    links = colliding_links(robot, q, world)
    np.testing.assert_array_equal(links.any(axis=1), hit)
    model = collision_model(robot)
    np.testing.assert_array_equal(
        links[:, 3],
        (d_torch[:, len(model.pairs) + 3] < 0)
        | np.array([any(d_torch[i, p] < 0 for p, pair in enumerate(model.pairs) if 3 in pair) for i in range(len(q))]),
    )


@pytest.mark.long
def test_compiled_jacobian_matches_finite_differences():
    from nik.kernels.collision import collision_distances, collision_residual

    robot = nik.load_robot("ur5")
    model = collision_model(robot)
    (G, joints), rest = kernel_arguments(robot, model, _world())
    R = len(model.pairs) + len(model.links)
    for q0 in _q(robot, 5, 3).numpy():
        d, J = np.empty(R), np.empty((R, robot.dof))
        collision_distances(G, joints, q0, *rest, d, J)
        Jn = np.empty_like(J)
        for k in range(robot.dof):
            dp, dm, scratch = np.empty(R), np.empty(R), np.empty((R, robot.dof))
            e = np.zeros(robot.dof)
            e[k] = 1e-6
            collision_distances(G, joints, q0 + e, *rest, dp, scratch)
            collision_distances(G, joints, q0 - e, *rest, dm, scratch)
            with np.errstate(invalid="ignore"):  # inf - inf on the rows with nothing to check
                Jn[:, k] = (dp - dm) / 2e-6
        finite = np.isfinite(d)
        np.testing.assert_allclose(J[finite], Jn[finite], atol=1e-6)
        r, Jr = np.empty(R), np.empty((R, robot.dof))
        smallest = collision_residual(G, joints, q0, *rest, 0.05, r, Jr)
        assert smallest == pytest.approx(d.min()) if d.min() <= 0.05 else smallest > 0.05
        np.testing.assert_allclose(r, np.maximum(0.0, 0.05 - d))
        np.testing.assert_allclose(Jr, np.where((0.05 - d > 0)[:, None], -J, 0.0))


def test_torch_gradient_matches_finite_differences():
    robot = nik.load_robot("ur5")
    q = _q(robot, 2, 5).requires_grad_(True)
    world = _world()
    rows = signed_distances(robot, q, world)
    finite = torch.isfinite(rows)
    total = rows[finite].sum()
    (grad,) = torch.autograd.grad(total, q)
    num = torch.zeros_like(q)
    with torch.no_grad():
        for k in range(robot.dof):
            e = torch.zeros_like(q)
            e[:, k] = 1e-6
            dp = signed_distances(robot, q + e, world)
            dm = signed_distances(robot, q - e, world)
            num[:, k] = torch.where(finite, (dp - dm) / 2e-6, 0.0).sum(dim=1)
    torch.testing.assert_close(grad, num, atol=1e-5, rtol=0)


# -- the world ------------------------------------------------------------------------
def test_world_changes_between_calls_without_rebuilding(prims):
    robot = nik.load_robot("ur5")
    q = _q(robot, 50, 1).numpy()
    world = World()
    free = collides(robot, q, world, self_collision=False)
    assert not free.any()
    v0, packed = world.version, world.packed()
    assert world.packed() is packed  # nothing changed: the same arrays
    world.add_sphere([0.0, 0.0, 0.3], 0.3)
    assert world.version == v0 + 1 and world.packed() is not packed
    assert collides(robot, q, world, self_collision=False).all()
    world.clear()
    assert not collides(robot, q, world, self_collision=False).any()


def test_scene_files_yaml_and_json(tmp_path):
    scene = {
        "spheres": [{"center": [0.3, 0, 0.3], "radius": 0.1}],
        "boxes": [{"center": [0.5, 0, 0], "size": [1, 1, 0.1], "rpy": [0, 0, 0.3]}],
        "capsules": [{"p0": [0, 0.5, 0], "p1": [0, 0.5, 1], "radius": 0.05}],
        "points": [{"xyz": [[1, 1, 1], [1, 1, 1.1]], "radius": 0.02}],
    }
    (tmp_path / "s.json").write_text(json.dumps(scene))
    import yaml

    (tmp_path / "s.yaml").write_text(yaml.safe_dump(scene))
    a, b = World.from_file(tmp_path / "s.json"), World.from_file(tmp_path / "s.yaml")
    assert a.counts() == (3, 1, 1)
    for x, y in zip(a.packed(), b.packed(), strict=True):
        np.testing.assert_allclose(x, y)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is empty"),
        ("spheres: [", "not valid YAML"),
        ("walls: []", "unknown key 'walls'"),
        ("spheres: [{center: [0, 0, 0], radius: -1}]", "must be positive"),
        ("boxes: [{center: [0, 0, 0], size: [1, -1, 1]}]", "must be positive"),
        ("spheres: [{center: [0, 0], radius: 1}]", "expected 3 finite numbers"),
        ("capsules: [{p0: [0, 0, 0], radius: 1}]", "missing 'p1'"),
    ],
)
def test_bad_scene_files_are_one_line_errors(tmp_path, text, message):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as err:
        World.from_file(path)
    assert "\n" not in str(err.value)


# -- files ---------------------------------------------------------------------------
def test_model_saved_beside_the_robot_is_loaded_and_checked(prims, tmp_path):
    robot, path = prims
    model = collision_model(robot)
    saved = model.save(tmp_path / "prims.collision.json")
    again = CollisionModel.load(saved, robot)
    np.testing.assert_array_equal(again.radii, model.radii)
    assert again.pair_names() == model.pair_names()
    fresh = nik.load_robot(path, end_link="l3")
    assert collision_model(fresh).robot_hash == robot.definition_hash
    with pytest.raises(ValueError, match="made for robot hash"):
        CollisionModel.load(saved, nik.load_robot("ur5"))


def test_a_urdf_that_is_not_the_robots_is_refused(prims, tmp_path):
    from nik.collision.urdf import urdf_bodies

    robot, _ = prims
    other = tmp_path / "other.urdf"
    other.write_text(
        URDF.replace('<origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>', '<origin xyz="0 0 0.5"/><axis xyz="0 1 0"/>')
    )
    with pytest.raises(ValueError, match="do not move as this robot's frames") as err:
        urdf_bodies(robot, other)
    assert "\n" not in str(err.value)


def test_a_mesh_that_cannot_be_read_is_one_line(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text(URDF.replace('<sphere radius="0.05"/>', '<mesh filename="missing.stl"/>'))
    robot = nik.load_robot(path, end_link="l3")
    with pytest.raises(ValueError, match="mesh file not found: missing.stl"):
        collision_model(robot)


def test_a_robot_with_collada_meshes_loads_with_the_extra(tmp_path):
    trimesh = pytest.importorskip("trimesh", reason="fitting spheres to meshes needs trimesh (extra collision-check)")
    pytest.importorskip("collada", reason="COLLADA meshes need pycollada (extra collision-check)")
    box = trimesh.creation.box(extents=[0.08, 0.06, 0.1])
    (tmp_path / "box.dae").write_bytes(trimesh.exchange.dae.export_collada(box))
    path = tmp_path / "dae.urdf"
    path.write_text(URDF.replace('<sphere radius="0.05"/>', '<mesh filename="box.dae"/>'))
    from nik.collision.shapes import mesh_triangles
    from nik.collision.urdf import urdf_bodies

    read = np.unique(mesh_triangles(tmp_path / "box.dae").reshape(-1, 3).round(9), axis=0)
    np.testing.assert_allclose(read, np.unique(np.asarray(box.vertices).round(9), axis=0), atol=1e-9)
    robot = nik.load_robot(path, end_link="l3")
    model = collision_model(robot, cache=False)
    centres, radii = model.spheres("l3")
    (body,) = [b for b in urdf_bodies(robot, path) if b.name == "l3"]
    corners = body.triangles.reshape(-1, 3)  # the box's corners (and the capsule's) in l3's frame
    held = (np.linalg.norm(corners[:, None] - centres[None], axis=2) <= radii[None] + 1e-9).any(axis=1)
    assert held.all()


def test_a_mesh_format_without_its_reader_is_one_line_naming_the_package(tmp_path, monkeypatch):
    trimesh = pytest.importorskip("trimesh", reason="reading meshes needs trimesh (extra collision-check)")
    pytest.importorskip("collada", reason="writing the COLLADA file needs pycollada (extra collision-check)")
    from nik.collision.shapes import mesh_triangles

    dae = tmp_path / "box.dae"
    dae.write_bytes(trimesh.exchange.dae.export_collada(trimesh.creation.box()))
    monkeypatch.setitem(sys.modules, "collada", None)  # as without pycollada
    with pytest.raises(ValueError, match="needs pycollada") as err:
        mesh_triangles(dae)
    msg = str(err.value)
    assert "\n" not in msg and str(dae) in msg and "pip install 'nik-ik[collision-check]'" in msg


# -- the independent check ---------------------------------------------------------
def test_spheres_never_call_free_what_the_meshes_call_colliding(prims):
    pytest.importorskip("coal", reason="the mesh check needs coal (extra collision-check)")
    from nik.collision.meshcheck import MeshCheck

    robot, path = prims
    mesh = MeshCheck(robot, path)
    q = _q(robot, 400, 11).numpy()
    world = World().add_box([0.25, 0.0, 0.4], [0.1, 0.4, 0.1]).add_sphere([-0.2, 0.1, 0.5], 0.06)
    for w in (None, world):
        theirs = mesh.collides(q, w)
        ours = collides(robot, q, w)
        assert theirs.any()
        assert not (theirs & ~ours).any()


@pytest.mark.long
def test_mesh_paths_resolve_the_same_with_a_cold_or_warm_cache(tmp_path, monkeypatch):
    trimesh = pytest.importorskip("trimesh", reason="fitting spheres to meshes needs trimesh (extra collision-check)")

    pkg = tmp_path / "src" / "pkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    trimesh.creation.box(extents=[0.08, 0.08, 0.08]).export(pkg / "meshes" / "box.stl")
    text = URDF.replace('<sphere radius="0.05"/>', '<mesh filename="package://pkg/meshes/box.stl"/>')
    (pkg / "urdf" / "r.urdf").write_text(text)
    first = collision_model(nik.load_robot(pkg / "urdf" / "r.urdf", end_link="l3"))  # fitted: the cache is warm
    copy = tmp_path / "a" / "b" / "r.urdf"  # the same bytes elsewhere: no folder above it holds pkg
    copy.parent.mkdir(parents=True)
    copy.write_text(text)
    robot = nik.load_robot(copy, end_link="l3")
    with pytest.raises(ValueError, match="mesh file not found") as err:
        collision_model(robot)  # not the warm cache's model: the meshes are looked for first, as when cold
    msg = str(err.value)
    assert "\n" not in msg and f"looked in: {copy.parent / 'pkg' / 'meshes' / 'box.stl'}" in msg
    assert str(tmp_path / "pkg" / "meshes" / "box.stl") in msg and "share/pkg/meshes/box.stl" in msg
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "src"))
    model = collision_model(robot, cache=False)  # found through ROS_PACKAGE_PATH, cold
    np.testing.assert_allclose(model.radii, first.radii)
    np.testing.assert_allclose(collision_model(robot).radii, first.radii)  # and warm


def test_scene_files_in_millimetres(tmp_path):
    metres = tmp_path / "m.yaml"
    metres.write_text(
        "boxes: [{center: [0.45, 0.0, -0.05], size: [0.9, 1.2, 0.1], rpy: [0, 0, 0.3]}]\n"
        "spheres: [{center: [0.5, 0.0, 0.3], radius: 0.05}]\n"
        "capsules: [{p0: [0.3, -0.4, 0.0], p1: [0.3, -0.4, 0.8], radius: 0.03}]\n"
        "points: [{xyz: [[0.6, 0.1, 0.2]], radius: 0.01}]\n"
    )
    mm = tmp_path / "mm.yaml"
    mm.write_text(
        "unit: mm\n"
        "boxes: [{center: [450, 0, -50], size: [900, 1200, 100], rpy: [0, 0, 0.3]}]\n"
        "spheres: [{center: [500, 0, 300], radius: 50}]\n"
        "capsules: [{p0: [300, -400, 0], p1: [300, -400, 800], radius: 30}]\n"
        "points: [{xyz: [[600, 100, 200]], radius: 10}]\n"
    )
    for a, b in zip(World.from_file(metres).packed(), World.from_file(mm).packed(), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    pose = tmp_path / "pose.yaml"
    pose.write_text("unit: mm\nboxes: [{pose: [450, 0, -50, 1, 0, 0, 0], size: [900, 1200, 100]}]\n")
    np.testing.assert_allclose(World.from_file(pose).packed()[1][0, 9:], [0.45, 0, -0.05, 0.45, 0.6, 0.05])
    forgot = tmp_path / "forgot.yaml"
    forgot.write_text(mm.read_text().replace("unit: mm\n", ""))
    with pytest.warns(UserWarning, match="written in millimetres\\? add 'unit: mm'"):
        World.from_file(forgot)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        World.from_file(metres)  # no warning for a scene in metres
    bad = tmp_path / "bad.yaml"
    bad.write_text("unit: cm\nspheres: [{center: [0, 0, 0], radius: 1}]\n")
    with pytest.raises(ValueError, match="unit must be m or mm, got 'cm'"):
        World.from_file(bad)
