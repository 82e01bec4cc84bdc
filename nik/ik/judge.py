"""Whether a network earns its place as the guess: its first residuals against the uniform starts LM would take.

A network's hypotheses are worth refining only where they start LM nearer the target than the solver would start
without them. Without a network the refiner starts each target from the best of ``LMCfg.first_starts`` (16) uniform
configurations and restarts it where it fails; with one, LM starts from the network's best hypothesis *without*
restarts, then from each of its other hypotheses in turn, and only then falls back to uniform restarts. A useless
network (untrained, its outputs scrambled, its weights randomised) therefore costs its forward pass, one LM run per
hypothesis and the fallback: 1.2-2.2x the time of the same solver without it here, up to 5x as the issue measured
it (``python benchmarks/bad_network.py``).

:func:`verdict` judges a network once per robot, before its first call: on :data:`PROBES` seeded probe poses (FK of
uniform configurations inside the limits; seed :data:`PROBE_SEED`, the same for every network) its best
hypothesis by FK (metres + 0.1 x radians, each hypothesis brought inside the limits) is compared with the best of
``M`` uniform configurations: :data:`UNIFORM_STARTS` (16, the starts LM takes its first from), or twice the network's
``K`` hypotheses where that is more, so that a network guessing at random wins a third of the probes whatever its
``K`` (``K / (K + M)``). The network *earns* its place when its best hypothesis is the better start on at least
:data:`MIN_WINS` (60 %) of the probes: the shipped networks 98-100 %; untrained, scrambled or randomised ones of the
shipped architecture 28-45 %, networks trained for a few steps about 40 % (``python benchmarks/bad_network.py``
prints each verdict). Cost: one forward pass of 64 poses and about 1,600 FK evaluations on the compiled kernels,
about 15 ms, once per network and robot.

:func:`earns` is what :func:`nik.ik.plan.choose_network` asks: a given (or installed) network that does not earn its
place is set aside for the plans that refine and have a fallback (the solver then guesses as it would without a
network: the closed form, or uniform starts), with one ``UserWarning`` per network naming the figures. Choices
where the issue is silent:

- the verdict is a property of the network and the robot, not of a call: the same call gives the same answer
  whatever came before (the probes are fixed and seeded); it is kept per network object and its weights' version
  counters: a network trained in place is judged again by the next solver that resolves a plan for it (a solver
  keeps its plans, and with them the verdict, for its life);
- plans that ask for the network's own guess are never changed: ``refine="none"`` (the raw guess) and
  ``fallback="none"`` (what the network delivers alone, as the evaluation measures it); a plan built by hand
  (``solver.solve(T, plan=replace(plan, source="network", net=net))``) runs as written;
- the networks shipped with nik are not judged on wins (they are measured: docs/learned.md); on the CPU they are
  timed as any network (below), from the record their files carry.

**Per call type, by time** (:func:`use`). On the compiled backend (the CPU), a network that earns its place may
still cost more than it saves: its forward pass for one pose (a 4 x 256 network: tens of microseconds in the kernels)
can exceed the LM iterations it saves there, while a batch's forward pass (torch's float32 matmuls) costs a fraction
of that per pose. So whether it serves is decided for each call type on its own, by time on seeded probes:

- ``pose``: a call of one pose (the one-pose path, :mod:`nik.ik.backends.one_pose`, or the general path with one
  target): :data:`POSE_PROBES` (32) poses solved one call each, with the network and without it, interleaved call
  by call, :data:`TIME_ROUNDS` (3) rounds; each pose's least time is kept and the two are compared by the median
  over the poses (the typical call: a tail the network shortens does not buy a slower median call);
- ``batch``: a call of more poses: one batch of :data:`BATCH_PROBES` (512) poses, with and without, 3 interleaved
  rounds, the least time of each (above :data:`nik.ik.backends.compiled.PACKED_MAX_BATCH`, so the forward pass runs
  as a large batch's does; a call of a few poses follows this decision too).

Without the network means LM from uniform starts: the solver's guess without a network where the arm has no closed
form; on an arm with a closed form a network is there because it was asked for in place of the closed form (which
stays its fallback), so it is judged against uniform starts too. Times are the CPU time of the calling thread
(:func:`time.thread_time`): on a busy machine wall time counts whatever else ran meanwhile; the calling thread's time
is the call's wall time on an idle machine, a batch forward pass spread over several torch threads included, and it
counts the wait for torch's other threads where they are held up.

The network serves a call type where it earns its place (wins, above) and its time there is at most the time without
it (``pose_us``, ``batch_us``: microseconds per pose, with and without). Cost of a measurement: 0.12-0.18 s of CPU
(panda's and ur5's shipped networks, a 2-minute ``nik train`` network of a 6-joint arm; the wall time on an idle
machine, 1.2-1.4 s on this shared one under load 10), the wins verdict included, once per network, robot and
weights in a process (more for a slow network); none where the network's file records the decision: ``nik train``
measures it once after training and writes it in the pair's JSON (``network_use``, :func:`record`; the shipped pairs
carry one too), and a network loaded from such a file (:func:`nik.nets.pair.load_pair`) uses the record, wins
included, while its weights are unchanged. A network without a record (a Lightning checkpoint of ``train.py``, a
network set by hand) is measured on the first call that needs it and the decision kept per network object (every
solver of the process shares it). While the kernels are not compiled yet (their first compile runs in the
background, :mod:`nik.kernels.background`) the decision is the wins verdict alone, not kept, and timed on a later
call. The torch backend (GPU targets, swarms) keeps the wins verdict alone: the probes time the CPU's kernels.
"""

