"""collision: the arm's sphere model, the world's obstacles, signed distances and the collision check.

The room sits between robots and data (it imports kernels, kinematics / poses and robots only):

- :func:`collision_model`: spheres per link fitted to a URDF's collision
  geometry, the shipped spheres of a built-in arm fitted to its vendor's meshes (:mod:`.builtin`), or capsules
  along the links; the link pairs worth checking; cached per robot (:mod:`.model`);
- :class:`World`: spheres, boxes, capsules and point clouds in the base frame (:mod:`.world`);
- :func:`signed_distances`, :func:`collision_residual`, :func:`collides`: batched, differentiable (torch,
  :mod:`.distance`, :mod:`.check`); the compiled kernels with their Jacobians are :mod:`nik.kernels.collision`.

Importing this room loads neither numba nor trimesh (the kernels and the mesh reader come on first use).
"""

from nik.collision.check import collides, colliding_links, collision_names, collision_residual, signed_distances
from nik.collision.distance import link_frames, self_distances, sphere_centers, world_distances
from nik.collision.model import CollisionModel, collision_model, set_collision_model
from nik.collision.world import World

__all__ = [
    "CollisionModel",
    "World",
    "colliding_links",
    "collides",
    "collision_names",
    "collision_model",
    "collision_residual",
    "link_frames",
    "self_distances",
    "set_collision_model",
    "signed_distances",
    "sphere_centers",
    "world_distances",
]
