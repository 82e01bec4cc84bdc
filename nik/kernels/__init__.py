"""Compiled one-pose kernels (numba): FK, FK + Jacobian, damped LM, network forward pass.

For one pose, the cost of the torch path is per-operation overhead, not arithmetic; these kernels
do the same work as plain compiled loops over small float64 numpy arrays, in microseconds. They
import nothing from nik (numpy and numba only), so every room may use them; the torch code stays
the reference they are tested against.

- :mod:`nik.kernels.chain`: the model arrays of a robot (:func:`chain_model`), FK of one
  configuration or a small batch, FK + geometric Jacobian;
- :mod:`nik.kernels.lm`: Levenberg-Marquardt with joint limits and seeded uniform restarts;
- :mod:`nik.kernels.mlp`: forward pass of an MLP whose weights are one flat float64 array.

Every kernel is ``numba.njit(cache=True)``: compiled on first use (seconds, once per machine), then
loaded from the cache folder chosen by :mod:`nik.kernels.cache` (``nik/kernels/__pycache__`` when
writable, else ``$XDG_CACHE_HOME/nik/numba``; ``NUMBA_CACHE_DIR`` overrides both).
``import nik`` does not import this room (nor numba): callers import it when the compiled path is
first used.
"""

from __future__ import annotations

from nik.kernels._jit import CACHE
from nik.kernels.chain import chain_model, fk, fk_batch, fk_jacobian
from nik.kernels.lm import lm_options, lm_solve, lm_work, seed_state, uniform_configurations

__all__ = [
    "CACHE",
    "chain_model",
    "fk",
    "fk_batch",
    "fk_jacobian",
    "lm_options",
    "lm_solve",
    "lm_work",
    "seed_state",
    "uniform_configurations",
]