from __future__ import annotations

import math
import time
import warnings
import weakref
from dataclasses import dataclass

import torch

__all__ = [
    "BATCH_PROBES",
    "MIN_WINS",
    "POSE_PROBES",
    "PROBES",
    "PROBE_SEED",
    "TIME_ROUNDS",
    "UNIFORM_STARTS",
    "Use",
    "Verdict",
    "counts",
    "earns",
    "measure",
    "record",
    "use",
    "verdict",
]

#: Probe poses per judgement, their seed, the fewest uniform starts a probe's network guess is compared with
#: (``LMCfg.first_starts``; twice the network's hypotheses where more), and the share of probes it must win.
PROBES, PROBE_SEED, UNIFORM_STARTS, MIN_WINS = 64, 20_37, 16, 0.6
#: Timed probes (module docstring, "Per call type"): poses solved one call each, the batch, the rounds.
POSE_PROBES, BATCH_PROBES, TIME_ROUNDS = 32, 512, 3

_VERDICTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_USES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_WARNED: weakref.WeakSet = weakref.WeakSet()
_COUNTS = {"judged": 0, "dropped": 0, "timed": 0}


@dataclass(frozen=True)
class Verdict:
    """A network judged on one robot's probe poses.

    Attributes:
        earns: its best hypothesis is the better start on at least :data:`MIN_WINS` of the probes.
        wins: the share of probes where it is.
        net_median, uniform_median: the median error (metres + 0.1 x radians) of its best hypothesis and of the best
            of :data:`UNIFORM_STARTS` uniform configurations.
        probes: how many probe poses.
    """

    earns: bool
    wins: float
    net_median: float
    uniform_median: float
    probes: int


def counts() -> dict:
    """``{"judged": n, "dropped": m, "timed": t}``: networks judged and set aside in this process (a judgement is not
    repeated for the same network, robot and weights), and timings on the probes (:func:`measure`)."""
    return dict(_COUNTS)


def _per_net(store, net) -> dict:
    """``net``'s entry of the weak-keyed cache ``store``; a fresh dict where ``net`` cannot be weakly referenced (it is
    then judged on every call)."""
    try:
        return store.setdefault(net, {})
    except TypeError:
        return {}


def _weights_version(net) -> tuple:
    params = net.parameters() if isinstance(net, torch.nn.Module) else ()
    return tuple(p._version for p in params)


