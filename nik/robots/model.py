"""The :class:`Robot` model and the builders that reduce DH, modified DH and screw-axis
(product of exponentials) tables, with revolute and prismatic joints, to the FK normal form
of :mod:`nik.kinematics`."""

from __future__ import annotations

import hashlib
import math
import warnings
from collections.abc import Sequence

import numpy as np
import torch

from nik.kernels import background as _background
from nik.kinematics import FKKernel, chain_jacobian, to_homogeneous
from nik.poses import validate_joints
from nik.robots.rates import check_rates

__all__ = ["Robot", "NormalFormBuilder", "dh_chain", "mdh_chain", "poe_chain", "rot_x", "rot_z", "trans", "axis_frame"]


# ---------------------------------------------------------------------------
# Elementary float64 transforms (numpy, built once at load time)
# ---------------------------------------------------------------------------
def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """Pure translation, 4x4."""
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def rot_x(angle: float) -> np.ndarray:
    """Rotation about x, 4x4. Exact at multiples of pi/2."""
    c, s = _cos_sin(angle)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def rot_z(angle: float) -> np.ndarray:
    """Rotation about z, 4x4. Exact at multiples of pi/2."""
    c, s = _cos_sin(angle)
    T = np.eye(4)
    T[0:2, 0:2] = [[c, -s], [s, c]]
    return T


def _cos_sin(angle: float) -> tuple[float, float]:
    # Snap multiples of pi/2 so that tables in degrees give exact 0 and +-1 entries.
    quarter = angle / (math.pi / 2)
    if abs(quarter - round(quarter)) < 1e-12:
        k = int(round(quarter)) % 4
        return [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][k]
    return math.cos(angle), math.sin(angle)


def axis_frame(axis: Sequence[float]) -> np.ndarray:
    """A rotation ``P`` (4x4) with ``P e_z = axis``, so that ``Rot(axis, q) = P Rz(q) P^T``.

    Exact (entries 0 and +-1) for axes along the coordinate axes.
    """
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    h = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = h - (h @ a) * a
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    P = np.eye(4)
    P[:3, :3] = np.stack([x, y, a], axis=1)
    return P


class NormalFormBuilder:
    """Collects a chain of fixed transforms and joints into ``G: (n + 1, 4, 4)``.

    ``fixed(M)`` right-multiplies a constant transform; ``joint(axis)`` inserts a revolute
    joint about ``axis`` (``P Rz(q) P^T``), ``joint(axis, prismatic=True)`` a prismatic joint
    along it (``P Tz(q) P^T``), ``axis`` expressed in the current frame. :attr:`prismatic`
    lists the joint types so far.
    """

    def __init__(self, base: np.ndarray | None = None):
        self._current = np.eye(4) if base is None else np.asarray(base, dtype=float)
        self._G: list[np.ndarray] = []
        self.prismatic: list[bool] = []

    def fixed(self, M: np.ndarray) -> NormalFormBuilder:
        self._current = self._current @ M
        return self

    def joint(self, axis: Sequence[float] = (0.0, 0.0, 1.0), *, prismatic: bool = False) -> NormalFormBuilder:
        P = axis_frame(axis)
        self._G.append(self._current @ P)
        self._current = P.T.copy()
        self.prismatic.append(bool(prismatic))
        return self

    def finish(self, tool: np.ndarray | None = None) -> np.ndarray:
        last = self._current if tool is None else self._current @ tool
        return np.stack(self._G + [last])


def _flags(prismatic, n: int) -> list[bool]:
    flags = [False] * n if prismatic is None else [bool(v) for v in prismatic]
    if len(flags) != n:
        raise ValueError(f"prismatic: expected {n} flags, got {len(flags)}")
    return flags


