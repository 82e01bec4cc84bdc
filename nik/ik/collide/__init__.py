"""The collision stage of :class:`nik.IKSolver`: which collision model a call uses, and collision-free answers.

**When collisions are checked** (``IKSolver(robot, world=None, self_collision=None)``, per call ``solve(world=)``):

- a ``world`` (on the solver or per call, even an empty one) turns the check on, **the arm against itself
  included**: ``collision_free`` means free of the world and of the arm (the model is built if needed: fitted to
  the URDF's collision geometry, or capsules along the links; cached, :func:`nik.collision.collision_model`);
  ``self_collision=False`` checks the world only;
- without a world, ``self_collision=None`` (the default) checks the arm against itself where the robot **has a
  collision model attached**: a ``NAME.collision.json`` beside its URDF / YAML file or one set by the user
  (:func:`nik.collision.set_collision_model`); otherwise nothing is checked; ``True``: checked; ``False``: never.

Why not on by default for every arm without a world: a sphere model is conservative (every surface point inside;
it overreaches by 1.5-3.5 cm), so it calls 5-33 % of the panda's free configurations colliding
(docs/collisions.md). Turned on silently, it would make random reachable targets fail that the same call solves
today, and fit a model (seconds) inside a solve. A world or an attached model is a decision the user made.

**What the stage does** (:func:`resolve`, after the main pipeline, both backends): every answer is checked
(:func:`nik.kernels.collision.collides_batch`, margin 0); the ones that collide (within reach) are solved again by
LM with collision rows (:mod:`nik.kernels.collision_lm`): first from the answer alone (it keeps a path or ``q_near``
on its branch, and ends most targets); then, from that pass's answer, the network's other hypotheses or the closed
form's other branches that are free, nearest the pose first (colliding ones dropped before any iteration), then
uniform restarts drawn collision-free. A target left by the first pass whose pose alone proves every answer
colliding (:func:`nik.collision.compiled.blocked_targets`: the hand against the world or the base, the first and the
last joint's links swept over their range) is not solved on (it would fail after the whole restart budget); with the
meshes judging where the spheres do not cover them (below), or a tolerant goal (``bounds``: no pose is fixed), it
is. Where the re-solve ends off the goal, once more from its answer with the rows at margin 0 (:func:`_solve_free`).
Where the meshes judge (below) and a target is still left without a free answer, the meshes steer
(:mod:`nik.ik.collide.mesh_step`, ``CollideCfg.mesh_steer``): the pose term and rows of coal's mesh distances (their
nearest points give the Jacobian) solved by the torch LM (:func:`nik.lm.loop.lm_loop`, each descent ending at its
first answer on the goal and free on the meshes), from the re-solve's answer, the call's own, then the branches or
hypotheses; so a target whose free answers all look colliding to the spheres (they overreach the meshes by
centimetres) is found, at about 5 ms a target on the panda and the xarm7. The torch backend runs the same compiled
kernel on the CPU (the answers go there and back).

**Constraints compose**: every mix of ``bounds=``, ``q_rest=``, a world and self-collision, in
:meth:`~nik.IKSolver.solve` and :meth:`~nik.IKSolver.solve_all`, on both backends:

- the re-solve keeps the call's goal: the collision LM's pose rows are the bounded residual with its dead zones
  (:mod:`nik.kernels.lm`'s, the one the goal stages use), not the full pose;
- the posture: with a check active, the main pipeline runs without ``q_rest`` and :func:`resolve` applies it after
  the re-solve, before the verdict (:func:`rest_free`: null-space steps that never leave the goal, and never end in
  a collision: the longest free prefix of the steps is kept), to every successful answer, re-solved or not;
- every answer that changed is judged again on its final ``q`` (as returned) by each term's check: the pose within
  the tolerances, or ``axis_err`` (recomputed) inside the bounds; the joint limits (the kernels keep them); the
  collision verdict;
- :meth:`~nik.IKSolver.solve_all` (:func:`solve_all`): colliding solutions solved again from themselves, plus one
  from uniform free starts, the free ones moved towards ``q_rest``, nearest first (:func:`all_solutions`).

Measured (``python benchmarks/compose.py``: panda, xarm7, ur5 in a clutter, targets from configurations free of it):
each mix within 1 point of the same mix without the world (benchmarks/results/compose.txt).

**The verdict** ``res.collision_free``: the sphere check of the returned ``q`` (margin 0): conservative, so an
answer called free is free on the meshes (docs/collisions.md measures it); ``success`` requires it. With a mesh
verdict (``IKSolver(mesh_verdict=)``: ``"auto"``, the default, where coal is installed and the robot has collision
meshes; True (required); a URDF path; False: the spheres always) the meshes judge instead
(:func:`nik.collision.meshcheck.mesh_check`, coal), in one of two ways, chosen once per call by
:func:`nik.collision.meshcheck.spheres_cover` (:attr:`Setup.covered`):

- **the spheres cover the meshes**: the model was fitted to the very URDF whose meshes judge (its ``source``) and
  checks every pair they check (no pair left out by sampling, ``"never"``): the built-in panda, ur5 and xarm7 with
  example-robot-data installed, and an arm whose model nik fitted to its URDF where the sampling left no pair out. A
  fit is an exact surface cover (:mod:`nik.collision.fit`), so an answer the spheres call free is free on the
  meshes, and coal need only judge what they call colliding: the stage runs as without a verdict (the spheres
  steer: the answers they call colliding are solved again, the blocked-pose proof spares the restarts), then coal
  judges the answers the spheres still call colliding; where a re-solved answer fails (off the goal, or colliding
  on the meshes) but the call's own answer met the goal and is free on the meshes, the own answer is returned (a
  conservative sphere model must never turn a free answer into a failure). The price of the choice: an own answer
  free on the meshes that the spheres call colliding is solved again like any other (it may move, or change branch),
  and kept only where the spheres find no free answer. Measured (built-in panda, a table and 10 obstacles, 1,000
  targets, scene seeds 0-2, ``benchmarks/collision_speed.py --builtin --mesh-verdict``, docs/collisions.md):
  success 99.8 / 99.9 / 99.8 % (the spheres judging: 99.8 / 99.7 / 98.9 %, no target lost against them), 0 answers
  called free that collide on the meshes, 21 / 24 / 35 us a target against 19 / 21 / 26 with the spheres judging
  (coal asked about 3 / 4 / 16 configurations of the call's 1,000 answers);
- **otherwise** (another URDF named, capsules, radii given, a pair left out by sampling) the spheres promise nothing
  about the meshes: every answer is checked on them and only those colliding there are solved again, without the
  blocked-pose proof (it does not bind the meshes); one coal check per answer (about 0.3-0.5 ms on the panda).

``res.collisions`` names what overlaps in each colliding answer (``"linkA|linkB"``, ``"link|box 2"``;
:func:`nik.collision.collision_names`), by the verdict's check.

Choices (:class:`CollideCfg`): margin 5 mm (the rows push the spheres that far apart, the verdict needs 0), weight
1 (a millimetre of penetration costs as much as a millimetre of pose error), 30 iterations per start,
:attr:`CollideCfg.restarts` uniform starts, each the collision-free draw nearest the pose among
:attr:`CollideCfg.tries`; a start at the pose whose hand overlaps by less than the tolerance can move it is first
finished inside the tolerance (:attr:`CollideCfg.finish` iterations, :mod:`nik.kernels.collision_lm`). A solver takes
other settings as ``solver.collide_cfg = CollideCfg(...)``.

The stage's modules, one job each: :mod:`~nik.ik.collide.choice` (which model and check a call uses, the settings),
:mod:`~nik.ik.collide.starts` (the starts of the re-solve), :mod:`~nik.ik.collide.resolver` (the collision LM, the
posture without leaving free), :mod:`~nik.ik.collide.stage` (:func:`resolve`: the order of the steps),
:mod:`~nik.ik.collide.verdict` (the meshes' verdict), :mod:`~nik.ik.collide.mesh_step` (the meshes steer),
:mod:`~nik.ik.collide.solutions` (:func:`solve_all`).
"""

