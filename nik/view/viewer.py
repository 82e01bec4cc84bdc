"""The browser page of ``nik view``: :class:`Viewer`, a viser server showing an arm and its IK answer.

What the page shows:

- the arm at the current solution: the URDF's meshes where the files are there
  (:mod:`nik.view.urdf_meshes`), else each link as a capsule between joint origins (:mod:`nik.view.arm`);
- a target frame with transform controls: dragging it solves the new pose (one ``IKSolver.solve``, ``q_near``
  the current joints, so the arm moves smoothly) and the GUI shows the success flag, the position and rotation
  errors (mm, deg) and the joint angles (deg; prismatic joints in mm) as text;
- every solution of the pose (``IKSolver.solve_all``) as faint ghost arms (a check box), drawn when a drag
  ends;
- with ``poses``: a slider over them; with ``path``: the path drawn, its joint trajectory
  (:meth:`nik.IKSolver.solve_path`: continuous over the whole path) played back with a slider and a play button;
- collisions (:mod:`nik.ik.collide`): the obstacles of the solver's world (orange: spheres, boxes, capsules; a
  point cloud as points), the arm's collision spheres (a check box, off by default; the model is built when first
  shown), and, where the solver checks collisions, the spheres of every colliding link in red (whatever the check
  box says) with the verdict and the colliding links' names in the panel.

Drags arrive on viser's thread pool; one worker thread solves the newest pose and drops the ones that a
newer drag superseded, so the page never queues stale solves; the ghosts wait for the end of the drag.
:meth:`Viewer.set_target` solves in the caller's thread (the page's API for scripts and tests).
:meth:`Viewer.stop` stops the server and threads.
"""

from __future__ import annotations

import math
import threading
import time
import warnings
from dataclasses import dataclass

import numpy as np
import torch

from nik.poses import matrix_to_quaternion, quaternion_to_matrix, validate_pose
from nik.robots.model import axis_frame
from nik.tolerances import DEFAULT_TOL_POS, DEFAULT_TOL_ROT, describe
from nik.view.arm import arm_points

__all__ = ["VIEW_EXTRA_MESSAGE", "MissingExtraError", "ViewState", "Viewer", "ViewerCfg", "viser_available"]

VIEW_EXTRA_MESSAGE = "nik view needs the optional extra: pip install 'nik-ik[view]'"

_ARM_RGB = (40, 100, 180)
_JOINT_RGB = (30, 30, 30)
_GHOST_RGB = (175, 175, 185)
_PATH_RGB = (230, 120, 20)
_OBSTACLE_RGB = (235, 140, 40)
_SPHERE_RGB = (60, 160, 230)
_HIT_RGB = (220, 30, 30)


class MissingExtraError(ImportError):
    """viser (the ``view`` extra) is not installed; the message says how to install it."""


def viser_available() -> bool:
    """True when viser can be imported (the ``view`` extra is installed)."""
    try:
        import viser  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass
class ViewerCfg:
    """Settings of a :class:`Viewer`."""

    host: str = "127.0.0.1"  # address the server listens on
    port: int = 8080  # TCP port; 0: any free port (see Viewer.url); viser moves on when the port is taken
    tol_pos: float = DEFAULT_TOL_POS  # metres: the success tolerance shown
    tol_rot: float = DEFAULT_TOL_ROT  # radians
    seed: int = 0  # seeds the solver and the starting configuration
    ghosts: bool = True  # draw every solution of the pose (solve_all) as faint arms
    max_ghosts: int = 8  # at most this many ghost arms (a 7-joint arm has a continuum of solutions)
    ghost_starts: int = 16  # solve_all's uniform starts on an arm without a closed form (256 took seconds on panda)
    link_radius: float | None = None  # metres, the capsules' radius; None: 2.5 % of the arm's size
    meshes: bool = True  # URDF meshes where the files are there (False: capsules always)
    play_rate: float = 10.0  # waypoints per second when a path plays
    spheres: bool = False  # draw the arm's collision spheres (the check box's first state)


