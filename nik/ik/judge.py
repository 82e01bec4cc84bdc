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
- the networks shipped with nik are not judged (they are measured: docs/learned.md).
"""

from __future__ import annotations

import warnings
import weakref
from dataclasses import dataclass

import torch

__all__ = ["MIN_WINS", "PROBES", "PROBE_SEED", "UNIFORM_STARTS", "Verdict", "counts", "earns", "verdict"]

#: Probe poses per judgement, their seed, the fewest uniform starts a probe's network guess is compared with
#: (``LMCfg.first_starts``; twice the network's hypotheses where more), and the share of probes it must win.
PROBES, PROBE_SEED, UNIFORM_STARTS, MIN_WINS = 64, 20_37, 16, 0.6

_VERDICTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_WARNED: weakref.WeakSet = weakref.WeakSet()
_COUNTS = {"judged": 0, "dropped": 0}


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
    """``{"judged": n, "dropped": m}``: networks judged and set aside in this process (a judgement is not
    repeated for the same network, robot and weights)."""
    return dict(_COUNTS)


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
    try:
        per_net = _VERDICTS.setdefault(net, {})
    except TypeError:  # not weak-referenceable: judge each time
        per_net = {}
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
    arm, :func:`nik.ik.plan.in_arm_frame`). Warns once per network where it does not."""
    v = verdict(net, robot.arm if arm_frame else robot)
    if not v.earns:
        _COUNTS["dropped"] += 1
        try:
            seen = net in _WARNED
            _WARNED.add(net)
        except TypeError:
            seen = False
        if not seen:
            warnings.warn(
                f"the network given for {robot.name} guesses no better than uniform starts (its best hypothesis is "
                f"the better start on {v.wins:.0%} of {v.probes} probe poses; median error {v.net_median:.3f} "
                f"against {v.uniform_median:.3f}, m + 0.1 rad): solving without it (nik.ik.judge)",
                UserWarning,
                stacklevel=5,  # the caller of IKSolver.solve (or .initial_source)
            )
    return v.earns
