"""The ``nik`` command line: argument parsing only; every command calls the library.

Each submodule of ``nik.cli`` registers its subcommands with ``register(subparsers)`` and
sets ``func`` on its parser; :func:`main` dispatches and turns a ``ValueError`` (nik's
errors included) or a missing file into one line on stderr and exit code 2, without a traceback. Output
piped into a reader that stops early (``nik networks | head``) ends quietly with exit code 141, as a
command killed by SIGPIPE does.

The top room: it may import every other room, and none imports it.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Submodules that add subcommands, in the order they appear in ``nik --help``.
COMMAND_MODULES = ["nik.cli.data", "nik.cli.solve", "nik.cli.path", "nik.cli.train", "nik.cli.networks", "nik.cli.view"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nik", description="nik: learned inverse kinematics for robot arms")
    parser.add_argument("--version", action="version", version=f"nik {importlib.import_module('nik').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name == name:  # that command group is not part of this build
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.invocation = ["nik", *(sys.argv[1:] if argv is None else [str(a) for a in argv])]  # recorded by nik train
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        threads = getattr(args, "threads", None)
        if threads is not None:
            from nik.threads import set_threads

            set_threads(threads)
        rc = int(args.func(args) or 0)
        sys.stdout.flush()  # here, not at interpreter exit, so that a closed pipe is caught below
        return rc
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    except KeyboardInterrupt:
        print("nik: interrupted", file=sys.stderr)
        return 130
    except (ValueError, FileNotFoundError, FileExistsError, PermissionError, NotADirectoryError) as err:
        print(f"nik {args.command}: error: {err}", file=sys.stderr)
        return 2


def _quiet_stdout() -> None:
    """The reader of stdout is gone: send what is left to /dev/null, so that the interpreter's last flush at exit
    does not raise (and print) the same error again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # stdout is no file (captured): nothing will be flushed to a pipe
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
