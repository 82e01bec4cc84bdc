"""One pose per call in a tight loop: median and p99 microseconds (CPU time of this thread) of the default solver.

Prints one line, ``arm:guess:median:p99`` per arm, so that two checkouts can be compared in alternating processes
(``PYTHONPATH=<checkout> python benchmarks/tight_loop.py panda xarm7 ur5 kuka_kr``, old, new, old, new, ...).
2,000 reachable poses per arm (seeded), after a warm-up; one torch thread. ``NIK_TIGHT_NUMPY=1``: the poses as numpy
arrays (numpy out, no torch on the way, where the checkout supports it).
"""

import os
import statistics
import sys
import time

import torch

import nik

torch.set_num_threads(1)
out = []
for name in sys.argv[1:] or ["panda", "xarm7", "ur5", "kuka_kr"]:
    robot = nik.load_robot(name)
    solver = nik.IKSolver(robot)
    T = robot.fk(robot.sample(2000, generator=torch.Generator().manual_seed(7), dtype=torch.float64))
    numpy_in = os.environ.get("NIK_TIGHT_NUMPY") == "1"
    poses = [T[i].numpy().copy() if numpy_in else T[i] for i in range(2000)]
    solver.solve(T[:64])
    for t in poses[:50]:
        solver.solve(t)
    times = []
    for t in poses:
        c0 = time.thread_time()
        res = solver.solve(t)
        times.append(time.thread_time() - c0)
    times.sort()
    out.append(f"{name}:{res.source}:{1e6 * statistics.median(times):.1f}:{1e6 * times[int(0.99 * len(times))]:.1f}")
print(" ".join(out))
