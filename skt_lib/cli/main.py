"""``skt``: the command line of skt-hang (``skt --help``).

Expected errors (bad input files or arguments, a missing or corrupt model, a mesh that
cannot be repaired…) print one line, ``ERROR: <file>: <what is wrong>``, and exit with
code 2; ``--debug`` shows the traceback too. Nothing is left half-written: every output is
written to a temporary file and renamed into place once complete.
"""

import argparse
import importlib
import sys
import traceback
from collections.abc import Sequence

from skt_lib.quiet import import_quietly

# before any command module imports it: PyBullet's banner goes to nowhere (stderr with --debug)
import_quietly("pybullet", to_stderr="--debug" in sys.argv)

from skt_lib.cli.common import EXIT_BAD_INPUT  # noqa: E402
from skt_lib.errors import SktError  # noqa: E402

EPILOG = """examples:
  skt predict hook.ply -o skt.json --rrd skt.rrd
  skt import-object my_mug.obj --name my_mug
  skt hang --support support_00008 --object my_mug --method oracle --rrd hang.rrd"""


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one ``ERROR:`` line and exit code 2."""

    def error(self, message: str):
        sys.stderr.write(f"ERROR: {self.prog}: {message} (see {self.prog} --help)\n")
        sys.exit(EXIT_BAD_INPUT)


#: Each subcommand and the module that defines it, in ``--help`` order. A run imports only
#: its own command's module: an import needs neither PyTorch nor the evaluation's modules.
COMMANDS = {"predict": "predict", "import-object": "import_mesh", "import-support": "import_support",
            "hang": "hang"}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``command`` alone, or of every subcommand (``None``, or not one)."""
    ap = _Parser(prog="skt", description="Semantic keypoint trajectories: predict, import, hang.",
                 epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--debug", action="store_true", help="show tracebacks of expected errors")
    sub = ap.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND")
    for name in [COMMANDS[command]] if command in COMMANDS else COMMANDS.values():
        importlib.import_module(f"skt_lib.cli.{name}").add_parser(sub)
    for p in sub.choices.values():
        p.formatter_class = argparse.RawDescriptionHelpFormatter
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(next((a for a in argv if not a.startswith("-")), None)).parse_args(argv)
    try:
        return args.run(args)
    except SktError as err:
        if args.debug:
            traceback.print_exc()
        message = " ".join(str(err).split())  # one line, whatever the library wrote
        sys.stderr.write(f"ERROR: {message}\n")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        sys.stderr.write("ERROR: interrupted\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
