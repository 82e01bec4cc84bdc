"""robots: robot models, YAML (DH / modified DH / screw axes) and URDF loading, and the :class:`Robot` class.

Also here: base and tool (TCP) frames (:mod:`nik.robots.frames`), joint-range arithmetic
(:mod:`nik.robots.joints`) and the provable reach bound (:mod:`nik.robots.reach`). The room may import
kinematics and poses; it is the only importer of pytorch-kinematics (URDF parsing).
"""

from nik.robots.config import BUILTIN_DIR, builtin_robots, load_robot, robot_from_config
from nik.robots.model import Robot

__all__ = ["BUILTIN_DIR", "Robot", "builtin_robots", "load_robot", "robot_from_config"]
