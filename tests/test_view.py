"""nik.view: the arm's points, the picture (plot_arm, nik solve --plot), URDF meshes, the viser page (Viewer,
nik view), and the page in a real headless browser (Chromium driven through its DevTools protocol).

The viewer tests skip without viser (the ``view`` extra), the browser test without ``chromium-headless-shell``
(Debian: ``apt-get install chromium-headless-shell``), the mesh test without example-robot-data. Every server
listens on 127.0.0.1 on a free port and is stopped at the end; every wait is bounded.
"""

from __future__ import annotations

import base64
import importlib.metadata
import io
import itertools
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

import nik
from nik.cli import main
from nik.view import arm_points, plot_arm, viser_available

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium-headless-shell")
needs_viser = pytest.mark.skipif(not viser_available(), reason="viser not installed (pip install -e '.[view]')")


def _q(robot, n, seed=0):
    return robot.sample(n, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


# ---- the arm's points ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["puma560", "panda", "stanford"])
def test_arm_points_run_from_the_base_to_the_tool(name):
    robot = nik.load_robot(name)
    q = _q(robot, 5)
    pts = arm_points(robot, q)
    assert pts.shape == (5, robot.dof + 2, 3)
    torch.testing.assert_close(pts[:, 0], torch.zeros(5, 3, dtype=torch.float64))
    torch.testing.assert_close(pts[:, -1], robot.fk(q)[:, :3, 3], atol=1e-12, rtol=0)


def test_turning_a_revolute_joint_moves_no_point_before_it_nor_its_own():
    # the origin of joint i's frame lies on its axis: turning joint i alone leaves points 0..i where they were
    robot = nik.load_robot("panda")
    q = _q(robot, 1)[0]
    before = arm_points(robot, q)
    for i in range(robot.dof):
        turned = q.clone()
        turned[i] += 0.4
        after = arm_points(robot, turned)
        torch.testing.assert_close(after[: i + 2], before[: i + 2], atol=1e-12, rtol=0)
        assert (after[-1] - before[-1]).norm() > 1e-4 or i == robot.dof - 1  # the tool moves (but for a roll)


def test_arm_points_refuse_the_wrong_number_of_joints():
    with pytest.raises(ValueError, match="6"):
        arm_points(nik.load_robot("puma560"), torch.zeros(5, dtype=torch.float64))


# ---- the picture ---------------------------------------------------------------------------------------------------
def _pixels(path):
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def _blue(img):  # the arm's colour (#1f5fa8)
    return int(((img[..., 2] > img[..., 0] + 80) & (img[..., 2] > img[..., 1] + 40)).sum())


def _grey(img):  # the ghosts' colour (#7f7f7f at alpha 0.28 over white)
    spread = img.max(-1) - img.min(-1)
    return int(((spread < 8) & (img.mean(-1) > 150) & (img.mean(-1) < 225)).sum())


def test_plot_arm_draws_the_arm_and_faint_ghosts_and_leaves_no_temporary_file(tmp_path):
    robot = nik.load_robot("puma560")
    q = _q(robot, 1)
    T = robot.fk(q)
    sols = nik.IKSolver(robot).solve_all(T)
    assert len(sols) > 1
    plain = plot_arm(robot, q[0], tmp_path / "plain.png", T_target=T[0])
    ghosts = plot_arm(robot, q[0], tmp_path / "out" / "ghosts.png", ghosts=sols, T_target=T[0])
    a, b = _pixels(plain), _pixels(ghosts)
    assert _blue(a) > 2000  # the arm is there
    assert _grey(b) > _grey(a) + 1000  # and the other solutions, faint
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["ghosts.png", "plain.png"]


def test_plot_arm_refuses_bad_joints_and_an_unknown_suffix(tmp_path):
    robot = nik.load_robot("puma560")
    with pytest.raises(ValueError, match="6"):
        plot_arm(robot, torch.zeros(7, dtype=torch.float64), tmp_path / "a.png")
    with pytest.raises(ValueError, match="suffix"):
        plot_arm(robot, torch.zeros(6, dtype=torch.float64), tmp_path / "a.xyz")
    assert not any(tmp_path.iterdir())


def test_nik_solve_plot_and_all_draw_and_print_every_solution(tmp_path, capsys):
    out = tmp_path / "arm.png"
    rc = main(["solve", "--robot", "kuka_kr", "--pose", "1.0", "0.2", "1.2", "0", "0.7071068", "0", "0.7071068",
               "--all", "--plot", str(out)])  # fmt: skip
    text = capsys.readouterr().out
    assert rc == 0 and out.is_file() and _blue(_pixels(out)) > 2000
    count = int(re.search(r"pose 0: (\d+) distinct solution", text).group(1))
    assert count >= 1 and f"wrote {out}" in text
    rows = [line for line in text.splitlines() if line.startswith("  ") and len(line.split()) == 6]
    assert len(rows) == count
    robot = nik.load_robot("kuka_kr")
    T = nik.ik.as_poses(torch.tensor([[1.0, 0.2, 1.2, 0, 0.7071068, 0, 0.7071068]], dtype=torch.float64), "quat")
    q = torch.tensor([[float(v) for v in row.split()] for row in rows], dtype=torch.float64).deg2rad()
    pos, rot = nik.pose_error(T.expand(len(q), 4, 4), robot.fk(q))  # every printed row reaches the pose (FK)
    assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3


def test_nik_solve_json_lists_every_solution_with_all(tmp_path, capsys):
    rc = main(["solve", "--robot", "puma560", "--pose", "0.4", "0.15", "0.3", "0", "1", "0", "0", "--all", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert rc == 0 and len(doc["results"][0]["all_q_display"]) >= 2


def test_nik_solve_plot_with_a_bad_suffix_is_one_line(tmp_path, capsys):
    rc = main(["solve", "--robot", "puma560", "--pose", "0.4", "0.15", "0.3", "0", "1", "0", "0",
               "--plot", str(tmp_path / "arm.nope")])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "suffix" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


# ---- nik view without and with viser -------------------------------------------------------------------------------
def test_nik_view_without_viser_says_how_to_install_it(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser now raises ImportError
    assert main(["view", "puma560", "--port", "0"]) == 2
    captured = capsys.readouterr()
    assert captured.err.strip() == "nik view needs the optional extra: pip install 'nik-ik[view]'"
    assert "Traceback" not in captured.err + captured.out


def test_nik_view_refuses_a_bad_port_in_one_line(capsys):
    assert main(["view", "puma560", "--port", "70000"]) == 2
    err = capsys.readouterr().err
    assert "--port" in err and len(err.strip().splitlines()) == 1


@needs_viser
def test_nik_view_serves_the_page_on_localhost_then_stops(monkeypatch, tmp_path, capsys):
    from nik.view import Viewer

    seen = {}

    def serve_once(self):  # instead of blocking until Ctrl-C: check the page is served, then stop
        import urllib.request

        with urllib.request.urlopen(self.url, timeout=10) as page:
            seen["status"] = page.status
        seen["path"] = None if self.path is None else len(self.path)
        self.stop()

    monkeypatch.setattr(Viewer, "serve_forever", serve_once)
    csv = tmp_path / "path.csv"
    csv.write_text("x,y,z,qw,qx,qy,qz\n" + "".join(f"{0.4 + 0.01 * i},0.15,0.3,0,1,0,0\n" for i in range(5)))
    assert main(["view", "puma560", "--port", "0", "--path", str(csv)]) == 0
    assert re.search(r"at http://127\.0\.0\.1:\d+ ", capsys.readouterr().out)
    assert seen == {"status": 200, "path": 5}


def test_import_nik_view_and_nik_help_load_neither_viser_nor_matplotlib():
    code = (
        "import sys, contextlib, io\nimport nik.view\nfrom nik.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['view', '--help'])\n"
        "print(sorted(m for m in ('viser', 'matplotlib', 'trimesh', 'lightning') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


# ---- the Viewer's page API -----------------------------------------------------------------------------------------
def _joints_in(text: str, robot) -> torch.Tensor:
    """Joint angles (radians) read back from the page's joint text (``name: 12.3456 deg``)."""
    found = [re.search(rf"{re.escape(n)}: (-?[\d.]+) deg", text) for n in robot.joint_names]
    if not all(found):
        return None
    return torch.tensor([float(m.group(1)) for m in found], dtype=torch.float64).deg2rad()


@needs_viser
def test_viewer_set_target_solves_from_the_current_joints_and_shows_them():
    from nik.view import Viewer, ViewerCfg

    robot = nik.load_robot("puma560")
    with Viewer(robot, cfg=ViewerCfg(port=0)) as viewer:
        q_true = _q(robot, 1, seed=3)[0]
        T = robot.fk(q_true)
        shown = viewer.set_target(T)
        assert shown.success and viewer.server.get_host() == "127.0.0.1"
        pos, rot = nik.pose_error(T, robot.fk(viewer.joints))  # FK round trip of what the page shows
        assert float(pos) < 1e-4 and float(rot) < 1e-3
        torch.testing.assert_close(_joints_in(viewer._joint_text.content, robot), viewer.joints, atol=1e-5, rtol=0)
        ghosts = viewer.ghosts  # every solution of the pose, each reaching it (FK), none twice
        assert len(ghosts) == len(nik.IKSolver(robot).solve_all(T[None])) >= 2
        pos, rot = nik.pose_error(T.expand(len(ghosts), 4, 4), robot.fk(ghosts))
        assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3
        assert float(torch.cdist(ghosts, ghosts).add(torch.eye(len(ghosts)) * 9).min()) > 1e-3
        assert f"{len(ghosts)} distinct solutions" in viewer._ghost_text.content
        # a small move of the target: the arm follows with a small joint motion (q_near = the current joints)
        before = viewer.joints
        T2 = T.clone()
        T2[:3, 3] += torch.tensor([0.01, -0.01, 0.005], dtype=torch.float64)
        assert viewer.set_target(T2).success
        assert float((viewer.joints - before).abs().max()) < math.radians(10)
        viewer.cfg.tol_pos = 1e-4
        far = T.clone()
        far[:3, 3] = torch.tensor([5.0, 0.0, 0.0], dtype=torch.float64)
        shown = viewer.set_target(far)
        assert not shown.success and not shown.reachable and "out of reach" in viewer._status.content


@needs_viser
def test_dragging_the_target_solves_the_newest_pose_in_the_solver_thread():
    from types import SimpleNamespace

    from nik.poses import matrix_to_quaternion
    from nik.view import Viewer, ViewerCfg

    robot = nik.load_robot("panda")  # no closed form: LM from the current joints
    with Viewer(robot, cfg=ViewerCfg(port=0)) as viewer:
        assert len(viewer.ghosts) > 0
        start = viewer.joints
        T = viewer.target
        for k in range(1, 6):  # the events of one drag, as viser's transform controls send them
            moved = T.clone()
            moved[:3, 3] += k * torch.tensor([0.01, 0.0, -0.01], dtype=torch.float64)
            gizmo = SimpleNamespace(wxyz=matrix_to_quaternion(moved[:3, :3]).numpy(), position=moved[:3, 3].numpy())
            viewer._dragged(SimpleNamespace(target=gizmo, phase="update"))
        done = _wait_for(lambda: bool(torch.allclose(viewer.target, moved, atol=1e-12)), timeout=30, every=0.05)
        assert done, "the solver thread never showed the last pose of the drag"
        assert len(viewer.ghosts) == 0  # while dragging: the first pose's ghosts are gone, no new ones yet
        viewer._dragged(SimpleNamespace(target=gizmo, phase="end"))  # release: the ghosts of the final pose
        assert _wait_for(lambda: len(viewer.ghosts) > 0, timeout=60, every=0.1), "no ghosts after the drag ended"
        pos, rot = nik.pose_error(moved.expand(len(viewer.ghosts), 4, 4), robot.fk(viewer.ghosts))
        assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3
        pos, rot = nik.pose_error(moved, robot.fk(viewer.joints))
        assert viewer.shown.success and float(pos) < 1e-4 and float(rot) < 1e-3
        assert float((viewer.joints - start).abs().max()) < math.radians(20)  # followed, not a new branch


@needs_viser
def test_viewer_plays_a_path_back_as_a_continuous_trajectory():
    from nik.view import Viewer, ViewerCfg

    robot = nik.load_robot("ur5")
    q0 = _q(robot, 1, seed=1)[0]
    steps = torch.linspace(0, 1, 12, dtype=torch.float64)[:, None]
    T_path = robot.fk(q0 + steps * torch.tensor([0.3, -0.2, 0.25, 0.1, -0.2, 0.3], dtype=torch.float64))
    with Viewer(robot, cfg=ViewerCfg(port=0, play_rate=50.0, ghosts=False), path=T_path) as viewer:
        traj = []
        for i in range(len(T_path)):
            viewer.show_waypoint(i)
            traj.append(viewer.joints)
            assert int(viewer._slider.value) == i
        traj = torch.stack(traj)
        pos, rot = nik.pose_error(T_path, robot.fk(traj))
        assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3
        assert float((traj[1:] - traj[:-1]).abs().max()) < math.radians(15)  # no jump between branches
        with pytest.raises(ValueError, match="out of range"):
            viewer.show_waypoint(len(T_path))
        start = int(viewer._slider.value)
        viewer._play.value = True  # press play: the waypoints advance by themselves
        deadline = time.monotonic() + 10
        while int(viewer._slider.value) == start and time.monotonic() < deadline:
            time.sleep(0.05)
        assert int(viewer._slider.value) != start


# ---- URDF meshes ---------------------------------------------------------------------------------------------------
def _erd_urdf(rel: str) -> Path | None:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    path = Path(dist.locate_file(f"cmeel.prefix/share/example-robot-data/robots/{rel}"))
    return path if path.is_file() else None


UR5_MESHED = _erd_urdf("ur_description/urdf/ur5_robot.urdf")


@pytest.mark.skipif(UR5_MESHED is None, reason="example-robot-data not installed (pip install -e '.[urdf-tests]')")
def test_urdf_meshes_sit_where_pytorch_kinematics_puts_each_link():
    pytest.importorskip("trimesh")
    import pytorch_kinematics as pk

    from nik.robots.urdf import kinematic_urdf
    from nik.view.urdf_meshes import load_urdf_visuals

    robot = nik.load_robot(UR5_MESHED, end_link="tool0")
    scene, note = load_urdf_visuals(robot)
    assert scene is not None, note
    assert {"shoulder_link", "forearm_link", "wrist_3_link"} <= set(scene.links)
    assert all(len(v.faces) > 0 for v in scene.visuals)
    chain = pk.build_chain_from_urdf(kinematic_urdf(UR5_MESHED.read_bytes()))  # an independent FK of every link
    names = chain.get_joint_parameter_names()
    for q in _q(robot, 3, seed=2):
        th = torch.zeros(len(names), dtype=torch.float64)
        for i, n in enumerate(robot.joint_names):
            th[names.index(n)] = q[i]
        ref = chain.to(dtype=torch.float64).forward_kinematics(th[None])
        poses = scene.link_poses(q)
        for link in scene.links:
            np.testing.assert_allclose(poses[link], ref[link].get_matrix()[0].numpy(), atol=1e-6)


def test_urdf_meshes_of_the_joints_outside_the_chain_stand_at_the_robots_joint_values(tmp_path):
    pytest.importorskip("trimesh")
    import pytorch_kinematics as pk

    from nik.robots.urdf import kinematic_urdf
    from nik.view.urdf_meshes import load_urdf_visuals

    box = '<visual><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.05 0.05"/></geometry></visual>'
    joint = (
        '<joint name="{0}" type="revolute"><parent link="{1}"/><child link="{2}"/><origin xyz="{3}"/>'
        '<axis xyz="0 0 1"/><limit lower="{4}" upper="2" effort="1" velocity="1"/></joint>'
    )
    text = (
        f'<robot name="two"><link name="torso">{box}</link>'
        + "".join(f'<link name="{n}">{box}</link>' for n in ("r1", "r2", "l1", "l2"))
        + joint.format("r_s0", "torso", "r1", "0 -0.3 0.6", -2)
        + joint.format("r_e0", "r1", "r2", "0.4 0 0", -2)
        + joint.format("l_s0", "torso", "l1", "0 0.3 0.6", -2)
        + joint.format("l_e0", "l1", "l2", "0.4 0 0", 0.5)  # 0 outside its range: it stands at the middle, 1.25
        + "</robot>"
    )
    path = tmp_path / "two.urdf"
    path.write_text(text)
    robot = nik.load_robot(path, end_link="r2", joint_values={"l_s0": -1.0})
    scene, note = load_urdf_visuals(robot)
    assert scene is not None, note
    chain = pk.build_chain_from_urdf(kinematic_urdf(text)).to(dtype=torch.float64)  # every link, independently
    names = chain.get_joint_parameter_names()
    q = torch.tensor([0.4, -0.7], dtype=torch.float64)
    th = torch.zeros(len(names), dtype=torch.float64)
    for name, v in (("r_s0", 0.4), ("r_e0", -0.7), ("l_s0", -1.0), ("l_e0", 1.25)):
        th[names.index(name)] = v
    ref = chain.forward_kinematics(th[None])
    poses = scene.link_poses(q)
    for link in ("r2", "l1", "l2"):
        np.testing.assert_allclose(poses[link], ref[link].get_matrix()[0].numpy(), atol=1e-6)


def test_a_robot_without_a_urdf_is_drawn_as_capsules():
    pytest.importorskip("trimesh")
    from nik.view.urdf_meshes import load_urdf_visuals

    for name in ("puma560", "ur5"):  # a DH table; a URDF shipped with kinematics only
        scene, note = load_urdf_visuals(nik.load_robot(name))
        assert scene is None and "capsules" in note


def test_mesh_paths_resolve_package_urls_from_the_folders_above(tmp_path):
    from nik.view.urdf_meshes import resolve_mesh_path

    mesh = tmp_path / "share" / "my_pkg" / "meshes" / "a.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text("solid a\nendsolid a\n")
    urdf_dir = tmp_path / "share" / "my_pkg" / "urdf"
    urdf_dir.mkdir()
    assert resolve_mesh_path("package://my_pkg/meshes/a.stl", urdf_dir) == mesh
    assert resolve_mesh_path("../meshes/a.stl", urdf_dir) == urdf_dir / "../meshes/a.stl"
    assert resolve_mesh_path("package://other_pkg/meshes/a.stl", urdf_dir) is None


# ---- the page in a real headless browser ---------------------------------------------------------------------------
class DevTools:
    """A headless Chromium driven through its DevTools protocol (one websocket, flat sessions); bounded waits."""

    def __init__(self, profile: Path, *, size=(900, 650), timeout: float = 30.0):
        from websockets.sync.client import connect

        self.proc = subprocess.Popen(
            [CHROMIUM, "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             f"--window-size={size[0]},{size[1]}", "--remote-debugging-address=127.0.0.1",
             "--remote-debugging-port=0", f"--user-data-dir={profile}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        url, deadline = None, time.monotonic() + timeout
        while url is None and time.monotonic() < deadline and self.proc.poll() is None:
            m = re.search(r"DevTools listening on (ws://\S+)", self.proc.stderr.readline())
            url = m.group(1) if m else None
        if url is None:
            self.close()
            raise RuntimeError("chromium-headless-shell did not open its DevTools port")
        self.ws = connect(url, open_timeout=timeout, max_size=64 * 2**20)
        self.ids = itertools.count(1)
        self.session = None

    def call(self, method: str, params=None, *, timeout: float = 30.0) -> dict:
        i = next(self.ids)
        msg = {"id": i, "method": method, "params": params or {}}
        if self.session and not method.startswith("Target."):
            msg["sessionId"] = self.session
        self.ws.send(json.dumps(msg))
        deadline = time.monotonic() + timeout
        while True:
            reply = json.loads(self.ws.recv(timeout=max(0.05, deadline - time.monotonic())))
            if reply.get("id") == i:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def open(self, url: str) -> None:
        target = self.call("Target.createTarget", {"url": url})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})["result"].get("value")

    def text(self) -> str:
        return self.evaluate("document.body ? document.body.innerText : ''") or ""

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, timeout=60)["data"])

    def close(self) -> None:
        if getattr(self, "ws", None) is not None:
            self.ws.close()
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)


def _wait_for(check, *, timeout: float, every: float = 0.2):
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(every)


@pytest.mark.long
@needs_viser
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium-headless-shell (apt-get install chromium-headless-shell)")
def test_page_in_a_headless_browser_draws_the_arm_and_shows_the_joints_of_a_moved_target(tmp_path):
    from PIL import Image

    from nik.view import Viewer, ViewerCfg

    robot = nik.load_robot("ur5")
    with Viewer(robot, cfg=ViewerCfg(port=0, seed=4)) as viewer:
        browser = DevTools(tmp_path / "profile")
        try:
            browser.open(viewer.url)
            # the page loads and shows the joints of the first solve, as text the browser renders
            text = _wait_for(lambda: t if _joints_in(t := browser.text(), robot) is not None else "", timeout=60)
            assert text, "the page never showed the joint angles"
            torch.testing.assert_close(_joints_in(text, robot), viewer.joints, atol=1e-5, rtol=0)

            # the arm is drawn: the 3-D view (left of the panel) is not blank
            def drawn():
                # close the notice "Software WebGL rendering detected" (it would hide part of the view)
                browser.evaluate(
                    "document.querySelectorAll('.mantine-Notification-closeButton').forEach(b => b.click())"
                )
                png = browser.screenshot()
                img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)[170:, :540]
                arm = ((img[..., 2] > img[..., 0] + 40) & (img[..., 2] > 120)).sum()  # the arm's blue capsules
                return png if arm > 1500 and (np.abs(img - 255).sum(-1) > 60).sum() > 8000 else None

            png = _wait_for(drawn, timeout=90, every=1.0)
            assert png is not None, "the screenshot stayed blank"
            (tmp_path / "view.png").write_bytes(png)
            if os.environ.get("NIK_DOCS_SCREENSHOT"):  # refresh the picture of docs/view.md
                (ROOT / "docs" / "view.png").write_bytes(png)

            # a target moved through the page's API (Viewer.set_target): the page shows the new joint angles
            before = _joints_in(text, robot)
            T = viewer.target.clone()
            T[:3, 3] += torch.tensor([-0.05, 0.04, 0.06], dtype=torch.float64)
            assert viewer.set_target(T).success
            moved = viewer.joints
            assert float((moved - before).abs().max()) > math.radians(1)
            shown = _wait_for(
                lambda: (q := _joints_in(browser.text(), robot)) is not None and bool((q - moved).abs().max() < 1e-5),
                timeout=30,
            )
            assert shown, "the page did not show the new joint angles"
        finally:
            browser.close()
