"""Compare bp, adam, lbfgs, de and de_bp on one dataset, split and wall-clock budget, three seeds each.

    python benchmarks/learners.py --data data/kuka_kr_100k --budget 45 --seeds 0 1 2 \
        --out benchmarks/results/learners_kuka_kr

Same as ``nik compare``; the work is in :mod:`nik.learn.compare` (see its docstring for the outputs).
"""

from __future__ import annotations

from nik.learn.compare import main

if __name__ == "__main__":
    raise SystemExit(main())
