"""nik and PyRoki side by side: collision-free IK of the panda in a scene, judged on the real meshes (coal).

The panda of example-robot-data (collision meshes, MoveIt's SRDF pairs), the scene of ``benchmarks/collisions.py``
(a table under the arm and 10 seeded boxes, spheres and capsules around it), targets: the poses of random
configurations that nik's sphere model calls free in the scene. Rows:

- nik, ``IKSolver(robot, world=world)`` (self-collision checked with the world), the spheres judging;
- nik with ``mesh_verdict=True`` (the meshes judge; the spheres steer);
- PyRoki with the settings of its collision-free IK example (``examples/pyroki_snippets/_solve_ik_with_collision.py``:
  pose cost 5 / 1, rest cost 0.01, self-collision cost margin 2 cm weight 5, joint limits and one world-collision
  constraint per obstacle with margin 5 cm, dense Cholesky, 50 iterations; its capsule per link from the URDF's
  meshes, the SRDF's pairs ignored), one target per call of its jitted solve.

Reported: success (within 0.1 mm / 0.1 deg by nik's FK, and free by the solver's own verdict for nik; PyRoki gives
no verdict: its answer within tolerance counts), the answers that count as success but collide on the meshes
("false free", coal through :class:`nik.collision.meshcheck.MeshCheck`), time per target (median of the rounds,
nik and PyRoki interleaved in one process, one core) and the first call (PyRoki's jit compile; nik's kernels load
from their disk cache). PyRoki also solves the gripper's finger joints; the mesh check keeps the fingers at rest
(they do not move the hand). Without PyRoki (``pip install almond-pyroki``), coal or example-robot-data the script
says why and exits 0.

    JAX_PLATFORMS=cpu taskset -c 0 python benchmarks/pyroki_collisions.py --targets 150 --seed 0
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nik  # noqa: E402
from nik.collision import collides  # noqa: E402

TOL_POS, TOL_ROT = 1e-4, np.radians(0.1)


def _missing() -> str | None:
    """Why the comparison cannot run here, or None."""
    try:  # the peer first: without it there is no comparison, whatever else is installed
        import pyroki  # noqa: F401
        import yourdfpy  # noqa: F401
    except ImportError as err:
        return f"PyRoki is not installed ({err}; pip install almond-pyroki)"
    try:
        import coal  # noqa: F401
    except ImportError:
        return "coal is not installed (pip install 'nik-ik[collision-check]')"
    return None


def _pyroki_world(world):
    """The nik world's obstacles as PyRoki geometries (boxes, spheres, capsules)."""
    from pyroki.collision import Box, Capsule, Sphere
    from scipy.spatial.transform import Rotation

    geoms = []
    spheres, boxes, caps = world.packed()
    for s in spheres:
        geoms.append(Sphere.from_center_and_radius(s[:3], np.array([s[3]])))
    for b in boxes:
        xyzw = Rotation.from_matrix(b[:9].reshape(3, 3)).as_quat()
        geoms.append(Box.from_extent(2 * b[12:15], b[9:12], np.roll(xyzw, 1)))
    for c in caps:
        a, e, r = c[:3], c[3:6], c[6]
        axis = e - a
        rot, _ = Rotation.align_vectors([axis / np.linalg.norm(axis)], [[0.0, 0.0, 1.0]])
        geoms.append(Capsule.from_radius_height(r, np.linalg.norm(axis), (a + e) / 2, np.roll(rot.as_quat(), 1)))
    return geoms