@dataclass
class ViewState:
    """What the page shows: the target ``T (4, 4)`` (metres), the joints ``q (dof,)`` and the solve that gave them."""

    T: torch.Tensor
    q: torch.Tensor
    success: bool
    reachable: bool
    pos_err: float  # metres
    rot_err: float  # radians
    source: str
    ms: float
    collision_free: bool | None = None  # None where the solver checks no collisions


class Viewer:
    """A viser page showing ``solver``'s answer for a target that the user drags.

    Args:
        solver: a :class:`nik.IKSolver`, or a robot / built-in name (then ``IKSolver(robot)``).
        cfg: :class:`ViewerCfg`.
        poses: optional ``(B, 4, 4)`` targets (metres), chosen with a slider; the first is shown first.
        path: optional ``(N, 4, 4)`` waypoints of a path, played back; its first waypoint is shown first.

    With neither, the first target is the FK of a seeded random configuration in the middle half of every
    joint's range (so that a drag does not run into a limit at once).
    The server starts at construction; use as a context manager or call :meth:`stop`.

    Raises:
        MissingExtraError: viser is not installed.
        ValueError: malformed poses.
    """

    def __init__(self, solver, *, cfg: ViewerCfg | None = None, poses=None, path=None, verbose: bool = False):
        try:
            import viser
        except ImportError as err:
            raise MissingExtraError(VIEW_EXTRA_MESSAGE) from err
        from nik.solver import IKSolver

        self.cfg = cfg or ViewerCfg()
        self.solver = solver if isinstance(solver, IKSolver) else IKSolver(solver)
        self.robot = self.solver.robot
        self.poses = None if poses is None else _poses(poses, "poses")
        self.path = None if path is None else _poses(path, "path")
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._pending: tuple[torch.Tensor, bool] | None = None  # the newest dragged pose, and whether the drag ended
        self._playing = threading.Event()
        self.ghosts = torch.zeros(0, self.robot.dof, dtype=torch.float64)
        self._ghost_node = None  # the line segments of every ghost arm

        self.server = viser.ViserServer(host=self.cfg.host, port=self.cfg.port, verbose=verbose)
        try:
            self._build()
        except BaseException:
            self.server.stop()
            raise
        self._worker = threading.Thread(target=self._drag_loop, name="nik-view-solver", daemon=True)
        self._worker.start()
        self._player = None
        if self.path is not None:
            self._player = threading.Thread(target=self._play_loop, name="nik-view-player", daemon=True)
            self._player.start()

    # -- the page's API -------------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """``http://HOST:PORT`` of the page (the port viser bound)."""
        return f"http://{self.cfg.host}:{self.server.get_port()}"

    @property
    def joints(self) -> torch.Tensor:
        """``(dof,)`` the joints shown now, radians (metres for prismatic joints)."""
        with self._lock:
            return self._shown.q.clone()

    @property
    def target(self) -> torch.Tensor:
        """``(4, 4)`` the target pose shown now, metres."""
        with self._lock:
            return self._shown.T.clone()

    @property
    def shown(self) -> ViewState:
        """The last solve: target, joints, success, reachability, errors (SI), guess used, time (ms)."""
        with self._lock:
            return self._shown

    def set_target(self, T) -> ViewState:
        """Move the target to ``T: (4, 4)`` (or (7,) xyz + wxyz quaternion), solve it from the current joints,
        update the page (arm, text, ghosts) and return what is shown. Runs in the caller's thread."""
        T = _poses(T, "T")[0]
        with self._lock:
            self._move_gizmo(T)
            self._solve_and_show(T)
            self._update_ghosts()
            return self._shown

    def show_pose(self, i: int) -> ViewState:
        """Target ``poses[i]`` (the slider does the same)."""
        if self.poses is None:
            raise ValueError("show_pose: this viewer was given no poses")
        i = _index(i, len(self.poses), "pose")
        slider = getattr(self, "_pose_slider", None)
        if slider is not None and int(slider.value) != i:
            slider.value = i  # the page's slider follows
        return self.set_target(self.poses[i])

    def show_waypoint(self, i: int) -> ViewState:
        """Show the path's trajectory at waypoint ``i`` (no new solve: the trajectory's joints there)."""
        if self.path is None:
            raise ValueError("show_waypoint: this viewer was given no path")
        i = _index(i, len(self.path), "waypoint")
        if int(self._slider.value) != i:
            self._slider.value = i  # the page's slider follows
        with self._lock:
            T = self.path[i]
            self._move_gizmo(T)
            self._show(self._path_shown[i])
            self._update_ghosts(skip=self._playing.is_set())  # while the path plays: no ghosts (solve_all per frame)
            return self._shown

    def serve_forever(self) -> None:
        """Block until :meth:`stop` (from another thread) or Ctrl-C; then stop."""
        try:
            while not self._stop.wait(0.5):
                pass
        finally:
            self.stop()

    def stop(self) -> None:
        """Stop the player, the solver thread and the server (bounded waits). Safe to call twice."""
        if self._stop.is_set() and not self._worker.is_alive():
            return
        self._stop.set()
        self._wake.set()
        self._playing.clear()
        for thread in (self._worker, self._player):
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=5.0)
        self.server.stop()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- building the page ----------------------------------------------------------------------------
    def _build(self) -> None:
        robot, cfg, server = self.robot, self.cfg, self.server
        gen = torch.Generator().manual_seed(cfg.seed)
        lo, hi = robot.limits[:, 0], robot.limits[:, 1]
        middle = torch.stack([0.75 * lo + 0.25 * hi, 0.25 * lo + 0.75 * hi], dim=1)  # the middle half of each range
        q_home = robot.sample(1, generator=gen, dtype=torch.float64, ranges=middle)[0]  # room to move every way
        pts = arm_points(robot, robot.sample(64, generator=gen, dtype=torch.float64)).reshape(-1, 3)
        self._size = float(max((pts.max(0).values - pts.min(0).values).max(), 0.05))
        self._radius = cfg.link_radius or 0.025 * self._size
        server.scene.set_up_direction("+z")
        server.scene.add_grid("/floor", width=2 * self._size, height=2 * self._size, cell_size=0.1)
        look = arm_points(robot, q_home).mean(0).numpy()  # the arm's middle, seen from a corner, a little above
        server.initial_camera.look_at = tuple(look)
        server.initial_camera.position = tuple(look + np.array([0.45, 0.6, 0.3]) * self._size)

        self._meshes = None
        self._mesh_note = "links drawn as capsules between joint origins"
        if cfg.meshes:
            from nik.view.urdf_meshes import load_urdf_visuals

            self._meshes, self._mesh_note = load_urdf_visuals(robot)
        if self._meshes is not None:
            self._link_nodes = {
                link: server.scene.add_frame(f"/arm/{link}", show_axes=False) for link in self._meshes.links
            }
            for k, vis in enumerate(self._meshes.visuals):
                server.scene.add_mesh_simple(f"/arm/{vis.link}/visual{k}", vis.vertices, vis.faces, color=vis.color)
        else:
            self._capsules = self._add_capsules("/arm", _ARM_RGB)
        self._tool = server.scene.add_frame("/tool", axes_length=0.1 * self._size, axes_radius=0.006 * self._size)
        self._gizmo = server.scene.add_transform_controls("/target", scale=0.15 * self._size)
        server.scene.add_frame("/target/axes", axes_length=0.12 * self._size, axes_radius=0.004 * self._size)

        self._collisions_build()
        gui = server.gui
        gui.add_markdown(f"**{robot.name}**, {robot.dof} joints{_tool_text(robot)}  \n{self._mesh_note}")
        self._status = gui.add_markdown("")
        self._joint_text = gui.add_markdown("")
        self._ghost_box = gui.add_checkbox("all solutions (faint)", cfg.ghosts)
        self._ghost_text = gui.add_markdown("")
        self._ghost_box.on_update(lambda _: self._locked(self._update_ghosts))
        self._sphere_box = gui.add_checkbox("collision spheres", cfg.spheres)
        self._sphere_box.on_update(lambda _: self._locked(lambda: self._show_collisions(self._shown.q)))

        self._gizmo.on_update(self._dragged)

        self._path_shown: list[ViewState] = []
        if self.poses is not None:
            first = self.poses[0]
            if len(self.poses) > 1:
                self._pose_slider = gui.add_slider("pose", 0, len(self.poses) - 1, 1, 0)
                self._pose_slider.on_update(lambda _: self.show_pose(int(self._pose_slider.value)))
        elif self.path is not None:
            first = self.path[0]
            self._solve_path()
            line = np.stack([self.path[:-1, :3, 3].numpy(), self.path[1:, :3, 3].numpy()], axis=1)
            server.scene.add_line_segments("/path", line, _PATH_RGB, thickness=0.3 * self._radius)
            ok = sum(s.success for s in self._path_shown)
            gui.add_markdown(
                f"path: {len(self.path)} waypoints, {ok} reached within {describe(cfg.tol_pos, cfg.tol_rot)}"
            )
            self._slider = gui.add_slider("waypoint", 0, len(self.path) - 1, 1, 0)
            self._slider.on_update(lambda _: self.show_waypoint(int(self._slider.value)))
            self._play = gui.add_button("play / pause")
            self._play.on_click(lambda _: self._playing.clear() if self._playing.is_set() else self._playing.set())
        else:
            first = robot.fk(q_home)
        self._shown = ViewState(first, q_home, False, True, math.nan, math.nan, "", 0.0)
        self._solve(first, q_home)  # warm-up (kernels load on the first call): the page shows the time of a move
        with self._lock:
            self._move_gizmo(first)
            if self.path is not None:
                self._show(self._path_shown[0])
            else:
                self._solve_and_show(first)
            self._update_ghosts()

    def _add_capsules(self, name: str, rgb) -> list:
        """One unit cylinder per segment (scaled to its length) and a sphere per joint: ``[cyl..., sph...]``."""
        scene, r = self.server.scene, self._radius
        n = self.robot.dof + 1
        cyl = [scene.add_cylinder(f"{name}/link{i}", radius=r, height=1.0, color=rgb) for i in range(n)]
        sph = [
            scene.add_icosphere(f"{name}/joint{i}", radius=1.25 * r, color=_JOINT_RGB, subdivisions=2)
            for i in range(n + 1)
        ]
        return cyl + sph

    def _place_capsules(self, nodes: list, q: torch.Tensor) -> None:
        pts = arm_points(self.robot, q).numpy()
        n = self.robot.dof + 1
        for i in range(n):
            a, b = pts[i], pts[i + 1]
            d = b - a
            length = float(np.linalg.norm(d))
            node = nodes[i]
            node.visible = length > 1e-9
            if length > 1e-9:
                R = torch.as_tensor(axis_frame(d / length)[:3, :3])
                node.position = tuple(0.5 * (a + b))
                node.wxyz = tuple(matrix_to_quaternion(R).tolist())
                node.scale = (1.0, 1.0, length)
        for i in range(n + 1):
            nodes[n + i].position = tuple(pts[i])

    # -- solving and showing --------------------------------------------------------------------------
    def _solve(self, T: torch.Tensor, q_near: torch.Tensor) -> ViewState:
        t0 = time.perf_counter()
        with warnings.catch_warnings():  # an unreachable target is shown on the page, not warned about
            warnings.simplefilter("ignore", UserWarning)
            res = self.solver.solve(
                T[None], tol_pos=self.cfg.tol_pos, tol_rot=self.cfg.tol_rot, seed=self.cfg.seed, q_near=q_near
            )
        ms = 1e3 * (time.perf_counter() - t0)
        return ViewState(
            T,
            res.q[0].double(),
            bool(res.success[0]),
            bool(res.reachable[0]),
            float(res.pos_err[0]),
            float(res.rot_err[0]),
            res.source,
            ms,
            None if res.collision_free is None else bool(res.collision_free[0]),
        )

    def _solve_path(self) -> None:
        """The path's trajectory from :meth:`nik.IKSolver.solve_path` (the choice over the whole path: no branch
        jump where one can be avoided); each waypoint shown as the solve there, its time the call's share."""
        t0 = time.perf_counter()
        with warnings.catch_warnings():  # unreached waypoints are shown on the page, not warned about
            warnings.simplefilter("ignore", UserWarning)
            res = self.solver.solve_path(
                self.path, tol_pos=self.cfg.tol_pos, tol_rot=self.cfg.tol_rot, seed=self.cfg.seed
            )
        ms = 1e3 * (time.perf_counter() - t0) / len(self.path)
        for i, T in enumerate(self.path):
            self._path_shown.append(
                ViewState(
                    T,
                    res.q[i].double(),
                    bool(res.success[i]),
                    bool(res.reachable[i]),
                    float(res.pos_err[i]),
                    float(res.rot_err[i]),
                    res.source,
                    ms,
                    None if res.collision_free is None else bool(res.collision_free[i]),
                )
            )

    def _solve_and_show(self, T: torch.Tensor) -> None:
        self._show(self._solve(T, self._shown.q))

    def _show(self, shown: ViewState) -> None:
        self._shown = shown
        q = shown.q
        if self._meshes is not None:
            for link, pose in self._meshes.link_poses(q).items():
                node = self._link_nodes.get(link)
                if node is not None:
                    node.position = tuple(pose[:3, 3])
                    node.wxyz = tuple(matrix_to_quaternion(torch.as_tensor(pose[:3, :3])).tolist())
        else:
            self._place_capsules(self._capsules, q)
        T_tool = self.robot.fk(q)
        self._tool.position = tuple(T_tool[:3, 3].tolist())
        self._tool.wxyz = tuple(matrix_to_quaternion(T_tool[:3, :3]).tolist())
        verdict = "**reached**" if shown.success else ("**out of reach**" if not shown.reachable else "**NOT reached**")
        self._status.content = (
            f"{verdict} within {describe(self.cfg.tol_pos, self.cfg.tol_rot)}  \n"
            f"position error {shown.pos_err * 1e3:.4f} mm, rotation error {math.degrees(shown.rot_err):.4f} deg  \n"
            f"guess: {shown.source or '-'}, solved in {shown.ms:.1f} ms"
        )
        self._joint_text.content = joint_lines(self.robot, q)
        self._show_collisions(q)

    # -- collisions -----------------------------------------------------------------------------------
    def _collisions_build(self) -> None:
        """The world's obstacles (static) and the collision check of the solver (None: none)."""
        from nik.ik import collide

        self._check = collide.setup(self.robot, self.solver.world, self.solver.self_collision)
        self._model, self._sphere_nodes = None, None
        world = self.solver.world
        if world is None or world.empty:
            return
        scene = self.server.scene
        spheres, boxes, capsules = world.packed()
        if len(spheres) > 200:  # a point cloud
            scene.add_point_cloud("/world/points", spheres[:, :3].astype(np.float32), _OBSTACLE_RGB,
                                  point_size=float(2 * np.median(spheres[:, 3])), point_shape="circle")  # fmt: skip
        else:
            for k, c in enumerate(spheres):
                scene.add_icosphere(f"/world/sphere{k}", radius=float(c[3]), color=_OBSTACLE_RGB, opacity=0.6,
                                    position=tuple(c[:3]))  # fmt: skip
        for k, b in enumerate(boxes):
            R = torch.as_tensor(b[:9].reshape(3, 3))
            scene.add_box(f"/world/box{k}", _OBSTACLE_RGB, tuple(2 * b[12:15]), opacity=0.5, position=tuple(b[9:12]),
                          wxyz=tuple(matrix_to_quaternion(R).tolist()))  # fmt: skip
        for k, c in enumerate(capsules):
            a, e, r = c[:3], c[3:6], float(c[6])
            d = e - a
            length = float(np.linalg.norm(d))
            R = torch.as_tensor(axis_frame(d / length if length > 1e-12 else np.array([0.0, 0.0, 1.0]))[:3, :3])
            wxyz = tuple(matrix_to_quaternion(R).tolist())
            scene.add_cylinder(f"/world/capsule{k}", radius=r, height=max(length, 1e-6), color=_OBSTACLE_RGB,
                               opacity=0.6, position=tuple(0.5 * (a + e)), wxyz=wxyz)  # fmt: skip
            for j, p in enumerate((a, e)):
                scene.add_icosphere(f"/world/capsule{k}/end{j}", radius=r, color=_OBSTACLE_RGB, opacity=0.6,
                                    position=tuple(p))  # fmt: skip

    def colliding_links(self, q: torch.Tensor) -> list[str]:
        """Names of the links that collide at ``q (dof,)`` under the solver's check (empty without one)."""
        if self._check is None:
            return []
        from nik.collision import colliding_links

        model = self._check.model
        hit = colliding_links(self.robot, q[None], self._check.world, model=model, self_collision=self._check.self_on)
        return [name for name, h in zip(model.links, hit[0], strict=True) if h]

    def _show_collisions(self, q: torch.Tensor) -> None:
        """Place the arm's spheres: every one when the check box is ticked, those of colliding links in red; the
        verdict in the panel."""
        want = bool(self._sphere_box.value)
        if self._check is None and not want and self._sphere_nodes is None:
            return
        if self._model is None:
            from nik.collision import collision_model

            self._model = self._check.model if self._check is not None else collision_model(self.robot)
        model = self._model
        hit_names = set(self.colliding_links(q))
        if self._sphere_nodes is None:
            scene = self.server.scene
            self._sphere_nodes = [
                (scene.add_icosphere(f"/spheres/s{k}", radius=float(r), color=_SPHERE_RGB, opacity=0.3,
                                     subdivisions=2, visible=False),
                 scene.add_icosphere(f"/spheres/hit{k}", radius=float(r), color=_HIT_RGB, opacity=0.7,
                                     subdivisions=2, visible=False))
                for k, r in enumerate(model.radii)
            ]  # fmt: skip
        from nik.collision import sphere_centers

        centres = sphere_centers(model, self.robot, q[None].double())[0].numpy()
        body = model.sphere_body
        for k, (plain, red) in enumerate(self._sphere_nodes):
            is_hit = model.links[body[k]] in hit_names
            node = red if is_hit else plain
            if is_hit or want:
                node.position = tuple(centres[k])
            node.visible = is_hit or want
            (plain if is_hit else red).visible = False
        if self._check is not None:
            verdict = "collision-free" if not hit_names else "**COLLIDING**: " + ", ".join(sorted(hit_names))
            self._status.content = self._status.content.split("  \ncollisions:")[0] + f"  \ncollisions: {verdict}"

    def _update_ghosts(self, *, skip: bool = False) -> None:
        """Solve every solution of the shown pose and draw up to ``max_ghosts`` of them as faint arms: one
        line-segments node for all (one message per update, however many ghosts); ``skip``: none."""
        if self._ghost_node is not None:
            self._ghost_node.remove()
            self._ghost_node = None
        if skip or not self._ghost_box.value:
            self.ghosts = torch.zeros(0, self.robot.dof, dtype=torch.float64)
            self._ghost_text.content = ""
            return
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            sols = self.solver.solve_all(
                self._shown.T[None],
                tol_pos=self.cfg.tol_pos,
                tol_rot=self.cfg.tol_rot,
                seed=self.cfg.seed,
                n_starts=self.cfg.ghost_starts,
            )
        self.ghosts = sols.double()
        shown = sols[: self.cfg.max_ghosts]
        if len(shown):
            pts = arm_points(self.robot, shown.double()).numpy()  # (K, dof + 2, 3)
            segments = np.stack([pts[:, :-1], pts[:, 1:]], axis=2).reshape(-1, 2, 3)
            self._ghost_node = self.server.scene.add_line_segments(
                "/ghosts", segments, _GHOST_RGB, thickness=0.6 * self._radius, thickness_units="world"
            )
        more = f" ({len(shown)} drawn)" if len(sols) > len(shown) else ""
        self._ghost_text.content = f"{len(sols)} distinct solutions of this pose{more}"

    def _move_gizmo(self, T: torch.Tensor) -> None:
        self._gizmo.position = tuple(T[:3, 3].tolist())
        self._gizmo.wxyz = tuple(matrix_to_quaternion(T[:3, :3]).tolist())

    def _locked(self, fn) -> None:
        with self._lock:
            fn()

    # -- threads ---------------------------------------------------------------------------------------
    def _dragged(self, event) -> None:
        """The transform controls moved (viser's thread pool): hand the newest pose to the solver thread."""
        T = torch.eye(4, dtype=torch.float64)
        T[:3, :3] = quaternion_to_matrix(torch.tensor(np.asarray(event.target.wxyz), dtype=torch.float64))
        T[:3, 3] = torch.tensor(np.asarray(event.target.position), dtype=torch.float64)
        self._pending = (T, getattr(event, "phase", "end") == "end")
        self._wake.set()

    def _drag_loop(self) -> None:
        """Solve the newest dragged pose; the ghosts (every solution: slower) once the drag has ended."""
        while not self._stop.is_set():
            if not self._wake.wait(0.5):
                continue
            self._wake.clear()
            pending, self._pending = self._pending, None
            if pending is None or self._stop.is_set():
                continue
            T, ended = pending
            with self._lock:
                self._solve_and_show(T)
                self._update_ghosts(skip=not ended or self._pending is not None)  # stale ghosts go meanwhile

    def _play_loop(self) -> None:
        """While playing, advance the waypoint slider ``play_rate`` times a second (wrapping at the end)."""
        while not self._stop.is_set():
            if not self._playing.wait(0.5):
                continue
            if self._stop.wait(1.0 / max(self.cfg.play_rate, 1e-3)):
                break
            if self._playing.is_set():
                self._slider.value = (int(self._slider.value) + 1) % len(self.path)


def joint_lines(robot, q: torch.Tensor) -> str:
    """Markdown, one line per joint: ``name: 12.3456 deg`` (prismatic joints: ``name: 12.3456 mm``)."""
    lines = []
    for name, v, p in zip(robot.joint_names, q.tolist(), robot.prismatic.tolist(), strict=True):
        lines.append(f"{name}: {v * 1e3:.4f} mm" if p else f"{name}: {math.degrees(v):.4f} deg")
    return "joints  \n" + "  \n".join(lines)


def _tool_text(robot) -> str:
    return f", tool link {robot.end_link}" if robot.end_link else ""


def _poses(T, name: str) -> torch.Tensor:
    """``(B, 4, 4)`` float64 from (4, 4), (B, 4, 4), (7,) or (B, 7) xyz + wxyz (metres)."""
    from nik.ik import as_poses

    T = torch.as_tensor(T, dtype=torch.float64)
    if T.ndim == 2 and T.shape == (4, 4):
        T = T[None]
    T = as_poses(T, None, name=name)
    return validate_pose(T.double(), name=name)


def _index(i: int, n: int, what: str) -> int:
    if not 0 <= int(i) < n:
        raise ValueError(f"{what} index {i} out of range 0..{n - 1}")
    return int(i)