def _hypotheses(net, T: torch.Tensor) -> torch.Tensor:
    """``(P, K, dof)`` float64 on the CPU: the hypotheses of ``net`` for ``T: (P, 4, 4)`` (one: a plain network)."""
    ref = getattr(net, "in_mean", None)
    if ref is None:
        ref = next(iter(net.parameters()), torch.empty(0, dtype=torch.float32))
    Tn = T.to(device=ref.device, dtype=ref.dtype)
    with torch.no_grad():
        hyp = net.hypotheses(Tn) if hasattr(net, "hypotheses") else net.predict(Tn)[:, None]
    return hyp.detach().to("cpu", torch.float64)


def verdict(net, robot) -> Verdict:
    """The :class:`Verdict` on ``net`` for ``robot`` (the robot whose FK ranks its hypotheses and whose frame its
    input poses are in: the bare arm :attr:`nik.Robot.arm` for a network made for it), judged once per network,
    robot definition and weights (module docstring). FK and the ranking run on the compiled kernels
    (:func:`nik.kernels.chain.fk_batch`, :func:`nik.kernels.seeded.rank`), wherever the network lives."""
    import numpy as np

    from nik.ik.model import model_of
    from nik.kernels.chain import fk_batch
    from nik.kernels.seeded import rank
    from nik.tolerances import SCORE_ROT_WEIGHT

    key = (robot.definition_hash, _weights_version(net))
    per_net = _per_net(_VERDICTS, net)
    found = per_net.get(key)
    if found is not None:
        return found
    model = model_of(robot)
    g = torch.Generator().manual_seed(PROBE_SEED)
    T = np.empty((PROBES, 4, 4))
    fk_batch(model.G, model.joints, robot.sample(PROBES, generator=g, dtype=torch.float64).numpy(), T)
    hyp = _hypotheses(net, torch.from_numpy(T)).numpy()
    m = max(UNIFORM_STARTS, 2 * hyp.shape[1])  # twice its hypotheses: a network guessing at random wins 1/3
    uni = robot.sample(PROBES * m, generator=g, dtype=torch.float64).numpy().reshape(PROBES, m, -1)

    def best(starts: np.ndarray) -> np.ndarray:  # (P, K, n) -> (P,): the best start's error, each inside the limits
        pos, rot = np.empty(PROBES), np.empty(PROBES)
        rank(model.G, model.joints, T, np.ascontiguousarray(starts), pos, rot)
        return np.nan_to_num(pos + SCORE_ROT_WEIGHT * rot, nan=np.inf)

    s_uni, s_net = best(uni), best(hyp)
    wins = float(np.mean(s_net < s_uni))
    found = Verdict(wins >= MIN_WINS, wins, float(np.median(s_net)), float(np.median(s_uni)), PROBES)
    if len(per_net) > 8:
        per_net.clear()
    per_net[key] = found
    _COUNTS["judged"] += 1
    return found


def earns(net, robot, arm_frame: bool = False) -> bool:
    """Whether ``net`` earns its place as ``robot``'s guess (:func:`verdict`; ``arm_frame``: it was made for the bare
    arm, :func:`nik.ik.plan.in_arm_frame`). Warns once per network where it does not. A network whose file records
    the verdict (:func:`record`) is not judged again: the record's share of wins decides."""
    judged = robot.arm if arm_frame else robot
    rec = _recorded(net, judged, _weights_version(net), "multistart")
    if rec is not None:
        v = Verdict(rec.wins >= MIN_WINS, rec.wins, math.nan, math.nan, PROBES)
    else:
        v = verdict(net, judged)
    if not v.earns:
        _COUNTS["dropped"] += 1
        try:
            seen = net in _WARNED
            _WARNED.add(net)
        except TypeError:
            seen = False
        if not seen:
            median = "" if math.isnan(v.net_median) else (
                f"; median error {v.net_median:.3f} against {v.uniform_median:.3f}, m + 0.1 rad"
            )  # fmt: skip
            warnings.warn(
                f"the network given for {robot.name} guesses no better than uniform starts (its best hypothesis is "
                f"the better start on {v.wins:.0%} of {v.probes} probe poses{median}): solving without it "
                "(nik.ik.judge)",
                UserWarning,
                stacklevel=5,  # the caller of IKSolver.solve (or .initial_source)
            )
    return v.earns