def dh_chain(alpha, a, d, *, base=None, tool=None, prismatic=None, theta=None) -> np.ndarray:
    """Standard (distal) DH: ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``; SI units. Returns G.

    Revolute joint ``i``: ``theta_i`` is the joint variable (plus its offset, outside G). Prismatic
    joint ``i`` (``prismatic[i]``): ``theta_i`` is the constant ``theta[i]`` (radians, default 0) and
    the variable is added to ``d_i``; as ``Rz`` and ``Tz`` commute, ``A_i = Tz(q) Tz(d_i) Rz(theta_i) ...``.
    """
    flags = _flags(prismatic, len(alpha))
    theta = [0.0] * len(alpha) if theta is None else list(theta)
    b = NormalFormBuilder(base)
    for al, ai, di, th, pr in zip(alpha, a, d, theta, flags, strict=True):
        if pr:
            b.joint(prismatic=True).fixed(trans(z=di) @ rot_z(th) @ trans(x=ai) @ rot_x(al))
        else:
            b.joint().fixed(trans(z=di) @ trans(x=ai) @ rot_x(al))
    return b.finish(tool)


def mdh_chain(alpha, a, d, *, base=None, tool=None, prismatic=None, theta=None) -> np.ndarray:
    """Modified DH (Craig): ``A_i = Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i)``; SI units. Returns G.

    Prismatic joints as in :func:`dh_chain`: constant ``theta[i]``, variable added to ``d_i``.
    """
    flags = _flags(prismatic, len(alpha))
    theta = [0.0] * len(alpha) if theta is None else list(theta)
    b = NormalFormBuilder(base)
    for al, ai, di, th, pr in zip(alpha, a, d, theta, flags, strict=True):
        if pr:
            b.fixed(rot_x(al) @ trans(x=ai) @ rot_z(th) @ trans(z=di)).joint(prismatic=True)
        else:
            b.fixed(rot_x(al) @ trans(x=ai)).joint().fixed(trans(z=di))
    return b.finish(tool)


def poe_chain(axes, points, home: np.ndarray, *, prismatic=None) -> np.ndarray:
    """Space-frame product of exponentials: ``T = exp([xi_1] q_1) ... exp([xi_n] q_n) M``.

    Revolute screw ``i`` turns about the unit axis ``axes[i]`` through ``points[i]`` (metres):
    ``exp([xi] q) = Tr(r) Rot(axis, q) Tr(-r)``. A prismatic screw (``prismatic[i]``) translates
    by ``q`` metres along ``axes[i]`` (its point plays no part). ``home`` is ``M``, the tool pose at q = 0.
    """
    flags = _flags(prismatic, len(axes))
    b = NormalFormBuilder()
    for w, r, pr in zip(axes, points, flags, strict=True):
        if pr:
            b.joint(w, prismatic=True)
        else:
            b.fixed(trans(*r)).joint(w).fixed(trans(*(-np.asarray(r, dtype=float))))
    return b.finish(home)


# ---------------------------------------------------------------------------
# the compiled path of Robot.fk, and joint vectors given as numpy arrays
# ---------------------------------------------------------------------------
#: :meth:`Robot.fk` runs the compiled kernel for at most this many CPU configurations (float32/float64, no
#: gradient wanted): measured one thread, panda and ur5, the kernel is 20x faster for one configuration, 3x for
#: 512 and 1.0-1.2x at 2,048.
FK_COMPILED_MAX = 512

_chain_module = None
#: FK of one configuration, compiled entry points without numba's dispatch (see :func:`_fk_one_kernels`): of a
#: tensor's address (:func:`nik.kernels.chain.fk_one_at`) and of a numpy array (:func:`nik.kernels.chain.fk`);
#: None until the first call, False when the kernels are unavailable.
_fk_one = _fk_one_np = None
_Tensor, _F64, _F32 = torch.Tensor, torch.float64, torch.float32
_grad_enabled, _from_numpy, _empty, _ndarray, _NP_F64 = (
    torch.is_grad_enabled,
    torch.from_numpy,
    np.empty,
    np.ndarray,
    np.dtype(np.float64),
)


