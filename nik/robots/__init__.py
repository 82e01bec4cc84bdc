"""Robot models: YAML (DH / modified DH / screw axes) and URDF loading, and the :class:`Robot` class."""

from nik.robots.config import BUILTIN_DIR, builtin_robots, load_robot, robot_from_config
from nik.robots.model import Robot

__all__ = ["BUILTIN_DIR", "Robot", "builtin_robots", "load_robot", "robot_from_config"]