_NAN2 = (math.nan, math.nan)


@dataclass(frozen=True)
class Use:
    """Whether a network serves each call type on the CPU (module docstring, "Per call type").

    Attributes:
        pose, batch: it serves calls of one pose / of more poses.
        wins: the share of the wins probes where its best hypothesis is the better start (:class:`Verdict`).
        pose_us: ``(with, without)`` microseconds of one call of one pose, the median over :data:`POSE_PROBES`
            poses (NaN: not timed, e.g. it lost on wins).
        batch_us: ``(with, without)`` microseconds per pose in a batch of :data:`BATCH_PROBES`.
        baseline: what guesses without it: ``multistart`` (uniform starts) or ``analytic`` (the closed form).
        how: ``record`` (read from the network's file), ``measured`` (timed in this process), ``wins`` (lost on
            wins: not timed), ``provisional`` (the kernels still compiling: wins only, timed later), ``asked``
            (set by hand: :attr:`nik.IKSolver.network_use`).
    """

    pose: bool
    batch: bool
    wins: float = math.nan
    pose_us: tuple = _NAN2
    batch_us: tuple = _NAN2
    baseline: str = "multistart"
    how: str = "measured"

    def serves(self, call: str) -> bool:
        """Whether it serves ``call`` (``"pose"`` or ``"batch"``)."""
        return self.pose if call == "pose" else self.batch

    def as_dict(self) -> dict:
        """Plain data (what :attr:`nik.IKSolver.network_use` returns)."""
        return {
            "pose": self.pose,
            "batch": self.batch,
            "pose_us": tuple(self.pose_us),
            "batch_us": tuple(self.batch_us),
            "wins": self.wins,
            "baseline": self.baseline,
            "how": self.how,
        }


def call_type(n_poses: int | None) -> str:
    """``"pose"`` for a call of one pose, ``"batch"`` for more (None: a batch)."""
    return "pose" if n_poses == 1 else "batch"


def _deferring() -> bool:
    """True while the compiled solve cannot be timed without waiting for its first compile (module docstring)."""
    from nik.kernels import background, driver

    if not background.defer_allowed():  # NIK_COMPILE=wait: compiled on the caller's thread, as every call does
        return False
    return not driver.solve.signatures and background.cold(driver.solve)  # as the one-pose path asks


def _fastest(solvers, call, rounds: int) -> list[float]:
    """The least CPU time (seconds, of this thread: :func:`time.thread_time`) of ``rounds`` runs of ``call(solver)``
    per solver, interleaved (A B, B A, ...)."""
    best = [math.inf] * len(solvers)
    for r in range(rounds):
        order = range(len(solvers)) if r % 2 == 0 else reversed(range(len(solvers)))
        for i in order:
            t0 = time.thread_time()
            call(solvers[i])
            best[i] = min(best[i], time.thread_time() - t0)
    return best