def _chain_kernels():
    """:mod:`nik.kernels.chain`, imported on first use (it imports numba); None when numba cannot be imported."""
    global _chain_module
    if _chain_module is None:
        try:
            from nik.kernels import chain

            _chain_module = chain
        except ImportError as err:  # pragma: no cover - numba is a dependency
            warnings.warn(f"compiled kernels unavailable ({err}); using the torch path", RuntimeWarning, stacklevel=3)
            _chain_module = False
    return _chain_module or None


def _fk_one_kernels(G: np.ndarray, joints: np.ndarray) -> None:
    """Set ``_fk_one`` and ``_fk_one_np`` on first use: the entry points of ``fk_one_at`` for (``G``, ``joints``, an
    address, a (4, 4) float64 array) and of ``fk`` for (``G``, ``joints``, a (dof,) float64 array, a (4, 4) float64
    array); False without the kernels. Left unset (None) while kernels compile in the background
    (:data:`nik.kernels.background.BUSY`): the torch path answers meanwhile."""
    global _fk_one, _fk_one_np
    if _background.BUSY:  # kernels compile in the background: not now (numba compiles under one lock)
        return
    chain = _chain_kernels()
    if chain is None:
        _fk_one = _fk_one_np = False
        return
    from nik.kernels._jit import entry_point

    T = _empty((4, 4))
    _fk_one = entry_point(chain.fk_one_at, G, joints, 0, T)
    _fk_one_np = entry_point(chain.fk, G, joints, _empty(len(joints)), T)


def _joint_array(q) -> np.ndarray:
    """A joint vector that is not a tensor (numpy array, list, tuple) as a numpy array: float32 and float64 kept,
    anything else (integers, bools, nested lists) as float64."""
    a = np.asarray(q)
    if a.dtype != np.float64 and a.dtype != np.float32:
        try:
            a = a.astype(np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"q: expected joint values (radians), got an array of {a.dtype}") from None
    return a


def _tensor_of(a: np.ndarray) -> torch.Tensor:
    """``a`` as a CPU tensor sharing its memory where torch allows (a copy when it is read-only or strided
    backwards)."""
    a = np.ascontiguousarray(a)
    return _from_numpy(a if a.flags.writeable else a.copy())


