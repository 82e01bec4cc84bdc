"""view: seeing an IK answer: the arm drawn at its joints, in a browser page or a picture.

- :mod:`nik.view.arm`: the points to draw, from FK of every prefix of the chain (joint origins, tool);
- :mod:`nik.view.plot`: :func:`plot_arm`, a static picture (matplotlib, imported when it runs);
- :mod:`nik.view.urdf_meshes`: a URDF's visual meshes placed at the arm's joints (trimesh, from the ``view``
  extra), where the mesh files are there;
- :mod:`nik.view.viewer`: :class:`Viewer`, a viser page: the arm, a target dragged with the mouse that the arm
  follows (one ``IKSolver.solve`` per move), every solution of the pose as faint ghost arms, a path played back.

A room above ik (it may import ik and every room below it) and below cli: nothing but cli imports it.
viser and matplotlib are optional here and imported only when a viewer starts or a picture is drawn, so
``import nik.view`` stays light; without viser, :class:`Viewer` raises :class:`MissingExtraError`.
"""

from nik.view.arm import arm_points
from nik.view.plot import plot_arm
from nik.view.viewer import VIEW_EXTRA_MESSAGE, MissingExtraError, Viewer, ViewerCfg, ViewState, viser_available

__all__ = [
    "VIEW_EXTRA_MESSAGE",
    "MissingExtraError",
    "Viewer",
    "ViewState",
    "ViewerCfg",
    "arm_points",
    "plot_arm",
    "viser_available",
]
