"""nets: the IK networks, pose -> joint angles, and their files.

- :mod:`nik.nets.mlp`: :class:`IKNet`, the plain MLP (paper C's 6-8-6 and the realistic default);
- :mod:`nik.nets.multi`: multi-solution networks (:class:`BranchIKNet`, :class:`MultiHypIKNet`) that give
  ``(B, K, dof)`` hypotheses instead of averaging IK branches;
- :mod:`nik.nets.pair`: an exported network, ``NAME.safetensors`` + ``NAME.json`` (SHA-256 checked on load);
- :mod:`nik.nets.checkpoint`: Lightning ``.ckpt`` files read safely (``weights_only=True``), and
  :func:`load_network` for any network file;
- :mod:`nik.nets.registry`: where networks live (the user folder, the shipped one) and which one an arm
  gets (by definition hash);
- :mod:`nik.nets.pretrained`: ``load_pretrained`` and the recorded validation error;
- :mod:`nik.nets.export` (``python -m nik.nets.export``): a training checkpoint -> a pair.

Imports inside the room run one way: ``mlp`` <- ``multi`` <- ``pair`` <- ``checkpoint``, ``registry``
<- ``pretrained`` <- ``export``.
The room may import kinematics, poses, robots and data (branch labels); never analytic, lm, swarm, ik,
learn or cli.
"""

from nik.nets.checkpoint import CHECKPOINT_FORMAT, checkpoint_extra, load_checkpoint, load_network, save_checkpoint
from nik.nets.mlp import ACTIVATIONS, DEFAULT, OUTPUTS, PAPER_C, REPRESENTATIONS, IKNet
from nik.nets.multi import BranchIKNet, MultiHypIKNet, build_net, hypothesis_pose_error
from nik.nets.pretrained import load_pretrained, pretrained_robots

__all__ = [
    "ACTIVATIONS",
    "CHECKPOINT_FORMAT",
    "DEFAULT",
    "OUTPUTS",
    "PAPER_C",
    "REPRESENTATIONS",
    "BranchIKNet",
    "IKNet",
    "MultiHypIKNet",
    "build_net",
    "checkpoint_extra",
    "hypothesis_pose_error",
    "load_checkpoint",
    "load_network",
    "load_pretrained",
    "pretrained_robots",
    "save_checkpoint",
]
