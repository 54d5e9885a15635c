"""The ``springbench`` command. Each subcommand is one module in ``harness.commands``
registered in ``harness.registry.COMMANDS``; it defines ``HELP``, ``add_arguments(parser)`` and
``main(args) -> int``. Bad input becomes one line on stderr and exit status 2."""

from __future__ import annotations

import argparse
import sys

from harness.errors import SpringbenchError, error_lines
from harness.outputs import os_error
from harness.registry import COMMANDS


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2, no usage dump
        self.exit(2, f"{self.prog}: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    from harness import __version__

    parser = _Parser(
        prog="springbench",
        description="Score and calibrate spring/mass models against linear elasticity.",
    )
    parser.add_argument("--version", action="version", version=f"springbench {__version__}")
    sub = parser.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")
    for name, mod in COMMANDS.items():
        p = sub.add_parser(
            name,
            help=mod.HELP,
            description=mod.HELP,
            epilog=getattr(mod, "EPILOG", None),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        mod.add_arguments(p)
        p.set_defaults(_main=mod.main)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_main", None):
        parser.print_help()
        return 2
    try:
        return int(args._main(args) or 0)
    except SpringbenchError as exc:
        for line in error_lines(exc):
            print(f"springbench: error: {line}", file=sys.stderr)
        return 2
    except OSError as exc:  # the file system refused (disk full, read-only, ...): still one line
        print(f"springbench: error: {os_error(exc, exc.filename or '', None)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("springbench: interrupted; finished cases are kept", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
