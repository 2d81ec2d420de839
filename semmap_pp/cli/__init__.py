"""The ``semmap`` command.

Each subcommand lives in its own module ``semmap_pp/cli/cmd_<name>.py`` exposing
``register(subparsers)``; the module registers its parser and sets ``func(args) -> int``.
Modules are discovered, so adding a subcommand never touches this file.

Every :class:`~semmap_pp.errors.SemmapError` becomes one line on stderr and exit status 2; so does
running out of memory (a map too large for the machine: docs/robustness.md gives the memory per
cell). Ctrl-C becomes exit status 130; a reader of stdout that goes away (``semmap diagnose DIR |
head``) ends the command quietly with status 141, as SIGPIPE would. An argument that is not UTF-8
text (a file name of other bytes) is one line and status 2 before the command starts
(:func:`not_utf8`). No traceback reaches the user for an input error.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import pkgutil
import re
import sys

from semmap_pp import __version__
from semmap_pp.errors import SemmapError, printable


_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
#: a negative number as an argument: argparse's own test takes ``-2``, ``-2.5`` and ``-.5`` only,
#: and reads ``-2e1`` or ``-2.`` as an unknown option (then "expected 5 arguments"); also a map
#: point ``X,Y`` whose X is negative (``semmap route``)
NEGATIVE_NUMBER = re.compile(rf"^-{_NUMBER}(,-?{_NUMBER})?$")


class Parser(argparse.ArgumentParser):
    """argparse's parser, reading every negative number (and point ``X,Y``) as one
    (:data:`NEGATIVE_NUMBER`): map coordinates in metres are often negative. Sub-commands'
    parsers are of this class too (``add_subparsers`` makes them of the parent's class)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="semmap",
        description="Abstract semantic maps (rooms, corridors, halls, doors) from ROS occupancy grids.",
    )
    parser.add_argument("--version", action="version", version=f"semmap_pp {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    package = importlib.import_module(__name__)
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{info.name}").register(subparsers)
    return parser


def not_utf8(argv) -> str | None:
    """The first argument that is not UTF-8 text (a file name of other bytes, which Python keeps as
    lone surrogates), or None. Names given to semmap go into its outputs (world.json, report.html,
    trace.nc) and onto stdout, all UTF-8, so such a name is refused before anything is read.

    >>> not_utf8(["map", "m.yaml"]), not_utf8(["map", "/tmp/\\udcff.yaml"])
    (None, '/tmp/\\udcff.yaml')
    """
    for a in argv:
        text = os.fsdecode(a) if isinstance(a, (bytes, os.PathLike)) else a
        if isinstance(text, str):
            try:
                text.encode("utf-8")
            except UnicodeEncodeError:
                return text
    return None


def quiet_finalizers() -> None:
    """After Ctrl-C, keep objects torn down half built from printing at their collection: an
    interrupt inside a library's constructor (a clingo AST node) leaves an object whose
    ``__del__`` fails, and Python prints that failure's traceback as an "Exception ignored"
    message. The run has said in one line that it was interrupted; nothing else is printed."""
    sys.unraisablehook = lambda unraisable: None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    bad = not_utf8(argv)
    if bad is not None:
        print(f"semmap: error: {printable(bad)}: not UTF-8 text (a name of other bytes, shown as \\xNN); "
              "semmap writes the names it is given into its outputs as UTF-8: rename the file or "
              "folder", file=sys.stderr)
        return 2
    try:    # building the parser imports every command's module: a second on a cold start
        args = build_parser().parse_args(argv)
        return int(args.func(args) or 0)
    except SemmapError as exc:
        print(f"semmap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        quiet_finalizers()
        print("semmap: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        try:    # stdout's reader is gone: no flush error at exit either
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        return 141
    except MemoryError:
        print("semmap: error: out of memory: the input is too large for this machine "
              "(docs/robustness.md: memory per map cell); --max-cells refuses such maps early",
              file=sys.stderr)
        return 2


def console_main(argv: list[str] | None = None) -> int:
    """The ``semmap`` command and ``python -m semmap_pp``: :func:`main`, after which every object
    is set aside from the garbage collector (:func:`gc.freeze`), so that the interpreter's teardown
    does not collect over the whole heap again: those collections took 0.8-0.9 s at the end of
    ``semmap map`` on a real floor (docs/benchmarks.md). Every file a command writes is closed
    and renamed into place by then (:mod:`semmap_pp.atomic`), and exit handlers run as before."""
    try:
        return main(argv)
    finally:
        gc.freeze()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