# ---------------------------------------------------------------------------
# Robot
# ---------------------------------------------------------------------------
class Robot:
    """A serial arm of revolute and prismatic joints: names, joint limits and a batched, differentiable FK.

    Built by :func:`nik.load_robot` (or :meth:`from_definition`); all quantities SI: a revolute
    joint's value is in radians, a prismatic joint's in metres.

    Attributes:
        name: robot name.
        dof: number of joints.
        joint_names: one name per joint.
        limits: (dof, 2) float64 tensor (lower, upper) of the joint variable ``q``: radians, or metres
            for prismatic joints.
        prismatic: (dof,) bool tensor, True for prismatic joints (all False for a revolute arm).
        end_link: tool link name for URDF arms, else None (with a ``tool`` frame, FK is at that link times it).
        base, tool: (4, 4) float64 base and tool (TCP) frames already folded into ``G`` (``T = base @ ... @ tool``),
            or None; see :mod:`nik.robots.frames`.
        vel_limits, acc_limits: (dof,) float64 tensors, the largest joint speed (rad/s; m/s for prismatic
            joints) and acceleration (rad/s^2; m/s^2), or None where unknown; assignable, checked by
            :func:`nik.robots.rates.check_rates`. Not part of the kinematics: neither :meth:`to_definition` nor
            :attr:`definition_hash` holds them.
        G: (dof + 1, 4, 4) float64 normal-form transforms (see :mod:`nik.kinematics`).
        offsets: (dof,) float64, ``theta = q + offset`` (revolute) or ``d = q + offset`` (prismatic).
    """

    def __init__(
        self,
        name: str,
        G: np.ndarray | torch.Tensor,
        offsets: Sequence[float] | torch.Tensor,
        limits: np.ndarray | torch.Tensor,
        joint_names: Sequence[str] | None = None,
        *,
        end_link: str | None = None,
        source: str | None = None,
        prismatic: Sequence[bool] | torch.Tensor | None = None,
        vel_limits=None,
        acc_limits=None,
    ):
        self.G = torch.as_tensor(np.asarray(G, dtype=float), dtype=torch.float64)
        n = self.G.shape[0] - 1
        self.offsets = torch.as_tensor(np.asarray(offsets, dtype=float), dtype=torch.float64).reshape(n)
        self.limits = torch.as_tensor(np.asarray(limits, dtype=float), dtype=torch.float64).reshape(n, 2)
        if not bool((self.limits[:, 0] < self.limits[:, 1]).all()):
            raise ValueError(f"robot {name!r}: every joint needs lower limit < upper limit, got {self.limits.tolist()}")
        self.name = name
        self.dof = n
        self.joint_names = list(joint_names) if joint_names is not None else [f"joint{i + 1}" for i in range(n)]
        if len(self.joint_names) != n:
            raise ValueError(f"robot {name!r}: {len(self.joint_names)} joint names for {n} joints")
        self.prismatic = torch.zeros(n, dtype=torch.bool)
        if prismatic is not None:
            flags = torch.as_tensor(np.asarray(prismatic, dtype=bool)).reshape(-1)
            if flags.numel() != n:
                raise ValueError(f"robot {name!r}: {flags.numel()} prismatic flags for {n} joints")
            self.prismatic = flags
        self.end_link = end_link
        self.source = source
        self.vel_limits = vel_limits
        self.acc_limits = acc_limits
        #: base and tool frames folded into ``G`` by :func:`nik.robots.frames.with_frames` ((4, 4) float64,
        #: metres), recorded for reports; None when the definition has none of its own.
        self.base: torch.Tensor | None = None
        self.tool: torch.Tensor | None = None
        #: the vendor's flange a robot file names (``flange:``, e.g. the built-in ur5's ``tool0``): its link name
        #: and its (4, 4) pose in ``end_link``'s frame, the first factor of :attr:`tool`; None otherwise.
        self.flange_link: str | None = None
        self.flange: torch.Tensor | None = None
        self._cache: dict[tuple[torch.dtype, torch.device], tuple[torch.Tensor, torch.Tensor]] = {}
        self._kernel: FKKernel | None = None
        self._arrays: tuple[np.ndarray, np.ndarray] | None = None
        self._arm: Robot | None = None  # the arm without base/tool frames (set by nik.robots.frames.with_frames)
        self._one_shape, self._one_tuple = torch.Size([n]), (n,)  # the shape of one configuration (fk's fast paths)

    # -- rate limits (not kinematics: outside the definition and its hash) --
    @property
    def vel_limits(self) -> torch.Tensor | None:
        """(dof,) float64 largest joint speeds, rad/s (m/s for prismatic joints), or None where unknown."""
        return self._vel_limits

    @vel_limits.setter
    def vel_limits(self, values) -> None:
        self._vel_limits = check_rates(values, self.dof, what="vel_limits", names=self.joint_names, where=self.name)

    @property
    def acc_limits(self) -> torch.Tensor | None:
        """(dof,) float64 largest joint accelerations, rad/s^2 (m/s^2 for prismatic joints), or None."""
        return self._acc_limits

    @acc_limits.setter
    def acc_limits(self, values) -> None:
        self._acc_limits = check_rates(values, self.dof, what="acc_limits", names=self.joint_names, where=self.name)

    # -- identity -------------------------------------------------------
    @property
    def has_prismatic(self) -> bool:
        """True when some joint is prismatic."""
        return bool(self.prismatic.any())

    def to_definition(self) -> dict:
        """A plain-data (JSON-able) description that :meth:`from_definition` rebuilds exactly.

        ``"prismatic"`` (one bool per joint) appears only when some joint is prismatic, so the
        definitions of revolute arms are what they were before prismatic joints existed; ``"base"`` and
        ``"tool"`` (4x4 lists, metres) only where such a frame was given (already part of ``"G"``).
        """
        definition = {
            "name": self.name,
            "joint_names": list(self.joint_names),
            "end_link": self.end_link,
            "G": self.G.tolist(),
            "offsets": self.offsets.tolist(),
            "limits": self.limits.tolist(),
        }
        if self.has_prismatic:
            definition["prismatic"] = self.prismatic.tolist()
        for key in ("base", "tool"):  # already folded into G; recorded only where a frame was given
            frame = getattr(self, key)
            if frame is not None:
                definition[key] = frame.tolist()
        return definition

    @classmethod
    def from_definition(cls, definition: dict) -> Robot:
        """Rebuild a robot from :meth:`to_definition` output (for checkpoints and datasets)."""
        try:
            robot = cls(
                definition["name"],
                definition["G"],
                definition["offsets"],
                definition["limits"],
                definition["joint_names"],
                end_link=definition.get("end_link"),
                prismatic=definition.get("prismatic"),
            )
            for key in ("base", "tool"):  # a record only: G holds them already
                if definition.get(key) is not None:
                    setattr(robot, key, torch.tensor(definition[key], dtype=torch.float64).reshape(4, 4))
            return robot
        except (KeyError, TypeError, RuntimeError) as err:
            raise ValueError(f"malformed robot definition: {err}") from err

    @property
    def definition_hash(self) -> str:
        """SHA-256 (hex, 16 chars) of the kinematics and limits; the name is not part of it.

        The joint types enter only when some joint is prismatic, so every revolute arm keeps the
        hash it had before prismatic joints existed (datasets and checkpoints carry it). Base and tool
        frames are part of ``G``, so a frame other than the identity changes the hash and none (or an
        identity) keeps it.
        """
        h = hashlib.sha256()
        for arr in (self.G, self.offsets, self.limits):
            h.update(np.round(arr.numpy(), 12).astype("<f8").tobytes())
        if self.has_prismatic:
            h.update(b"prismatic:" + self.prismatic.numpy().astype("u1").tobytes())
        return h.hexdigest()[:16]

    @property
    def arm(self) -> Robot:
        """This robot without its base and tool frames (itself when it has none): the bare arm, in whose frame a
        network trained for the arm guesses (``base^-1 @ T @ tool^-1``)."""
        if self.base is None and self.tool is None:
            return self
        if self._arm is None:  # rebuilt from a definition: undo the recorded frames
            G = self.G.numpy().copy()
            if self.base is not None:
                G[0] = np.linalg.inv(self.base.numpy()) @ G[0]
            if self.tool is not None:
                G[-1] = G[-1] @ np.linalg.inv(self.tool.numpy())
            snapped = np.round(G, 12) + 0.0  # undo the inversion's rounding (and -0.0) where it is only that
            G = np.where(np.abs(G - snapped) < 1e-14, snapped, G)
            self._arm = Robot(
                self.name, G, self.offsets, self.limits, self.joint_names, end_link=self.end_link,
                source=self.source, prismatic=self.prismatic,
            )  # fmt: skip
        return self._arm

    @property
    def arm_hash(self) -> str:
        """The :attr:`definition_hash` of :attr:`arm` (the frames left out): networks are matched by it, so a base
        or tool frame keeps the arm's network."""
        return self.arm.definition_hash

    def __repr__(self) -> str:
        return f"Robot(name={self.name!r}, dof={self.dof}, hash={self.definition_hash})"

    # -- kinematics -----------------------------------------------------
    def _params(self, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        key = (like.dtype, like.device)
        if key not in self._cache:
            self._cache[key] = (self.G.to(like.device, like.dtype), self.offsets.to(like.device, like.dtype))
        return self._cache[key]

    def fk(
        self, q: torch.Tensor | np.ndarray, *, compiled: bool = False, check: bool = True
    ) -> torch.Tensor | np.ndarray:
        """Forward kinematics.

        Args:
            q: (..., dof) joint values (radians; metres for prismatic joints); any leading batch shape,
                any float dtype/device; or a numpy array (or a list) of them.
            compiled: run the ``torch.compile``'d kernel (fast for large batches; the first call compiles).
            check: validate ``q`` (shape, NaN/inf); hot loops that built ``q`` themselves pass False.

        Returns:
            (..., 4, 4) tool poses in the base frame, metres, in q's dtype and device; differentiable with
            respect to ``q``. A numpy ``q`` gives a numpy array (float32 kept, float64 for any other dtype).

        Up to :data:`FK_COMPILED_MAX` configurations on the CPU in float32/float64, when no gradient is
        wanted, run through the compiled kernel of :mod:`nik.kernels.chain` (microseconds instead of the
        fraction of a millisecond torch's per-op overhead costs; float64 inside, cast to q's dtype); one
        contiguous float64 configuration ``(dof,)`` through that kernel's entry point (no numba dispatch: a
        microsecond, ``benchmarks/fk.py --pinocchio-only``).
        """
        if not isinstance(q, _Tensor):
            if type(q) is _ndarray and q.dtype is _NP_F64 and q.shape == self._one_tuple and not compiled:
                flags = q.flags  # the exact array type of the entry point: (dof,) float64, C order, aligned, writeable
                if flags.c_contiguous and flags.aligned and flags.writeable:
                    G, joints = self._arrays or self.chain_arrays()
                    if _fk_one_np is None:
                        _fk_one_kernels(G, joints)
                    if _fk_one_np:
                        T = _empty((4, 4))
                        if not _fk_one_np(G, joints, q, T) and check:
                            validate_joints(_tensor_of(q), self.dof)  # raises the usual message
                        return T
            return self._fk_numpy(q, compiled, check)
        # a CPU tensor and no gradient wanted, by the cheapest checks torch offers (under 0.1 us each;
        # q.device.type alone costs 0.5 us)
        if not compiled and q.is_cpu and not (q.requires_grad and _grad_enabled()):
            if q.dtype is _F64 and q.shape == self._one_shape and q.is_contiguous():
                G, joints = self._arrays or self.chain_arrays()
                if _fk_one is None:
                    _fk_one_kernels(G, joints)
                if _fk_one:
                    T = _empty((4, 4))
                    if not _fk_one(G, joints, q.data_ptr(), T) and check:
                        validate_joints(q, self.dof)  # raises the usual message
                    return _from_numpy(T)
            T = self._fk_compiled(q, check)
            if T is not None:
                return T
        if check:
            validate_joints(q, self.dof)
        if self._kernel is None:
            self._kernel = FKKernel(self.G.numpy(), self.offsets.numpy(), prismatic=self.prismatic.tolist())
        return self._kernel(q.reshape(-1, self.dof), compiled=compiled).reshape(*q.shape[:-1], 4, 4)

    def _fk_numpy(self, q, compiled: bool, check: bool) -> np.ndarray:
        """:meth:`fk` of a joint vector that is not a tensor: the compiled kernel straight from the array where
        :meth:`fk` would run it, else the torch path; a numpy array back."""
        a = _joint_array(q)
        shape, dof = a.shape, self.dof
        B = a.size // dof if shape and shape[-1] == dof else 0
        chain = (
            None if compiled or not 0 < B <= FK_COMPILED_MAX or _background.BUSY else _chain_module or _chain_kernels()
        )
        if chain is None:
            return self.fk(_tensor_of(a), compiled=compiled, check=check).numpy()
        G, joints = self._arrays or self.chain_arrays()
        q64 = np.ascontiguousarray(a, dtype=np.float64)
        if not q64.flags.writeable:  # a read-only array is another numba type: one compiled signature serves
            q64 = q64.copy()
        if len(shape) == 1:
            T = _empty((4, 4))
            finite = chain.fk(G, joints, q64, T)
        else:
            T = _empty((B, 4, 4))
            finite = chain.fk_batch(G, joints, q64.reshape(B, dof), T)
            T = T.reshape(*shape[:-1], 4, 4)
        if check and not finite:
            validate_joints(_tensor_of(a), dof)  # raises the usual message
        return T if a.dtype == np.float64 else T.astype(a.dtype)

    def chain_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The model arrays of the compiled kernels (:func:`nik.kernels.chain.chain_model`): ``G: (dof + 1, 4, 4)``
        and ``joints: (dof, 5)`` float64 (offset, limits, prismatic, wraps), built once."""
        if self._arrays is None:
            from nik.kernels.chain import chain_model

            self._arrays = chain_model(
                self.G.numpy(), self.offsets.numpy(), self.limits.numpy(), self.prismatic.numpy()
            )
        return self._arrays

    def _fk_compiled(self, q: torch.Tensor, check: bool) -> torch.Tensor | None:
        """FK of a few float32/float64 CPU configurations ``(..., dof)`` through the compiled kernel; None when
        ``q`` is not that (or the kernels are unavailable): the torch path then answers or raises.

        A contiguous float64 ``q`` is read in place (:func:`nik.kernels.chain.fk_at`: its address, not
        ``q.numpy()``, 0.7 us), and the result is the one tensor made per call (``torch.from_numpy``, 0.5 us;
        ``torch.empty`` costs 1.5 us): measured on panda, ``benchmarks/fk.py --pinocchio-only``."""
        shape = q.shape
        dof = self.dof
        if not shape or shape[-1] != dof:
            return None
        B = q.numel() // dof
        if not 0 < B <= FK_COMPILED_MAX or _background.BUSY:  # BUSY: the torch path while kernels compile
            return None
        chain = _chain_module or _chain_kernels()
        if chain is None:
            return None
        G, joints = self._arrays or self.chain_arrays()
        dtype = q.dtype
        out = np.empty((B, 4, 4))
        if dtype is _F64 and q.is_contiguous():
            finite = chain.fk_at(G, joints, q.data_ptr(), out)
        elif dtype is _F64 or dtype is _F32:
            finite = chain.fk_batch(G, joints, q.detach().numpy().reshape(B, dof).astype(np.float64), out)
        else:
            return None
        if check and not finite:
            validate_joints(q, dof)  # raises the usual message
        T = _from_numpy(out[0] if len(shape) == 1 else out.reshape(*shape[:-1], 4, 4))
        return T if dtype is _F64 else T.to(dtype)

    def fk_and_jacobian(
        self, q: torch.Tensor | np.ndarray
    ) -> tuple[torch.Tensor, torch.Tensor] | tuple[np.ndarray, np.ndarray]:
        """FK and geometric Jacobian in the base frame.

        Args:
            q: (..., dof) radians (metres for prismatic joints); a tensor, or a numpy array (or a list).

        Returns:
            ``T: (..., 4, 4)`` and ``J: (..., 6, dof)`` (rows: linear then angular velocity; a prismatic
            joint's column is its unit axis, then zeros); numpy arrays for a numpy ``q`` (as :meth:`fk`).
        """
        if not isinstance(q, _Tensor):
            T, J = self.fk_and_jacobian(_tensor_of(_joint_array(q)))
            return T.numpy(), J.numpy()
        validate_joints(q, self.dof)
        G, off = self._params(q)
        batch = q.shape[:-1]
        T, J = chain_jacobian(q.reshape(-1, self.dof), G, off, prismatic=self.prismatic_or_none)
        return to_homogeneous(T).reshape(*batch, 4, 4), J.reshape(*batch, 6, self.dof)

    def jacobian(self, q: torch.Tensor) -> torch.Tensor:
        """The geometric Jacobian of the tool (flange and tool frame) in the base frame.

        Args:
            q: ``(..., dof)`` radians (metres for prismatic joints); any leading batch shape, any float
                dtype/device (a numpy array or a list: float64).

        Returns:
            ``(..., 6, dof)`` in ``q``'s dtype and device, rows linear velocity (m/s per unit of joint speed) then
            angular velocity (rad/s): a revolute joint's column ``[z_i x (p - p_i); z_i]``, a prismatic one's
            ``[z_i; 0]``. Differentiable with respect to ``q`` (the torch closed form of
            :func:`nik.kinematics.chain_jacobian`, the one :meth:`fk_and_jacobian` and the LM use).
        """
        if not isinstance(q, _Tensor):
            q = _tensor_of(_joint_array(q))
        return self.fk_and_jacobian(q)[1]

    @property
    def prismatic_or_none(self) -> torch.Tensor | None:
        """:attr:`prismatic`, or None for an all-revolute arm (the kernels' fast path)."""
        return self.prismatic if self.has_prismatic else None

    # -- joint space ----------------------------------------------------
    def sample(
        self,
        n: int,
        *,
        generator: torch.Generator | None = None,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
        ranges: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``(n, dof)`` joint vectors uniform within the limits (or within ``ranges: (dof, 2)``).

        Drawn in float64 on the generator's device and then cast, so the same generator seed
        gives the same joints in every dtype (up to rounding) and on every device.
        """
        if int(n) < 0:
            raise ValueError(f"sample: n must be >= 0, got {n}")
        lim = self.limits if ranges is None else torch.as_tensor(ranges, dtype=torch.float64).reshape(self.dof, 2)
        gen_device = generator.device if generator is not None else torch.device("cpu")
        u = torch.rand(int(n), self.dof, generator=generator, dtype=torch.float64, device=gen_device)
        lim = lim.to(gen_device)
        q = lim[:, 0] + u * (lim[:, 1] - lim[:, 0])
        dtype = dtype or torch.get_default_dtype()
        q = q.to(device=device or gen_device, dtype=dtype)
        lo, hi = self.limits_as(q)
        return torch.minimum(torch.maximum(q, lo), hi)

    def limits_as(self, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Lower and upper limits ``(dof,)`` each, in the dtype/device of ``like``, rounded inward."""
        lim = self.limits.to(like.device)
        lo, hi = lim[:, 0].to(like.dtype), lim[:, 1].to(like.dtype)
        # a float32 cast may round a limit outward; nudge it back inside
        lo = torch.where(lo.double() < lim[:, 0], torch.nextafter(lo, hi), lo)
        hi = torch.where(hi.double() > lim[:, 1], torch.nextafter(hi, lo), hi)
        return lo, hi

    def within_limits(self, q: torch.Tensor | np.ndarray, *, atol: float = 0.0) -> torch.Tensor | np.ndarray:
        """``(...,)`` bool: every joint of ``q: (..., dof)`` inside ``[lower - atol, upper + atol]`` (a numpy bool
        array for a numpy ``q``)."""
        if not isinstance(q, _Tensor):
            return self.within_limits(_tensor_of(_joint_array(q)), atol=atol).numpy()
        lo, hi = self.limits_as(q)
        return ((q >= lo - atol) & (q <= hi + atol)).all(dim=-1)

    def clamp(self, q: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
        """``q: (..., dof)`` clamped into the joint limits (a numpy array for a numpy ``q``, float32 kept, float64
        for any other dtype)."""
        if not isinstance(q, _Tensor):
            return self.clamp(_tensor_of(_joint_array(q))).numpy()
        lo, hi = self.limits_as(q)
        return torch.minimum(torch.maximum(q, lo), hi)
