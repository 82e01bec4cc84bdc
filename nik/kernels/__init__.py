"""Compiled one-pose kernels (numba): FK, FK + Jacobian, damped LM, closed forms, network forward pass.

For one pose, the cost of the torch path is per-operation overhead, not arithmetic; these kernels
do the same work as plain compiled loops over small float64 numpy arrays, in microseconds. They
import nothing from nik but the constants of :mod:`nik.tolerances` (numpy and numba only), so every room may use
them; the torch code stays the reference they are tested against.

- :mod:`nik.kernels.chain`: the model arrays of a robot (:func:`chain_model`), FK of one
  configuration or a small batch, FK + geometric Jacobian;
- :mod:`nik.kernels.lm_step`: the one LM step (damped normal equations of residual rows, extra weighted rows and a
  prior; the limit-hold rule; the step cap) and its accept/damping rule, that every compiled solver below calls;
- :mod:`nik.kernels.lm`: Levenberg-Marquardt with joint limits and seeded uniform restarts, pose errors;
- :mod:`nik.kernels.closed`: the closed forms of 6R arms (spherical wrist, three parallel axes) and the
  choice among their solutions;
- :mod:`nik.kernels.poses`: the checks and conversions of target poses, the reach bound;
- :mod:`nik.kernels.mlp`: forward pass of an MLP whose weights are one flat float64 (or float32) array;
- :mod:`nik.kernels.seeded`: a network's hypotheses as LM seeds: forward pass and decoding, ranking by FK, LM from
  several starts in turn, merging refined answers;
- :mod:`nik.kernels.cache`: where the compiled code is kept (imports no numba);
- :mod:`nik.kernels.background`: the first compile on a cold cache: one line on stderr, the compiled solve compiled in
  a background thread while the torch backend answers (imports no numba).

Every kernel is ``numba.njit(cache=True, nogil=True)``, and none writes memory shared between calls
(scratch is allocated per call), so threads sharing a solver run their kernels in parallel. Compiled on
first use (tens of seconds, once per machine, announced by one line on stderr; ``backend="auto"`` answers from torch
meanwhile: :mod:`nik.kernels.background`), then loaded from the cache folder chosen by
:mod:`nik.kernels.cache` (``nik/kernels/__pycache__`` when writable, else ``$XDG_CACHE_HOME/nik/numba``;
``NUMBA_CACHE_DIR`` overrides both).
``import nik`` does not import this room (nor numba): callers import it when the compiled path is
first used.
"""

from __future__ import annotations

import importlib

#: Public names and the submodule that defines each; imported on first access, so that
#: ``import nik.kernels.cache`` (no numba) stays light.
_NAMES = {
    "CACHE": "nik.kernels._jit",
    "chain_model": "nik.kernels.chain",
    "fk": "nik.kernels.chain",
    "fk_at": "nik.kernels.chain",
    "fk_one_at": "nik.kernels.chain",
    "fk_batch": "nik.kernels.chain",
    "fk_jacobian": "nik.kernels.chain",
    "lm_options": "nik.kernels.lm",
    "lm_solve": "nik.kernels.lm",
    "pose_errors": "nik.kernels.lm",
    "seed_state": "nik.kernels.lm",
    "uniform_configurations": "nik.kernels.lm",
}

__all__ = sorted(_NAMES)


def __getattr__(name: str):
    if name in _NAMES:
        return getattr(importlib.import_module(_NAMES[name]), name)
    raise AttributeError(f"module 'nik.kernels' has no attribute {name!r}")
