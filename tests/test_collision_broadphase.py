"""The broad phase of the compiled collision rows (nik/kernels/collision.py) and the shortcuts of the collision stage
(nik/ik/collide.py, nik/kernels/collision_lm.py): below the cutoff the rows equal the all-pairs ones, above it they
stay lower bounds above the cutoff; the verdict is that of the all-pairs rows; a pose called blocked has no free
configuration; skipping blocked targets and ranking the starts by clearance change no answer's verdict."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nik
from nik.collision import collides, collision_model
from nik.collision.compiled import blocked_targets, kernel_arguments
from nik.collision.distance import sphere_centers
from nik.kernels.collision import (
    collides_batch,
    collision_distances,
    collision_distances_batch,
    collision_residual,
    collision_rows_batch,
)


def _scene(seed: int, n: int = 12) -> nik.World:
    """A table under the arm (its top 2 cm below the base: the shipped ur5 model's shoulder spheres come within 1 cm
    of the base plane, so a 1 cm margin would call every configuration colliding) and ``n`` seeded boxes, spheres
    and capsules within its reach."""
    rng = np.random.default_rng(seed)
    world = nik.World().add_box([0.4, 0.0, -0.07], [1.2, 1.2, 0.1])
    for i in range(n):
        angle, r = rng.uniform(-np.pi, np.pi), rng.uniform(0.25, 0.7)
        c = np.array([r * np.cos(angle), r * np.sin(angle), rng.uniform(0.05, 0.8)])
        if i % 3 == 0:
            rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = rot * np.sign(np.linalg.det(rot)), c
            world.add_box(pose, rng.uniform(0.04, 0.2, size=3))
        elif i % 3 == 1:
            world.add_sphere(c, rng.uniform(0.02, 0.1))
        else:
            world.add_capsule(c, c + rng.normal(size=3) * 0.15, rng.uniform(0.02, 0.06))
    return world


def _q(robot, n: int, seed: int) -> np.ndarray:
    g = torch.Generator().manual_seed(seed)
    return np.ascontiguousarray(robot.sample(n, generator=g, dtype=torch.float64).numpy())


@pytest.mark.parametrize("name", ["panda", "ur5"])
@pytest.mark.parametrize("self_on", [True, False])
def test_broad_phase_rows_equal_all_pairs_below_the_cutoff(name, self_on):
    robot = nik.load_robot(name)
    model = collision_model(robot)
    Q = _q(robot, 400, seed=11)
    for seed in range(3):
        (G, joints), rest = kernel_arguments(robot, model, _scene(seed), self_collision=self_on)
        exact = np.empty((len(Q), len(model.pairs) + len(model.links)))
        collision_distances_batch(G, joints, Q, *rest, exact)
        below_somewhere = 0
        for cutoff in (0.0, 0.005, 0.05):
            broad = np.empty_like(exact)
            collision_rows_batch(G, joints, Q, *rest, cutoff, broad)
            near = (exact <= cutoff) | (broad <= cutoff)
            below_somewhere += int(near.sum())
            np.testing.assert_allclose(broad[near], exact[near], rtol=0, atol=1e-12)
            far = ~near
            assert (broad[far] > cutoff).all()  # above the cutoff: still above it
            assert (broad[far] <= exact[far] + 1e-12).all()  # ... and a lower bound of the exact row
        assert below_somewhere > 0  # the scenes and configurations do bring rows below the cutoffs


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_the_verdict_is_that_of_the_all_pairs_rows(name):
    robot = nik.load_robot(name)
    model = collision_model(robot)
    Q = _q(robot, 500, seed=12)
    for seed in range(3):
        for self_on in (True, False):
            (G, joints), rest = kernel_arguments(robot, model, _scene(seed + 5), self_collision=self_on)
            exact = np.empty((len(Q), len(model.pairs) + len(model.links)))
            collision_distances_batch(G, joints, Q, *rest, exact)
            for margin in (0.0, 0.01):
                hit = np.empty(len(Q), dtype=bool)
                collides_batch(G, joints, Q, *rest, margin, hit)
                np.testing.assert_array_equal(hit, (exact < margin).any(axis=1))
                assert 0 < hit.sum() < len(Q)


def test_residual_rows_and_jacobian_equal_the_exact_ones_within_the_margin():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    (G, joints), rest = kernel_arguments(robot, model, _scene(2))
    R, n = len(model.pairs) + len(model.links), robot.dof
    active = 0
    for q in _q(robot, 60, seed=13):
        d, J = np.empty(R), np.empty((R, n))
        collision_distances(G, joints, q, *rest, d, J)
        for margin in (0.005, 0.03):
            r, Jr = np.empty(R), np.empty((R, n))
            smallest = collision_residual(G, joints, q, *rest, margin, r, Jr)
            np.testing.assert_allclose(r, np.maximum(0.0, margin - d), rtol=0, atol=1e-12)
            np.testing.assert_allclose(Jr, np.where((margin - d > 0)[:, None], -J, 0.0), rtol=0, atol=1e-12)
            assert smallest == pytest.approx(d.min(), abs=1e-12) if d.min() <= margin else smallest > margin
            active += int((r > 0).sum())
    assert active > 0


def test_a_blocked_pose_has_no_free_configuration():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    world = _scene(4, n=20)
    Q = _q(robot, 3000, seed=14)
    T = np.asarray(robot.fk(Q))
    blocked = blocked_targets(robot, model, world, T, 1e-4, 1e-3)
    hit = collides(robot, Q, world, model=model)
    assert blocked.sum() >= 10  # the proof bites in a cluttered scene
    assert hit[blocked].all()  # a pose called blocked: its own configuration collides too
    assert not blocked[~hit].any()


def test_the_first_joints_sweep_blocks_a_pose_whose_base_link_always_collides():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    T = np.asarray(robot.fk(_q(robot, 50, seed=15)))
    assert not blocked_targets(robot, model, nik.World(), T, 1e-4, 1e-3, self_collision=False).any()
    on_one = np.asarray(model.sphere_frame) == 1
    assert on_one.any()  # a link rides on the first joint
    centres = sphere_centers(model, robot, torch.zeros(1, robot.dof, dtype=torch.float64))[0].numpy()[on_one]
    height, radius = centres[:, 2].mean(), np.hypot(centres[:, 0], centres[:, 1]).mean()
    ring = nik.World()  # balls around the first joint's axis at the height of its link: hit at every angle
    for a in np.linspace(0, 2 * np.pi, 72, endpoint=False):
        ring.add_sphere([radius * np.cos(a), radius * np.sin(a), height], 0.05)
    blocked = blocked_targets(robot, model, ring, T, 1e-4, 1e-3, self_collision=False)
    assert collides(robot, _q(robot, 200, seed=16), ring, model=model, self_collision=False).all()
    assert blocked.all()


def test_skipping_blocked_targets_and_ranking_starts_keep_the_verdicts(monkeypatch):
    """Every answer called free is free by the all-pairs rows; a target the shortcut skips (a blocked pose) fails
    without the shortcut too (the full re-solve finds no free answer for it either)."""
    import nik.collision.compiled as compiled

    robot = nik.load_robot("panda")
    world = _scene(6)
    Q = _q(robot, 400, seed=17)
    T = np.ascontiguousarray(np.asarray(robot.fk(Q))[:120])
    solver = nik.IKSolver(robot, world=world, mesh_verdict=False)
    res = solver.solve(T)
    model = collision_model(robot)
    (G, joints), rest = kernel_arguments(robot, model, world)
    exact = np.empty((len(T), len(model.pairs) + len(model.links)))
    collision_distances_batch(G, joints, np.ascontiguousarray(res.q), *rest, exact)
    np.testing.assert_array_equal(res.collision_free, (exact >= 0).all(axis=1))
    plan = solver.plan()
    blocked = blocked_targets(robot, model, world, T, plan.tol_pos, plan.tol_rot)
    assert blocked.sum() >= 3  # the scene blocks some poses: the comparison covers the shortcut
    monkeypatch.setattr(compiled, "blocked_targets", lambda robot, model, world, T, *a, **k: np.zeros(len(T), bool))
    ref = nik.IKSolver(robot, world=world, mesh_verdict=False).solve(T)
    assert not res.success[blocked].any() and not ref.success[blocked].any()
    assert abs(int(res.success.sum()) - int(ref.success.sum())) <= 2  # the rest: other random streams, same rate


@pytest.mark.parametrize("self_on", [True, False])
def test_compiled_names_equal_the_torch_ones(self_on):
    from nik.collision import collision_names
    from nik.collision.compiled import collision_names_compiled

    robot = nik.load_robot("panda")
    model = collision_model(robot)
    world = _scene(3)
    Q = _q(robot, 300, seed=18)
    ours = collision_names_compiled(robot, Q, world, model=model, self_collision=self_on)
    ref = collision_names(robot, Q, world, model=model, self_collision=self_on)
    assert ours == ref
    assert sum(x is not None for x in ours) > 10


def test_the_last_joints_sweep_blocks_a_pose_whose_wrist_link_always_collides():
    """A ring of balls around the last joint's axis, where the links it turns pass: every configuration reaching the
    pose collides, and the sweep over the last joint proves it (the hand itself stays free)."""
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    n = robot.dof
    q = _q(robot, 1, seed=19)
    on_wrist = np.asarray(model.sphere_frame) == n - 1
    assert on_wrist.any()
    F = nik.collision.link_frames(robot, torch.as_tensor(q))[0].numpy()  # (n + 1, 3, 4) frames, base first
    c = sphere_centers(model, robot, torch.as_tensor(q))[0].numpy()[on_wrist]
    axis, origin = F[n][:3, 2], F[n][:3, 3]
    rel = c - origin
    along = rel @ axis
    radial = rel - along[:, None] * axis
    k = int(np.argmax(np.linalg.norm(radial, axis=1)))
    u = radial[k] / np.linalg.norm(radial[k])
    v = np.cross(axis, u)
    r, h = float(np.linalg.norm(radial[k])), float(along[k])
    ring = nik.World()
    for a in np.linspace(0, 2 * np.pi, 90, endpoint=False):
        ring.add_sphere(origin + h * axis + r * (np.cos(a) * u + np.sin(a) * v), 0.01)
    T = np.asarray(robot.fk(q))
    fixed_only = blocked_targets(robot, model, ring, T, 1e-4, 1e-3, self_collision=False, samples=1)
    assert not fixed_only.any()  # the hand is free of the ring: the sweep does the proving
    assert blocked_targets(robot, model, ring, T, 1e-4, 1e-3, self_collision=False).all()
    assert collides(robot, q, ring, model=model, self_collision=False).all()


def test_one_configuration_check_is_that_of_the_all_pairs_rows():
    from nik.kernels.collision import collides_bounded, link_bounds

    robot = nik.load_robot("panda")
    model = collision_model(robot)
    Q = _q(robot, 300, seed=21)
    (G, joints), rest = kernel_arguments(robot, model, _scene(7))
    exact = np.empty((len(Q), len(model.pairs) + len(model.links)))
    collision_distances_batch(G, joints, Q, *rest, exact)
    bounds = np.empty((len(model.links), 4))
    link_bounds(rest[0].spheres, rest[0].body_start, bounds)
    d = np.empty(exact.shape[1])
    for margin in (0.0, 0.01):
        hit = np.array([collides_bounded(G, joints, q, *rest, margin, d, bounds) for q in Q])
        np.testing.assert_array_equal(hit, (exact < margin).any(axis=1))
        assert 0 < hit.sum() < len(Q)


def test_patience_ends_the_restarts_early_and_keeps_the_verdicts():
    """CollideCfg.patience: fewer iterations on the targets the re-solve fails; every answer called free stays free
    by the all-pairs rows, and a success is a success without it too (the same starts come first)."""
    from nik.ik.collide import CollideCfg

    robot = nik.load_robot("panda")
    world = _scene(6)
    T = np.ascontiguousarray(np.asarray(robot.fk(_q(robot, 400, seed=17)))[:120])
    solver = nik.IKSolver(robot, world=world, mesh_verdict=False)
    full = solver.solve(T)
    solver.collide_cfg = CollideCfg(patience=2)
    short = solver.solve(T)
    model = collision_model(robot)
    (G, joints), rest = kernel_arguments(robot, model, world)
    exact = np.empty((len(T), len(model.pairs) + len(model.links)))
    collision_distances_batch(G, joints, np.ascontiguousarray(short.q), *rest, exact)
    np.testing.assert_array_equal(short.collision_free, (exact >= 0).all(axis=1))
    assert not (short.success & ~full.success).any()
    failed = ~full.success & ~short.success
    assert failed.any() and short.iterations[failed].sum() < full.iterations[failed].sum()


def test_uniform_starts_end_free_and_within_the_tolerance_after_the_pose_leg():
    """The collision LM's uniform starts go to the pose by LM without the collision rows first, then on with them
    (nik/kernels/collision_lm.py): from uniform starts alone (no given start, two restarts), every answer called done
    is within the pose tolerance by FK and free by the all-pairs rows, most targets from free configurations end
    done (measured 151 of 200), and the iterations count both legs (at least one per target that was not free at
    its draw)."""
    from nik.ik.collide import CollideCfg, _collision_solve, _goal, setup
    from nik.kernels.lm import pose_errors

    robot = nik.load_robot("panda")
    world = _scene(6)
    model = collision_model(robot)
    (G, joints), rest = kernel_arguments(robot, model, world)
    Q = _q(robot, 600, seed=17)
    hit = np.empty(len(Q), dtype=bool)
    collides_batch(G, joints, Q, *rest, 0.0, hit)
    T = np.ascontiguousarray(np.asarray(robot.fk(Q[~hit][:200])))
    solver = nik.IKSolver(robot, world=world, mesh_verdict=False)
    plan = solver.plan()
    k = len(T)
    goal = _goal(robot, plan, k, False)
    q, done, it = _collision_solve(robot, setup(robot, world, None), plan, CollideCfg(), goal, T,
                                   np.zeros((k, 0, robot.dof)), np.zeros(k), np.full(k, 2), 0.005)  # fmt: skip
    pos, rot = np.empty(k), np.empty(k)
    pose_errors(G, joints, T, np.ascontiguousarray(q), pos, rot)
    exact = np.empty((k, len(model.pairs) + len(model.links)))
    collision_distances_batch(G, joints, np.ascontiguousarray(q), *rest, exact)
    assert (pos[done] <= plan.tol_pos).all() and (rot[done] <= plan.tol_rot).all()
    assert (exact[done] >= 0).all()
    assert done.mean() >= 0.6
    assert (it >= 1).all()


def _rotation(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_the_hands_slack_never_blocks_a_pose_that_a_free_configuration_reaches_within_the_tolerance():
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    n, tol_pos, tol_rot = robot.dof, 1e-4, 1e-3
    (G, joints), rest = kernel_arguments(robot, model, nik.World(), self_collision=False)
    spheres, frames = rest[0].spheres, rest[0].sphere_frame
    hand = np.flatnonzero(frames == n)
    assert hand.size  # the hand rides on the last frame
    levers = np.linalg.norm(spheres[hand, :3] - G[n][:3, 3], axis=1)
    inv = np.linalg.inv(G[n - 1])
    wrist = spheres[frames == n - 1, :3] @ inv[:3, :3].T + inv[:3, 3]
    wide = float((np.linalg.norm(wrist, axis=1) + np.linalg.norm(G[n][:3, 3])).max())
    assert wide > levers.max()  # the sweeps' lever is the larger: the hand's rows get the smaller slack
    on_hand = np.asarray(model.sphere_frame) == n
    near = far = 0
    for q in _q(robot, 6, seed=21):
        T = np.asarray(robot.fk(q[None]))[0]
        c = sphere_centers(model, robot, torch.as_tensor(q[None]))[0].numpy()[on_hand]
        for u in (T[:3, 0], -T[:3, 0], T[:3, 1], -T[:3, 1]):  # across the hand
            k = int(np.argmax(c @ u + spheres[hand, 3]))  # the hand's outermost sphere that way: a ball beyond it
            v, r, rho = c[k] - T[:3, 3], spheres[hand[k], 3], 0.005  # touches no other sphere of the hand
            w = np.cross(v, u)  # turning about w through the tool point moves the sphere towards u
            reach = tol_pos + tol_rot * np.linalg.norm(w)  # |v x u|: the lever across u
            past = tol_pos + tol_rot * (levers.max() + wide) / 2  # past the hand's slack, short of the sweeps'
            for expect, a, t, ball in (
                (False, 0.999 * tol_rot, 0.999 * tol_pos, c[k] + u * (r + rho + 1e-6)),
                (True, 0.0, 0.0, c[k] + u * (r + rho - past)),
            ):
                world = nik.World()
                world.add_sphere(ball, rho)
                A = np.eye(4)
                A[:3, :3] = _rotation(w, a)
                A[:3, 3] = T[:3, 3] - A[:3, :3] @ T[:3, 3] + t * u
                Tm = A @ T  # the tool point moved by t, the frame turned by a: q reaches it within the tolerance
                blocked = blocked_targets(robot, model, world, Tm[None], tol_pos, tol_rot, self_collision=False,
                                          samples=1)  # fmt: skip
                hit = collides(robot, q[None], world, model=model, self_collision=False)[0]
                if expect:
                    assert blocked[0] and hit
                    far += 1
                elif not hit:  # q is free and within the tolerance of Tm
                    moved = A[:3, :3] @ c[k] + A[:3, 3]
                    assert np.linalg.norm(moved - ball) - rho - r < -0.9 * reach  # Tm puts the sphere in the ball
                    assert reach > 1.5 * tol_pos  # by more than the position tolerance alone
                    assert not blocked[0]
                    near += 1
    assert near >= 12 and far == 24


def _wrist_ring(robot, model, q, side, gap, radius=0.01, count=360, hole=None):
    """A ring of ``count`` balls about the last joint's axis for ``q (1, n)``, on the circle of the wrist sphere
    farthest from that axis (the sweep over the last joint turns the wrist's spheres about it), moved along
    ``side * axis`` until the nearest wrist sphere is ``gap`` (m) clear of the circle of the balls (clear of the balls
    by that where it lies under one, by up to 17 um more between two): ``(count, 3)`` centres, and the axis. With
    ``hole = (a, b)`` (rad) the ring lies on that sphere's circle instead (through its centre), from ``a`` to
    ``2 pi - b`` of its angle."""
    c, r, axis, origin = _wrist(robot, model, q)
    along = (c - origin) @ axis
    radial = c - origin - along[:, None] * axis
    k = int(np.argmax(np.linalg.norm(radial, axis=1)))
    u, rho = radial[k] / np.linalg.norm(radial[k]), float(np.linalg.norm(radial[k]))
    v = np.cross(axis, u)
    ball = np.abs(np.linalg.norm(radial, axis=1) - rho)  # each wrist sphere's offset from the circle, across

    def clear(t):  # the wrist's clearance from the circle of the balls at height t along side * axis
        return float((np.hypot(ball, t - side * along) - r - radius).min())

    if hole is not None:
        a = np.linspace(hole[0], 2 * np.pi - hole[1], count)[:, None]
        return origin + along[k] * axis + rho * (np.cos(a) * u + np.sin(a) * v), axis
    ts = np.linspace(float((side * along).min()), float((side * along).max()) + 0.2, 2001)
    lo = float(ts[max(i for i, t in enumerate(ts) if clear(t) < gap)])  # touching here, clear one grid step on
    hi = lo + float(ts[1] - ts[0])
    for _ in range(100):  # a height where the clearance is gap (it is continuous in the height)
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clear(mid) < gap else (lo, mid)
    a = np.linspace(0, 2 * np.pi, count, endpoint=False)[:, None]
    return origin + side * hi * axis + rho * (np.cos(a) * u + np.sin(a) * v), axis


_PLACED: dict = {}


def _placed(robot, model, key):
    """The centres ``(S, 3)`` of the spheres and the frames ``(n + 1, 3, 4)`` for ``q = np.frombuffer(key)``, kept
    for the last configuration (the rings' searches place the same one many times)."""
    if _PLACED.get("key") != (id(robot), id(model), key):
        q = torch.as_tensor(np.frombuffer(key).reshape(1, -1).copy())
        _PLACED["key"] = (id(robot), id(model), key)
        _PLACED["got"] = sphere_centers(model, robot, q)[0].numpy(), nik.collision.link_frames(robot, q)[0].numpy()
    return _PLACED["got"]


def _wrist(robot, model, q):
    """The wrist's (frame ``n - 1``) sphere centres and radii for ``q (1, n)``, the last joint's axis and origin."""
    n, frames = robot.dof, np.asarray(model.sphere_frame)
    c, F = _placed(robot, model, np.ascontiguousarray(q, dtype=np.float64).tobytes())
    return c[frames == n - 1], model.arrays()[0][frames == n - 1, 3], F[n][:3, 2], F[n][:3, 3]


def _balls(centres, radius=0.01) -> nik.World:
    world = nik.World()
    for c in centres:
        world.add_sphere(c, radius)
    return world


def _read_clear(robot, model, q, centres, radius=0.01) -> float:
    """The clearance from balls ``centres`` of the links :func:`blocked_targets` reads for a ring about the last
    joint (those on frames 1, ``n - 1`` and ``n``; the links between are not read)."""
    n, frames = robot.dof, np.asarray(model.sphere_frame)
    read = np.isin(frames, (1, n - 1, n))
    c = _placed(robot, model, np.ascontiguousarray(q, dtype=np.float64).tobytes())[0][read]
    d = c[:, None] - centres[None]
    return float((np.sqrt((d * d).sum(axis=2)) - model.arrays()[0][read, 3][:, None] - radius).min())


def test_the_sweeps_halving_never_blocks_a_pose_that_a_free_configuration_reaches_within_the_tolerance():
    """A ring of balls about the last joint's axis over the circle its wrist link's outer sphere turns on, just
    clear of the wrist: where the configuration is free, the target moved 0.999 x tol_pos towards the ring (every
    wrist sphere that much nearer it at every value of the last joint) is reached within the tolerance, so it is
    never blocked at any depth of the halving (the links between, which the ring's circle crosses, are not what the
    proof reads: the links it reads are free); a ring 1 mm into the wrist (more than the slack, less than one step's
    motion) is blocked by the halving and not by the plain sweep. With half the slack the first case is called
    blocked."""
    robot = nik.load_robot("panda")
    model = collision_model(robot)
    free = caught = 0
    for q in _q(robot, 6, seed=23):
        q = q[None]
        T = np.asarray(robot.fk(q))[0]
        for side in (1.0, -1.0):
            tol_pos, tol_rot = 1e-3, 1e-4  # slack 1.02 mm on the built-in panda's wrist lever
            ring, axis = _wrist_ring(robot, model, q, side, 1e-6)
            world = _balls(ring)
            if _read_clear(robot, model, q, ring) >= 0:  # the hand may touch the ring
                Tm = T.copy()
                Tm[:3, 3] += side * 0.999 * tol_pos * axis  # q reaches Tm within tol_pos
                for depth in (0, 4, 6):
                    blocked = blocked_targets(robot, model, world, Tm[None], tol_pos, tol_rot, self_collision=False,
                                              depth=depth)  # fmt: skip
                    assert not blocked[0]
                free += 1
            world = _balls(_wrist_ring(robot, model, q, side, -1e-3)[0])
            plain, halved = (
                blocked_targets(robot, model, world, T[None], 1e-4, 1e-3, self_collision=False, depth=d)[0]
                for d in (0, 4)
            )
            assert collides(robot, q, world, model=model, self_collision=False)[0]
            caught += bool(halved and not plain)
    assert free >= 3 and caught >= 3


def test_the_halvings_motion_bound_never_blocks_a_pose_free_only_between_two_swept_values():
    """A ring of balls on the circle the wrist's outer sphere turns on, with a hole just wide enough that the
    configuration's wrist is free there, the last joint set halfway between two of the sweep's values: the pieces
    next to it collide at their centres by more than the slack (the sphere runs head-on into the ball at the hole's
    edge) but are free at their edge, so the pose is never blocked at any depth (with half the motion bound it is)."""
    from nik.kernels.chain import LOWER, UPPER

    robot = nik.load_robot("panda")
    model = collision_model(robot)
    n = robot.dof
    (_, joints), _ = kernel_arguments(robot, model, nik.World(), self_collision=False)
    lo, hi = joints[n - 1, LOWER], joints[n - 1, UPPER]
    h = min(hi - lo, 2 * np.pi) / 179  # blocked_targets' 180 values of the last joint
    checked = 0
    for q in _q(robot, 4, seed=29):
        q = q[None].copy()
        q[0, n - 1] = lo + (np.floor((q[0, n - 1] - lo) / h) + 0.5) * h
        T = np.asarray(robot.fk(q))

        hole = [1.5, 1.5]  # the narrowest hole (rad each way) that frees the links the proof reads: both edges touch
        for side in (0, 1):
            a, b = 0.0, 1.5
            for _ in range(28):
                hole[side] = 0.5 * (a + b)
                ring = _wrist_ring(robot, model, q, 1.0, 0.0, hole=hole)[0]
                a, b = (a, hole[side]) if _read_clear(robot, model, q, ring) >= 0 else (hole[side], b)
            hole[side] = b
        world = _balls(_wrist_ring(robot, model, q, 1.0, 0.0, hole=hole)[0])
        for depth in (0, 4):  # slack 0.12 mm, less than a third of the least row next to the hole
            assert not blocked_targets(robot, model, world, T, 1e-4, 1e-4, self_collision=False, depth=depth)[0]
        checked += 1
    assert checked >= 3


def test_a_negative_halving_depth_is_refused_in_one_line():
    robot = nik.load_robot("panda")
    T = np.asarray(robot.fk(_q(robot, 1, seed=31)))
    with pytest.raises(ValueError, match="depth must be >= 0"):
        blocked_targets(robot, collision_model(robot), nik.World(), T, 1e-4, 1e-3, depth=-1)


@pytest.mark.parametrize("prismatic", [(), (1, 4)])
def test_the_rows_frames_are_the_chains_products_bit_for_bit(prismatic):
    """The rows' frames (written out in place) are the chain's own products ``G[0] J(q0) G[1] J(q1) ...`` of
    :mod:`nik.kernels.chain` to the bit, revolute and prismatic joints alike, and end at the forward kinematics."""
    from nik.kernels.chain import OFFSET, PRISMATIC, _joint, _start, _times, fk
    from nik.kernels.collision import _frames

    robot = nik.load_robot("panda")
    G, joints = robot.chain_arrays()
    joints = joints.copy()
    for k in prismatic:
        joints[k, PRISMATIC] = 1.0
    n = robot.dof
    for q in _q(robot, 50, seed=15):
        F = np.empty((n + 1, 3, 4))
        _frames(G, joints, q, F)
        T = np.empty((3, 4))
        _start(T, G[0])
        for i in range(n):
            _joint(T, joints[i, PRISMATIC] != 0.0, q[i] + joints[i, OFFSET])
            np.testing.assert_array_equal(F[i + 1], T)
            _times(T, G[i + 1])
        np.testing.assert_array_equal(F[0], np.eye(4)[:3])
        if not prismatic:
            full = np.empty((4, 4))
            fk(G, joints, q, full)
            np.testing.assert_allclose(T, full[:3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7"])
def test_the_link_capsules_hold_their_spheres_and_bound_the_pairs_from_below(name):
    """Each link's capsule (the pairs' broad phase) holds every one of its spheres, and the capsules' distance
    (segments apart, minus both radii) is at most the pair's all-sphere distance: a lower bound, never above."""
    from nik.kernels.collision import _point_segment, _segment_segment, link_capsules

    robot = nik.load_robot(name)
    model = collision_model(robot)
    spheres, sphere_frame, body_start, pairs = model.arrays()
    L = len(body_start) - 1
    caps = np.empty((L, 7))
    link_capsules(spheres, body_start, caps)
    for link in range(L):
        for s in range(body_start[link], body_start[link + 1]):
            reach = _point_segment(*spheres[s, :3], *caps[link, :6]) + spheres[s, 3]
            assert reach <= caps[link, 6] - 0.5e-6  # inside, with the rounding slack to spare
    G, joints = robot.chain_arrays()
    from nik.kernels.collision import _frames

    Q = _q(robot, 300, seed=16)
    X = sphere_centers(model, robot, torch.as_tensor(Q)).numpy()
    F = np.empty((robot.dof + 1, 3, 4))
    tight = 0
    for b, q in enumerate(Q):
        _frames(G, joints, q, F)
        ends = [np.concatenate([F[sphere_frame[body_start[k]]] @ np.append(caps[k, 3 * e : 3 * e + 3], 1.0)
                                for e in range(2)]) for k in range(L)]  # fmt: skip
        for a, c in pairs:
            xa, xc = X[b, body_start[a] : body_start[a + 1]], X[b, body_start[c] : body_start[c + 1]]
            ra, rc = spheres[body_start[a] : body_start[a + 1], 3], spheres[body_start[c] : body_start[c + 1], 3]
            exact = (np.linalg.norm(xa[:, None] - xc[None], axis=2) - ra[:, None] - rc[None]).min()
            bound = _segment_segment(*ends[a], *ends[c]) - caps[a, 6] - caps[c, 6]
            assert bound <= exact
            tight += bound > exact - 0.05
    assert tight > 0  # and not vacuous: some bounds within 5 cm of the distance


def test_the_segment_distance_is_the_closest_points_distance():
    """The capsules' segment distance against a dense grid of point pairs: never above the grid's smallest distance
    by more than rounding (it is the true minimum), and near it; random, parallel and degenerate (point) segments."""
    from nik.kernels.collision import _segment_segment

    rng = np.random.default_rng(17)
    u = np.linspace(0.0, 1.0, 401)
    cases = [rng.normal(size=(4, 3)) for _ in range(200)]
    for _ in range(50):  # parallel and near-parallel
        p, d = rng.normal(size=3), rng.normal(size=3)
        q = rng.normal(size=3)
        cases.append(np.array([p, p + d, q, q + d * rng.uniform(-2, 2) + 1e-9 * rng.normal(size=3)]))
    cases.append(np.array([[0.0, 0, 0], [0, 0, 0], [1, 1, 1], [1, 1, 1]]))  # two points
    cases.append(np.array([[0.0, 0, 0], [0, 0, 0], [-1, 2, 0], [3, 2, 0]]))  # a point and a segment
    for p1, q1, p2, q2 in cases:
        a = p1 + u[:, None] * (q1 - p1)
        b = p2 + u[:, None] * (q2 - p2)
        grid = np.linalg.norm(a[:, None] - b[None], axis=2).min()
        got = _segment_segment(*p1, *q1, *p2, *q2)
        step = (np.linalg.norm(q1 - p1) + np.linalg.norm(q2 - p2)) / 400
        assert got <= grid + 1e-7  # near-parallel rounding reaches ~1e-9: the capsules' 1 um slack covers it
        assert got >= grid - step
