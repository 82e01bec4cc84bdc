"""Datasets of (joint vector, pose) pairs: generation, storage format, loading, IK branch labels.

generate_dataset(robot, n, out, seed=...)  -> writes data/NAME/ (q.npy, pose.npy, branch.npy, meta.json)
load_dataset(path, robot=None)             -> IKDataset (.q (N, dof), .pose (N, 4, 4), .meta, splits)
generate_dataset(..., shard=(i, k))         -> shard i of k of that dataset; merge_shards(out, dirs) joins them
generate_dataset(..., sampling=Sampling(sampler="sobol"), compute=Compute(device="cuda"))  -> grouped options

The room may import kinematics, poses and robots; never nets, analytic, lm, swarm, ik, learn or cli.
"""

from nik.data.branches import BRANCH_NAMES, BranchClassifier, branch_classifier, branch_labels, branch_name
from nik.data.generate import (
    BLOCK_SIZE,
    DEFAULT_CHUNK,
    Compute,
    Sampling,
    generate_dataset,
    parse_shard,
    resolve_ranges,
    sample_stream,
    shard_rows,
)
from nik.data.merge import merge_shards
from nik.data.storage import IKDataset, load_dataset, read_meta, sha256_file

__all__ = [
    "BLOCK_SIZE",
    "BRANCH_NAMES",
    "BranchClassifier",
    "Compute",
    "DEFAULT_CHUNK",
    "IKDataset",
    "Sampling",
    "branch_classifier",
    "branch_labels",
    "branch_name",
    "generate_dataset",
    "load_dataset",
    "merge_shards",
    "parse_shard",
    "read_meta",
    "resolve_ranges",
    "sample_stream",
    "sha256_file",
    "shard_rows",
]