def _pyroki_solver(urdf: Path, skip):
    """``solve(T (4, 4)) -> q (n,)`` with PyRoki's example settings, and the indices of nik's joints in its q."""
    import jax
    import jax.numpy as jnp
    import jax_dataclasses as jdc
    import jaxlie
    import jaxls
    import pyroki as pk
    import yourdfpy
    from loguru import logger

    from nik.collision.urdf import resolve_mesh_path

    logger.disable("pyroki")  # its problem-building log lines
    logger.disable("jaxls")

    model = yourdfpy.URDF.load(
        str(urdf), filename_handler=lambda fname: str(resolve_mesh_path(fname, urdf.parent)), load_collision_meshes=True
    )
    robot = pk.Robot.from_urdf(model)
    coll = pk.collision.RobotCollision.from_urdf(model, user_ignore_pairs=tuple(skip))
    link = robot.links.names.index("panda_hand")

    @jdc.jit
    def solve(robot, coll, world_coll, T_target, target_link):
        joint_var = robot.joint_var_cls(0)
        costs = [
            pk.costs.pose_cost(
                robot, joint_var, target_pose=T_target, target_link_index=target_link, pos_weight=5.0, ori_weight=1.0
            ),  # fmt: skip
            pk.costs.rest_cost(joint_var, rest_pose=jnp.array(joint_var.default_factory()), weight=0.01),
            pk.costs.self_collision_cost(robot, robot_coll=coll, joint_var=joint_var, margin=0.02, weight=5.0),
            pk.costs.limit_constraint(robot, joint_var),
        ]
        costs += [pk.costs.world_collision_constraint(robot, coll, joint_var, w, 0.05) for w in world_coll]
        sol = (
            jaxls.LeastSquaresProblem(costs=costs, variables=[joint_var])
            .analyze()
            .solve(
                verbose=False, linear_solver="dense_cholesky", termination=jaxls.TerminationConfig(max_iterations=50)
            )
        )
        return sol[joint_var]

    names = list(robot.joints.actuated_names)

    def run(T: np.ndarray, world_coll) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        wxyz = np.roll(Rotation.from_matrix(T[:3, :3]).as_quat(), 1)
        pose = jaxlie.SE3(jnp.concatenate([jnp.asarray(wxyz), jnp.asarray(T[:3, 3])]))
        return np.asarray(jax.block_until_ready(solve(robot, coll, world_coll, pose, jnp.array(link))))

    return run, names


def _errors(robot, q: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    F = robot.fk(np.ascontiguousarray(q))
    pos = np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=1)
    cos = (np.einsum("bij,bij->b", F[:, :3, :3], T[:, :3, :3]) - 1) / 2
    return pos, np.arccos(np.clip(cos, -1, 1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3, help="timed rounds per solver, interleaved (default 3)")
    args = ap.parse_args(argv)
    os.environ.setdefault("JAX_PLATFORMS", "cpu")  # before jax loads: one core, no busy-waiting thread pool
    os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
    why = _missing()
    if why is not None:
        print(f"skipped: {why}")
        return 0
    from collisions import panda_urdf, scene

    from nik.collision.meshcheck import MeshCheck
    from nik.collision.model import srdf_disabled, srdf_of

    try:
        urdf = panda_urdf()
    except SystemExit as err:
        print(f"skipped: {err}")
        return 0
    nik.set_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = nik.load_robot(urdf, end_link="panda_hand")
    world = scene(args.seed)
    skip = sorted(srdf_disabled(srdf_of(urdf)))
    mesh = MeshCheck(robot, urdf, skip=skip)
    q = robot.sample(20 * args.targets, generator=torch.Generator().manual_seed(args.seed), dtype=torch.float64)
    q = q.numpy()
    q = q[~collides(robot, q, world)][: args.targets]
    T = np.ascontiguousarray(robot.fk(q))
    print(f"panda (example-robot-data), table + 10 obstacles, {len(T)} targets free by nik's spheres; one core")

    spheres = nik.IKSolver(robot, world=world)
    judged = nik.IKSolver(robot, world=world, mesh_verdict=True)
    run, names = _pyroki_solver(urdf, skip)
    cols = [names.index(n) for n in robot.joint_names]
    world_coll = _pyroki_world(world)

    first = {}
    for label, call in (("nik", lambda: spheres.solve(T[:1])), ("nik, mesh verdict", lambda: judged.solve(T[:1])),
                        ("PyRoki", lambda: run(T[0], world_coll))):  # fmt: skip
        t = time.perf_counter()
        call()
        first[label] = time.perf_counter() - t

    def pyroki_all():
        return np.stack([run(T[i], world_coll)[cols] for i in range(len(T))])

    times = {k: [] for k in first}
    out = {}
    for _ in range(args.rounds):  # interleaved
        for label, call in (("nik", lambda: spheres.solve(T)), ("nik, mesh verdict", lambda: judged.solve(T)),
                            ("PyRoki", pyroki_all)):  # fmt: skip
            t = time.process_time()
            out[label] = call()
            times[label].append((time.process_time() - t) / len(T))

    print("| solver | success (0.1 mm / 0.1 deg, free) | within 1 mm / 1 deg | false free (meshes) | us/target CPU | "
          "first call (s) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for label, res in out.items():
        qa = res if label == "PyRoki" else res.q
        pos, rot = _errors(robot, qa, T)
        ok = (pos <= TOL_POS) & (rot <= TOL_ROT)
        loose = (pos <= 1e-3) & (rot <= np.radians(1.0))
        if label != "PyRoki":
            ok &= np.asarray(res.collision_free)
        hit = mesh.collides(qa, world)
        print(f"| {label} | {ok.mean():.1%} | {loose.mean():.1%} | {int((ok & hit).sum())} of {int(ok.sum())} | "
              f"{statistics.median(times[label]) * 1e6:.0f} | {first[label]:.1f} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
