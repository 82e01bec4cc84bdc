"""The closest known names to a mistyped one, for error messages: links, joints, built-in robots, file fields.

A message that lists 57 link names leaves the user to search them; :func:`did_you_mean` puts the likely ones first.
Closeness is :func:`difflib.get_close_matches` (the ratio of matching characters, cut-off 0.6), compared without
case, so ``'Panda'`` finds ``'panda'``; a name that is a prefix or suffix of known names (``'right_hand'`` of
``'right_hand_link'``) always counts as close, since a link or joint named without its ``_link``/``_joint`` ending
is the commonest slip. Imports nothing from nik.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["closest", "did_you_mean"]

#: How many suggestions a message names at most.
MAX_SUGGESTIONS = 3


def closest(name: str, known: Iterable[str], n: int = MAX_SUGGESTIONS) -> list[str]:
    """Up to ``n`` names of ``known`` closest to ``name``, closest first: those that ``name`` (3 characters or more)
    begins or ends (without case) first, shortest first, then :func:`difflib.get_close_matches`'s (ratio >= 0.6,
    without case); [] where none is close. ``name`` itself is never among them."""
    known = [str(k) for k in known]
    lower = {}
    for k in known:
        lower.setdefault(k.lower(), k)
    key = str(name).lower()
    if not key:
        return []
    affix = [
        k
        for k in known
        if len(key) >= 3 and k.lower() != key and key in (k.lower()[: len(key)], k.lower()[-len(key) :])
    ]
    affix.sort(key=len)
    fuzzy = [lower[m] for m in difflib.get_close_matches(key, list(lower), n=n, cutoff=0.6)]
    out = []
    for k in affix + fuzzy:
        if k not in out and k != name:
            out.append(k)
    return out[:n]


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``"did you mean 'right_hand_link'?"`` (or ``"'a' or 'b'"`` for several) for ``name`` among ``known``; ``""``
    where no known name is close. Meant to come first in a one-line error, before the full list."""
    found = closest(name, known)
    if not found:
        return ""
    return "did you mean " + " or ".join(repr(k) for k in found) + "?"
