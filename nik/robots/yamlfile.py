"""YAML text parsed with its errors placed: the one reader of robot files, scene files and ranges files.

Parsing uses libyaml (PyYAML's ``CSafeLoader``, the same safe types, about 10x faster than the pure-Python parser:
0.16 against 1.6 ms for the built-in panda's file) where PyYAML was built with it, else ``SafeLoader``.
:func:`load_yaml_file` keeps the parse of a file for as long as the file is unchanged (its size and modification
time), so that the built-in robots' files, looked at by name and then read, are parsed once per process.

PyYAML's errors carry where the parser stopped (``problem_mark``: 0-based line and column) and what it was doing
(``context``: ``while parsing a flow sequence``); its one-line summary keeps only the context, which leaves the user
to search the file. :func:`yaml_problem` words both, lines and columns counted from 1 as editors count them, and
:func:`load_yaml` raises it as one line. yaml is imported on first use (``import nik`` does not import it).
"""

from __future__ import annotations

import copy
from pathlib import Path

__all__ = ["load_yaml", "load_yaml_file", "yaml_problem"]

_PARSED: dict = {}  # resolved path -> ((size, mtime_ns), data)


def yaml_problem(err: Exception) -> str:
    """``"line 2, column 52: expected ',' or ']', but got '}' (while parsing a flow sequence begun at line 2, column
    39)"``: where a :class:`yaml.YAMLError` stopped the parser (1-based), what it found and what it was parsing.
    An error without a place (not a ``MarkedYAMLError``) gives its first line."""
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None)
    context = getattr(err, "context", None)
    if mark is None:
        text = str(err).strip()
        return text.splitlines()[0] if text else type(err).__name__
    where = f"line {mark.line + 1}, column {mark.column + 1}"
    out = f"{where}: {problem}" if problem else where
    if context:
        began = getattr(err, "context_mark", None)
        if began is not None and (began.line, began.column) != (mark.line, mark.column):
            context += f" begun at line {began.line + 1}, column {began.column + 1}"
        out += f" ({context})" if problem else f": {context}"
    return out


def load_yaml(text: str, source: str, error: type[Exception] = ValueError):
    """``yaml.safe_load(text)``; a syntax error raises ``error(f"{source}: not valid YAML: {yaml_problem}")``, one
    line (``source``: the file as the message names it)."""
    import yaml

    try:
        return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as err:
        raise error(f"{source}: not valid YAML: {yaml_problem(err)}") from None


def load_yaml_file(path: str | Path, error: type[Exception] = ValueError, source: str | None = None):
    """:func:`load_yaml` of the file at ``path`` (``source``: how messages name it, default the path), parsed once
    while the file keeps its size and modification time; each call gets its own copy of the data. An unreadable
    file raises :class:`OSError` as ``Path.read_text`` does."""
    path = Path(path)
    st = path.stat()
    key, stamp = str(path.resolve()), (st.st_size, st.st_mtime_ns)
    hit = _PARSED.get(key)
    if hit is None or hit[0] != stamp:
        hit = (stamp, load_yaml(path.read_text(), source or str(path), error))
        _PARSED[key] = hit
    return copy.deepcopy(hit[1])