def measure(
    net, robot, solver_type, arm_frame: bool = False, baseline: str = "multistart", *, always: bool = False
) -> Use:
    """Time ``net`` on ``robot``'s probes (module docstring, "Per call type") with solvers of ``solver_type``
    (:class:`nik.IKSolver`, given by the caller: this room lies below it); ``baseline`` is the guess without it
    (``multistart`` or ``analytic``: the closed form). A network that loses on wins serves no call type and is not
    timed unless ``always`` (the figures of a report and of a network's record: then timed even while the kernels
    are not compiled yet, after compiling them on this thread, so that a record is never provisional). Not kept
    (:func:`use` keeps it); 0.12-0.18 s of CPU."""
    import numpy as np

    v = verdict(net, robot.arm if arm_frame else robot)
    if not v.earns and not always:
        return Use(False, False, v.wins, baseline=baseline, how="wins")
    if not always and _deferring():
        return Use(True, True, v.wins, baseline=baseline, how="provisional")
    kw = {"checkpoint": None, "analytic": baseline == "analytic", "backend": "compiled"}
    with_net, without = solver_type(robot, **kw), solver_type(robot, **kw)
    with_net.net = net
    with_net.network_use = {"pose": True, "batch": True}
    g = torch.Generator().manual_seed(PROBE_SEED + 1)
    q = robot.sample(POSE_PROBES + BATCH_PROBES, generator=g, dtype=torch.float64)
    T = np.ascontiguousarray(robot.fk(q).numpy())
    poses, batch = [T[i] for i in range(POSE_PROBES)], T[POSE_PROBES:]
    solvers = (with_net, without)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for s in solvers:  # loads the kernels, packs the network: not timed
            s.solve(poses[0])
        one = np.array([_fastest(solvers, lambda s, p=p: s.solve(p), TIME_ROUNDS) for p in poses])  # (P, 2)
        many = _fastest(solvers, lambda s: s.solve(batch), TIME_ROUNDS)
    _COUNTS["timed"] += 1
    pose_us = tuple(float(x) for x in 1e6 * np.median(one, axis=0))
    batch_us = tuple(1e6 * t / BATCH_PROBES for t in many)
    pays = (v.earns and pose_us[0] <= pose_us[1], v.earns and batch_us[0] <= batch_us[1])
    return Use(*pays, v.wins, pose_us, batch_us, baseline, "measured" if v.earns else "wins")


def record(net, robot, solver_type, baselines=("multistart",)) -> dict:
    """What a network's file records of :func:`measure` (``network_use`` in the pair's JSON): for ``robot`` (the
    arm it was made for) and each of ``baselines``, the decision and the figures (timed even where it loses on wins),
    with the probes' sizes (timed with solvers of ``solver_type``: :func:`measure`)."""
    against = {}
    for b in baselines:
        u = measure(net, robot, solver_type, baseline=b, always=True)
        figures = {k: [None if math.isnan(x) else x for x in getattr(u, k)] for k in ("pose_us", "batch_us")}
        against[b] = {"pose": u.pose, "batch": u.batch, **figures}  # figures null: not timed (lost on wins)
        wins = u.wins
    return {
        "robot_hash": robot.definition_hash,
        "wins": wins,
        "probes": {"pose": POSE_PROBES, "batch": BATCH_PROBES, "rounds": TIME_ROUNDS, "seed": PROBE_SEED + 1},
        "threads": torch.get_num_threads(),
        "against": against,
    }


def _recorded(net, robot, version: tuple, baseline: str) -> Use | None:
    """The decision the network's file records for ``robot`` and ``baseline`` (:func:`nik.nets.pair.load_pair`
    attaches it with its weights' version counters at load), None where there is none or the weights changed."""
    found = getattr(net, "network_use_record", None)
    if not found or found[1] != version:
        return None
    rec = found[0]
    try:
        if rec["robot_hash"] != robot.definition_hash:
            return None
        r = rec["against"][baseline]

        def us(k) -> tuple:
            return tuple(math.nan if x is None else float(x) for x in r[k])

        return Use(bool(r["pose"]), bool(r["batch"]), float(rec["wins"]), us("pose_us"), us("batch_us"), baseline,
                   "record")  # fmt: skip
    except (KeyError, TypeError, ValueError):  # another record's shape: measured instead
        return None


def use(net, robot, solver_type, arm_frame: bool = False, baseline: str = "multistart") -> Use:
    """Whether ``net`` serves each call type of ``robot`` on the CPU (:class:`Use`; module docstring): from the
    network's record, else measured (:func:`measure`, solvers of ``solver_type``) once per network, robot, baseline
    and weights."""
    judged = robot.arm if arm_frame else robot
    version = _weights_version(net)
    key = (robot.definition_hash, version, baseline)
    per_net = _per_net(_USES, net)
    found = per_net.get(key)
    if found is not None:
        return found
    found = _recorded(net, judged, version, baseline) or measure(net, robot, solver_type, arm_frame, baseline)
    if found.how == "provisional":
        return found
    if len(per_net) > 8:
        per_net.clear()
    per_net[key] = found
    return found