from nik.ik.collide.choice import (
    CollideCfg,
    Setup,
    attached_model,
    check_mesh_verdict,
    check_self_collision,
    has_attached,
    setup,
)
from nik.ik.collide.choice import (
    _like as _like,
)
from nik.ik.collide.choice import (
    _numpy as _numpy,
)
from nik.ik.collide.resolver import _collision_solve as _collision_solve
from nik.ik.collide.resolver import _goal as _goal
from nik.ik.collide.resolver import _judge as _judge
from nik.ik.collide.resolver import _pusher as _pusher
from nik.ik.collide.resolver import _solve_free as _solve_free
from nik.ik.collide.resolver import rest_free
from nik.ik.collide.solutions import all_solutions, solve_all
from nik.ik.collide.stage import after_solve, resolve
from nik.ik.collide.starts import _starts as _starts
from nik.ik.collide.verdict import _meshes_judge as _meshes_judge
from nik.ik.collide.verdict import free_solutions, path_waypoints

__all__ = [
    "CollideCfg",
    "Setup",
    "after_solve",
    "attached_model",
    "all_solutions",
    "check_mesh_verdict",
    "check_self_collision",
    "free_solutions",
    "has_attached",
    "path_waypoints",
    "resolve",
    "rest_free",
    "setup",
    "solve_all",
]
