"""Timing of a joint path: the time-optimal trajectory through its waypoints within joint speed and acceleration
limits (and, as an option, a speed limit of the tool), computed by TOPP-RA (``toppra``, a core dependency).

One job: waypoints ``q: (N, dof)`` in, :class:`Timing` out: ``t: (N,)`` seconds at each waypoint, ``qd, qdd:
(N, dof)`` the joint velocities and accelerations there, the duration, and the trajectory to sample between.

Choices (each kept small so that the answer is toppra's own):

- **Geometric path.** toppra's cubic spline (``SplineInterpolator``, not-a-knot) through the distinct waypoints,
  parametrised by ``s = cumsum(max_j |dq_j| / v_j)``: seconds, the time the slowest joint of each step needs at
  full speed, so revolute and prismatic joints mix without units. Consecutive equal waypoints share one ``s``
  (and so one time). With a ``robot``, a cubic that leaves the joint limits between waypoints (a path that hugs a
  limit overshoots it) is replaced by the shape-preserving PCHIP interpolant (monotone between waypoints, so never
  past a waypoint's value: the joint limits are kept). PCHIP is C1 only: its ``q''`` jumps at the waypoints, and
  toppra reads a path at a gridpoint from the right, so a second acceleration constraint reads ``q''`` there from
  the left (both sides of every waypoint kept).
- **Grid.** Every waypoint is a gridpoint (so ``t`` at a waypoint is toppra's time of that gridpoint); each step
  is cut evenly so that the grid has at least :data:`GRID_MIN` intervals, and an interval is halved while a
  straight chord across it departs from the path by more than :data:`GRID_ERR` (toppra's own
  ``propose_gridpoints`` rule), so bends are checked densely.
- **Parametrisation.** ``toppra.algorithm.TOPPRA`` (seidel solver) with ``JointVelocityConstraint`` and
  ``JointAccelerationConstraint`` (toppra's default interpolation discretisation) and the ``ParametrizeConstAccel``
  output: constant path acceleration between gridpoints, so the trajectory passes exactly through the path at
  every gridpoint. Rest to rest: zero velocity at the first and last waypoint.
- **Closed paths** (first row equal to the last): timed rest to rest too, so a repeated cycle stops at its seam.
  A cycle without the stop would need the seam velocity to be a fixed point of the whole cycle's reachable sets;
  not done.
- **No acceleration limits** (``acc_limits`` None): :data:`DEFAULT_ACC_PER_VEL` times the speed limits (full
  speed within 0.1 s), recorded in :attr:`Timing.acc_assumed`: toppra with velocity limits alone lets the path
  speed jump between gridpoints, so its answer would be a property of the grid, not of the robot.
- **Tool speed** (``tool_speed`` m/s, needs ``robot``): an upper bound on toppra's ``x = sd^2`` at each gridpoint,
  ``tool_speed^2 / |J_v(q(s)) q'(s)|^2``: exactly the tool's linear speed ``|J_v qd| <= tool_speed`` (``J_v`` the
  linear rows of the geometric Jacobian, base frame), given to toppra as a constraint of the same kind as its joint
  velocity constraint (a bound on ``x``), not a scaling of the joint limits.
- **Check.** toppra keeps the limits at its gridpoints; between them the trajectory may pass a limit by a little.
  Every interval between gridpoints is sampled at :data:`CHECK_POINTS` instants (its ends included, seen from
  inside), then the trajectory every :data:`CHECK_DT` (1 ms, a controller's period); where some speed or
  acceleration passes its limit by more than :data:`RATE_RTOL`, the whole trajectory is slowed uniformly,
  ``t -> k t, qd -> qd / k, qdd -> qdd / k^2``, by the least ``k`` that brings every sample within its limit
  (:attr:`Timing.stretch`: 1 when toppra's answer keeps every limit; the duration is toppra's times the stretch;
  measured on IK paths of ur5 and panda, ``benchmarks/timing.py``: 1 to 1.02).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from nik.robots.rates import check_rates

__all__ = [
    "CHECK_DT",
    "CHECK_POINTS",
    "DEFAULT_ACC_PER_VEL",
    "GRID_ERR",
    "GRID_MAX",
    "GRID_MIN",
    "RATE_RTOL",
    "TIME_COLUMN",
    "Timing",
    "check_scale",
    "read_time_column",
    "scale_limits",
    "time_cells",
    "time_path",
]

#: The acceleration limits assumed where none are known: this many times the speed limits (1/s): full speed in 0.1 s.
DEFAULT_ACC_PER_VEL = 10.0
#: Least number of grid intervals of toppra's discretisation (every waypoint is a gridpoint; steps cut evenly).
GRID_MIN = 400
#: Largest chord error (radians; metres for prismatic joints) of a grid interval: bends get a denser grid.
GRID_ERR = 1e-4
#: Most grid intervals (the refinement by GRID_ERR stops before).
GRID_MAX = 20_000
#: Instants checked in every interval between gridpoints (its two ends included).
CHECK_POINTS = 17
#: Sampling period of the final check (seconds): a controller's.
CHECK_DT = 1e-3
#: Relative excess over a limit taken as float rounding of toppra's solver (not slowed for).
RATE_RTOL = 1e-9
#: Name of the time column of the path CSV (seconds).
TIME_COLUMN = "t_s"

_INSTALL = "timing needs toppra: pip install 'nik-ik[timing]' (or pip install toppra)"


@dataclass
class Timing:
    """A timed joint path (SI: seconds, rad/s, rad/s^2; m/s and m/s^2 for prismatic joints).

    Attributes:
        t: (N,) time at each waypoint, ``t[0] = 0``, non-decreasing (equal for consecutive equal waypoints).
        qd: (N, dof) joint velocities at the waypoints (zero at the first and last).
        qdd: (N, dof) joint accelerations at the waypoints: the constant acceleration of the interval that starts
            there (the one that ends there at the last waypoint).
        duration: seconds, ``t[-1]``.
        vel_limits, acc_limits: (dof,) the limits kept (after any scale).
        acc_assumed: True where ``acc_limits`` were not given (:data:`DEFAULT_ACC_PER_VEL`).
        tool_speed: the tool's speed limit kept (m/s), or None.
        stretch: the uniform slow-down the check applied (>= 1; 1 when toppra's answer keeps every limit).
        toppra_duration: the duration of toppra's answer (``duration = toppra_duration * stretch``).
        interpolation: ``"cubic"`` (toppra's spline) or ``"pchip"`` (where the cubic left the joint limits).
        s: (N,) the waypoints' path parameter; gridpoints: (G,) toppra's grid (every ``s`` among them).
        path: toppra's geometric path (``path(s, order)``); trajectory: toppra's output ``traj(t / stretch, order)``
            (None for a path that does not move).
    """

    t: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    duration: float
    vel_limits: np.ndarray
    acc_limits: np.ndarray
    acc_assumed: bool
    tool_speed: float | None
    stretch: float
    toppra_duration: float
    interpolation: str
    s: np.ndarray
    gridpoints: np.ndarray
    path: object = field(repr=False, default=None)
    trajectory: object = field(repr=False, default=None)
    _knots: tuple = field(repr=False, default=())  # (ts, ss, sd, u) of the gridpoints, toppra's time

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at times ``t: (M,)`` seconds (clamped into ``[0, duration]``):
        ``(M, dof)`` each, vectorised (toppra's ``ParametrizeConstAccel`` evaluates the same formulas one by one)."""
        t = np.clip(np.asarray(t, dtype=np.float64).reshape(-1), 0.0, self.duration)
        dof = self.qd.shape[1]
        if self.trajectory is None:
            q0 = np.broadcast_to(self.path(self.s[:1])[0], (t.size, dof)).copy()
            return q0, np.zeros((t.size, dof)), np.zeros((t.size, dof))
        k = self.stretch
        s, v, a = _state(self.path, self._knots, t / k)
        d1 = self.path(s, 1)
        return self.path(s), d1 * v[:, None] / k, (self.path(s, 2) * v[:, None] ** 2 + d1 * a[:, None]) / k**2

    def sample(self, dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The trajectory every ``dt`` seconds (default 1 ms, a controller's period) and at its end:
        ``t: (M,)``, ``q, qd, qdd: (M, dof)``."""
        if not dt > 0:
            raise ValueError(f"sample: dt must be > 0 seconds, got {dt}")
        t = np.append(np.arange(0.0, self.duration, dt), self.duration)
        return (t, *self.at(t))


def check_scale(scale, what: str = "vel_scale") -> float:
    """``scale`` as a float when ``0 < scale <= 1`` (a fraction of the robot's limits, as ``nik path --vel-scale S``
    / ``--acc-scale S`` give it); else ValueError, one line naming ``what`` (the CLI passes its option's name)."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale <= 1:
        raise ValueError(f"{what}: must be a number in (0, 1], got {scale!r}")
    return float(scale)


def scale_limits(limits, scale: float, *, what: str = "vel_scale") -> np.ndarray:
    """``limits: (dof,)`` times ``scale`` (checked by :func:`check_scale`), as float64."""
    return np.asarray(limits, dtype=np.float64) * check_scale(scale, what)


def time_path(
    q,
    vel_limits=None,
    acc_limits=None,
    *,
    robot=None,
    tool_speed: float | None = None,
    vel_scale: float = 1.0,
    acc_scale: float = 1.0,
) -> Timing:
    """The time-optimal trajectory through the joint path ``q`` (module docstring: the choices).

    Args:
        q: (N, dof) waypoints (radians; metres for prismatic joints), a continuous path (no turn jumps).
        vel_limits: (dof,) largest joint speeds (rad/s, m/s); default ``robot.vel_limits``.
        acc_limits: (dof,) largest joint accelerations (rad/s^2, m/s^2); default ``robot.acc_limits``, else
            :data:`DEFAULT_ACC_PER_VEL` times the speed limits (:attr:`Timing.acc_assumed`).
        robot: the arm (:class:`nik.Robot`): limits, joint names in messages, the joint-limit guard of the
            interpolant and the Jacobian of ``tool_speed``.
        tool_speed: largest linear speed of the tool (m/s; needs ``robot``), or None.
        vel_scale, acc_scale: fractions (0, 1] of the limits to use.

    Returns:
        :class:`Timing`. Raises ValueError (one line) on bad waypoints or limits, on missing speed limits, and
        when toppra is not installed (naming the ``timing`` extra) or finds no parametrisation.
    """
    qa = q.detach().cpu().double().numpy() if isinstance(q, torch.Tensor) else np.asarray(q, dtype=np.float64)
    if qa.ndim != 2 or qa.shape[0] < 1:
        raise ValueError(f"time_path: q must be (N, dof) waypoints, got shape {qa.shape}")
    if not np.isfinite(qa).all():
        raise ValueError(f"time_path: q has NaN or inf at waypoint {int(np.argwhere(~np.isfinite(qa))[0, 0])}")
    dof = qa.shape[1]
    names = robot.joint_names if robot is not None else None
    if robot is not None and robot.dof != dof:
        raise ValueError(f"time_path: {robot.name} has {robot.dof} joints, q has {dof} columns")
    if vel_limits is None and robot is not None:
        vel_limits = robot.vel_limits
    if acc_limits is None and robot is not None:
        acc_limits = robot.acc_limits
    if vel_limits is None:
        who = f"{robot.name} has none" if robot is not None else "none given"
        raise ValueError(f"timing needs joint speed limits: {who} (give vel_limits=, rad/s per joint)")
    vel = scale_limits(check_rates(vel_limits, dof, what="vel_limits", names=names).numpy(), vel_scale)
    acc_assumed = acc_limits is None
    acc = vel * DEFAULT_ACC_PER_VEL if acc_assumed else check_rates(acc_limits, dof, what="acc_limits", names=names)
    acc = scale_limits(np.asarray(acc), acc_scale, what="acc_scale")
    if tool_speed is not None:
        if robot is None:
            raise ValueError("tool_speed needs robot= (the tool's speed comes from the arm's Jacobian)")
        if isinstance(tool_speed, bool) or not (isinstance(tool_speed, (int, float)) and 0 < tool_speed < math.inf):
            raise ValueError(f"tool_speed: must be a finite number > 0 (m/s), got {tool_speed!r}")
        tool_speed = float(tool_speed)
    if robot is not None:
        _check_within_limits(qa, robot)
    toppra = _toppra()

    step = np.max(np.abs(np.diff(qa, axis=0)) / vel, axis=1) if len(qa) > 1 else np.zeros(0)
    s = np.concatenate([[0.0], np.cumsum(step)])
    keep = np.concatenate([[True], step > 0])  # the first of each run of equal waypoints
    s_u, q_u = s[keep], qa[keep]
    common = dict(vel_limits=vel, acc_limits=acc, acc_assumed=acc_assumed, tool_speed=tool_speed, s=s)
    if len(s_u) == 1:  # the path does not move
        path = toppra.SplineInterpolator(s_u, q_u)
        zero = np.zeros_like(qa)
        return Timing(np.zeros(len(qa)), zero, zero.copy(), 0.0, stretch=1.0, toppra_duration=0.0,
                      interpolation="cubic", gridpoints=s_u.copy(), path=path, **common)  # fmt: skip

    interpolation, path = "cubic", toppra.SplineInterpolator(s_u, q_u)
    grid, at_waypoint = _grid(s_u, path)
    constraints = [
        toppra.constraint.JointVelocityConstraint(vel),
        toppra.constraint.JointAccelerationConstraint(acc),
    ]
    if robot is not None and not _path_within_limits(path, grid, robot):
        interpolation, path = "pchip", _pchip_path(toppra, s_u, q_u)
        grid, at_waypoint = _grid(s_u, path)
        constraints.append(_left_acceleration(toppra, acc, path, s_u[1:]))
    if tool_speed is not None:
        constraints.append(_tool_speed_constraint(toppra, robot, tool_speed))
    algo = toppra.algorithm.TOPPRA(
        constraints, path, gridpoints=grid, solver_wrapper="seidel", parametrizer="ParametrizeConstAccel"
    )
    traj = algo.compute_trajectory(0.0, 0.0)
    if traj is None:
        raise ValueError(
            f"toppra found no time parametrisation of this path (return code {algo.problem_data.return_code})"
        )
    sd = np.asarray(algo.problem_data.sd_vec, dtype=np.float64)
    ds = np.diff(grid)
    u = (sd[1:] ** 2 - sd[:-1] ** 2) / (2 * ds)
    ts = np.concatenate([[0.0], np.cumsum(2 * ds / (sd[:-1] + sd[1:]))])
    knots = (ts, grid, sd, u)
    stretch = _stretch(path, knots, vel, acc, robot, tool_speed)

    g = at_waypoint[np.cumsum(keep) - 1]  # each waypoint's gridpoint (equal waypoints: the first's)
    seg = np.minimum(g, len(u) - 1)
    d1, d2 = path(grid[g], 1), path(grid[g], 2)
    v, a = sd[g][:, None], u[seg][:, None]
    return Timing(
        ts[g] * stretch,
        d1 * v / stretch,
        (d2 * v**2 + d1 * a) / stretch**2,
        float(ts[-1] * stretch),
        stretch=stretch,
        toppra_duration=float(traj.duration),
        interpolation=interpolation,
        gridpoints=grid,
        path=path,
        trajectory=traj,
        _knots=knots,
        **common,
    )


# ---------------------------------------------------------------------------
# the parts
# ---------------------------------------------------------------------------
def _toppra():
    try:
        import toppra
        import toppra.algorithm
        import toppra.constraint
    except ImportError as err:
        raise ValueError(_INSTALL) from err
    return toppra


def _check_within_limits(q: np.ndarray, robot) -> None:
    lim = robot.limits.numpy()
    out = (q < lim[:, 0] - 1e-9) | (q > lim[:, 1] + 1e-9)
    if out.any():
        i, j = (int(x) for x in np.argwhere(out)[0])
        raise ValueError(
            f"time_path: waypoint {i} is outside the joint limits ({robot.joint_names[j]}: {q[i, j]:.6g} not in "
            f"[{lim[j, 0]:.6g}, {lim[j, 1]:.6g}])"
        )


def _grid(s: np.ndarray, path) -> tuple[np.ndarray, np.ndarray]:
    """toppra's gridpoints ``(G,)`` and the index of each ``s`` among them.

    Every ``s``; each step cut evenly into ``ceil(ds / h)`` pieces with ``h = s[-1] / GRID_MIN``; then, as
    toppra's ``propose_gridpoints`` does, a piece is halved while the error of a straight chord across it,
    ``0.5 max_j |q_j''(mid)| h^2``, is above :data:`GRID_ERR` (at most :data:`GRID_MAX` intervals): where the path
    bends, toppra's constraints are checked more densely.
    """
    ds = np.diff(s)
    pieces = np.maximum(1, np.ceil(ds / (s[-1] / GRID_MIN) - 1e-9)).astype(int)
    grid = np.concatenate([s[i] + ds[i] * np.arange(pieces[i]) / pieces[i] for i in range(len(ds))] + [s[-1:]])
    grid[np.concatenate([[0], np.cumsum(pieces)])] = s  # exactly the waypoints' s
    for _ in range(32):
        h = np.diff(grid)
        mid = grid[:-1] + 0.5 * h
        split = 0.5 * np.abs(path(mid, 2)).max(axis=1) * h**2 > GRID_ERR
        if not split.any() or len(grid) + int(split.sum()) > GRID_MAX + 1:
            break
        grid = np.sort(np.concatenate([grid, mid[split]]))
    return grid, np.searchsorted(grid, s)


def _dense(grid: np.ndarray) -> np.ndarray:
    """:data:`CHECK_POINTS` instants (path parameter) in every interval of ``grid``, ends included: ``(G-1, P)``."""
    w = np.linspace(0.0, 1.0, CHECK_POINTS)
    return grid[:-1, None] + np.diff(grid)[:, None] * w


def _path_within_limits(path, grid: np.ndarray, robot) -> bool:
    qs = path(_dense(grid).reshape(-1))
    lim = robot.limits.numpy()
    return bool(((qs >= lim[:, 0] - 1e-9) & (qs <= lim[:, 1] + 1e-9)).all())


def _pchip_path(toppra, s: np.ndarray, q: np.ndarray):
    """A toppra geometric path through ``q: (M, dof)`` at ``s: (M,)`` by scipy's PCHIP (shape preserving)."""
    from scipy.interpolate import PchipInterpolator

    class PchipPath(toppra.interpolator.AbstractGeometricPath):
        def __init__(self):
            self.f = PchipInterpolator(s, q, axis=0)
            self.d = [self.f, self.f.derivative(1), self.f.derivative(2)]

        def __call__(self, path_positions, order=0):
            return self.d[order](path_positions)

        @property
        def dof(self):
            return q.shape[1]

        @property
        def path_interval(self):
            return np.array([s[0], s[-1]])

        @property
        def waypoints(self):
            return s, q

    return PchipPath()


def _left_acceleration(toppra, acc: np.ndarray, path, knots: np.ndarray):
    """toppra's joint acceleration constraint with ``q''`` taken from the left at ``knots`` (PCHIP's inner
    waypoints, where ``q''`` jumps): toppra evaluates a path at a gridpoint from the right, so with this second
    constraint the acceleration at the end of the interval before a waypoint is kept too."""

    class LeftPath(toppra.interpolator.AbstractGeometricPath):
        def __call__(self, path_positions, order=0):
            x = np.asarray(path_positions, dtype=np.float64)
            if order == 2:
                x = np.where(np.isin(x, knots), np.nextafter(x, -np.inf), x)
            return path(x, order)

        dof = property(lambda self: path.dof)
        path_interval = property(lambda self: path.path_interval)

    class LeftAcceleration(toppra.constraint.JointAccelerationConstraint):
        def compute_constraint_params(self, _path, gridpoints, *args, **kwargs):
            return super().compute_constraint_params(LeftPath(), gridpoints, *args, **kwargs)

    return LeftAcceleration(acc)


def _tool_linear_rate(robot, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """``|J_v(q) dq|`` for ``q, dq: (M, dof)``: the tool's linear speed per unit of ``dq`` (metres)."""
    _, J = robot.fk_and_jacobian(torch.from_numpy(np.ascontiguousarray(q)))
    return np.linalg.norm(np.einsum("mij,mj->mi", J[:, :3, :].numpy(), dq), axis=1)


def _tool_speed_constraint(toppra, robot, speed: float):
    """toppra constraint ``x = sd^2 <= speed^2 / |J_v(q(s)) q'(s)|^2`` at each gridpoint."""

    class ToolSpeedConstraint(toppra.constraint.LinearConstraint):
        def __init__(self):
            super().__init__()
            self.dof = robot.dof
            self._format_string = f"    Tool speed limit: {speed} m/s\n"

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            rate = _tool_linear_rate(robot, path(gridpoints), path(gridpoints, 1))
            xbound = np.zeros((len(gridpoints), 2))
            xbound[:, 1] = speed**2 / np.maximum(rate, 1e-12) ** 2
            return None, None, None, None, None, None, xbound

    return ToolSpeedConstraint()


def _state(path, knots, t: np.ndarray):
    """Path parameter ``s: (M,)``, path speed ``sd: (M,)``, path acceleration ``u: (M,)`` at toppra's times
    ``t: (M,)`` (as ``ParametrizeConstAccel`` evaluates them)."""
    ts, ss, sd, u = knots
    i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(u) - 1)
    tau = t - ts[i]
    s = np.clip(ss[i] + sd[i] * tau + 0.5 * u[i] * tau**2, ss[0], ss[-1])
    return s, sd[i] + u[i] * tau, u[i]


def _worst(path, s, v, a, vel, acc, robot, tool_speed) -> float:
    """The largest ratio of a speed to its limit, or of the square root of an acceleration to its limit's, at path
    parameters ``s: (M,)`` with path speeds ``v`` and path accelerations ``a``."""
    d1 = path(s, 1)
    ratio = max(
        float(np.max(np.abs(d1 * v[:, None]) / vel)),
        math.sqrt(float(np.max(np.abs(path(s, 2) * v[:, None] ** 2 + d1 * a[:, None]) / acc))),
    )
    if tool_speed is not None:
        ratio = max(ratio, float(np.max(_tool_linear_rate(robot, path(s), d1) * v)) / tool_speed)
    return ratio


def _stretch(path, knots, vel, acc, robot, tool_speed) -> float:
    """The least uniform slow-down ``k >= 1`` that keeps every speed and acceleration within its limit where
    checked: :data:`CHECK_POINTS` instants per grid interval (both ends with that interval's acceleration), then
    the stretched trajectory every :data:`CHECK_DT` (a controller's 1 ms), slowed again until no sample passes."""
    ts, ss, sd, u = knots
    tau = np.diff(ts)[:, None] * np.linspace(0.0, 1.0, CHECK_POINTS)
    s = np.clip(ss[:-1, None] + sd[:-1, None] * tau + 0.5 * u[:, None] * tau**2, ss[:-1, None], ss[1:, None])
    s[:, -1] = np.nextafter(ss[1:], -np.inf)  # the interval's end seen from inside it (a jump of q'' there)
    v = sd[:-1, None] + u[:, None] * tau
    ratio = _worst(path, s.reshape(-1), v.reshape(-1), np.repeat(u, CHECK_POINTS), vel, acc, robot, tool_speed)
    k = ratio if ratio > 1 + RATE_RTOL else 1.0
    for _ in range(8):
        duration = float(ts[-1] * k)  # as Timing.sample takes the samples
        t = np.append(np.arange(0.0, duration, CHECK_DT), duration) / k
        s, v, a = _state(path, knots, t)
        ratio = _worst(path, s, v / k, a / k**2, vel, acc, robot, tool_speed)
        if ratio <= 1 + RATE_RTOL:
            break
        k *= ratio
    return k


# ---------------------------------------------------------------------------
# the t_s column of the path CSV
# ---------------------------------------------------------------------------
def time_cells(t) -> list[str]:
    """``t: (N,)`` seconds as the cells of the path CSV's :data:`TIME_COLUMN` (microsecond resolution)."""
    return [f"{float(v):.6f}" for v in np.asarray(t, dtype=np.float64).reshape(-1)]


def read_time_column(path: str | Path) -> np.ndarray:
    """The :data:`TIME_COLUMN` of a path CSV as ``(N,)`` float64 seconds; ValueError (one line) when the file has
    no such column or a cell is not a finite number, negative, or smaller than the one before."""
    path = Path(path)
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or TIME_COLUMN not in rows[0]:
        raise ValueError(f"{path}: no {TIME_COLUMN!r} column (write the trajectory with timing)")
    col = rows[0].index(TIME_COLUMN)
    out = np.empty(len(rows) - 1)
    for i, row in enumerate(rows[1:]):
        try:
            out[i] = float(row[col])
        except (ValueError, IndexError):
            raise ValueError(f"{path}: row {i + 1}: {TIME_COLUMN} is not a number") from None
        if not (math.isfinite(out[i]) and out[i] >= 0 and (i == 0 or out[i] >= out[i - 1])):
            raise ValueError(
                f"{path}: row {i + 1}: {TIME_COLUMN} = {row[col]} (times must be finite, >= 0 and non-decreasing)"
            )
    return out
