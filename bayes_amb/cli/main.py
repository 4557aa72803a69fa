"""Entry point of the `bayes-amb` console script.

User errors (BayesAmbError, bad options, missing files) give one line on stderr and exit
status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from typing import Any

from bayes_amb import __version__
from bayes_amb.compile_notice import install as install_compile_notice
from bayes_amb.errors import BayesAmbError, one_line
from bayes_amb.threads import ENV_VAR as THREADS_ENV
from bayes_amb.threads import configure_process

_NEGATIVE_NUMBER = re.compile(r"^-(\d[\d_]*\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$",
                              re.IGNORECASE)


class _OneLineParser(argparse.ArgumentParser):
    """ArgumentParser whose errors are a single line and exit status 2, and which reads
    negative numbers in any notation (``--dt -1e-3``, ``--noise-rms -.5``, ``-inf``) as
    values: argparse's own pattern knows only ``-1`` and ``-1.5``, so ``-1e-3`` looked like
    an unknown option and gave "expected one argument"."""

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(one_line(f"{self.prog}: error: {message}") + "\n")
        raise SystemExit(2)


COMMAND_MODULES = {
    "model": "model_cmd", "params": "params_cmd", "controller": "controller_cmd",
    "simulate": "simulate_cmd", "identify": "identify_cmd", "study": "study_cmd",
    "bench": "bench_cmd", "diagnose": "diagnose_cmd", "library": "library_cmd",
    "report": "report_cmd", "demo": "demo_cmd", "import": "import_cmd",
    "import-controller": "import_cmd", "rig": "rig_cmd", "answers": "answers_cmd",
    "plan": "plan_cmd", "compare": "compare_cmd",
}
"""Each command and the module of bayes_amb.cli that registers it, in the order of
``bayes-amb --help``. A command's module imports what its run needs (python-control,
ArviZ, matplotlib: seconds), so a run builds only its own command's parser."""


COMMAND_HELP = {
    "model": "build the FE rotor model and its reduction; summarise",
    "params": "list the uncertain-parameter names",
    "controller": "design and export the reference controller",
    "simulate": "simulate a closed-loop recording",
    "identify": "identify parameters from a recording",
    "study": "run a sensitivity or calibration study",
    "bench": "run the benchmarks (ratios against baselines)",
    "diagnose": "locate and explain model discrepancy",
    "library": "list the candidate physics of the diagnosis",
    "report": "write an HTML and a PDF report of a run",
    "demo": "run the end-to-end demonstration and write a report",
    "import": "import a DAQ recording (.mat, TDMS, HDF5, CSV)",
    "import-controller": "import a MATLAB state-space or transfer-function controller "
                         "(.mat) as a controller file",
    "rig": "rig files: convert from ROSS",
    "answers": "bearing ks and c, closed-loop modes, log decrements, API 617 margins, "
               "ISO 14839-3 peak sensitivity, with 90%% intervals",
    "plan": "predict what a test will tell before it is run",
    "compare": "how much each coefficient changed between two runs, and the probability "
               "that it changed",
}
"""Each command's one line in ``bayes-amb --help`` (the same as its module registers; a
test holds them equal), so that the overview imports no command's module."""


def _global_parser() -> tuple[argparse.ArgumentParser, Any]:
    parser = _OneLineParser(prog="bayes-amb", description="Bayesian closed-loop "
                            "identification of rotors on active magnetic bearings.")
    parser.add_argument("--version", action="version", version=f"bayes-amb {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--threads", metavar="N", help="BLAS/OpenMP threads (default: "
                        f"${THREADS_ENV} or 1; 0 keeps the libraries' own default)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_OneLineParser)
    return parser, sub


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or of ``command`` alone (a name of COMMAND_MODULES):
    the same options, without importing the other commands' modules."""
    import importlib

    parser, sub = _global_parser()
    names = (COMMAND_MODULES[command],) if command in COMMAND_MODULES else COMMAND_MODULES.values()
    for name in dict.fromkeys(names):
        importlib.import_module(f"bayes_amb.cli.{name}").add_parser(sub)
    return parser


def overview_parser() -> argparse.ArgumentParser:
    """The parser without a known command (``bayes-amb``, ``bayes-amb --help``, an unknown
    command): the global options and each command's one line, no command module imported
    (building every command's parser imports python-control and ArviZ, about 3 s)."""
    parser, sub = _global_parser()
    for name, text in COMMAND_HELP.items():
        sub.add_parser(name, help=text)
    return parser


def _global_words(argv: list[str]) -> tuple[str | None, str | None]:
    """(the value of a global --threads N / --threads=N, the command): read before
    anything imports numpy (BLAS reads its thread count then) and before the parser is
    built (it builds the command's alone). Global options come before the command; the
    first --threads counts."""
    threads, skip = None, False
    for i, arg in enumerate(argv):
        if skip:
            skip = False
        elif arg == "--threads":
            skip = True
            if threads is None and i + 1 < len(argv):
                threads = argv[i + 1]
        elif arg.startswith("--threads="):
            threads = arg.partition("=")[2] if threads is None else threads
        elif not arg.startswith("-"):
            return threads, arg
    return threads, None


def _swallowed_value(parser: argparse.ArgumentParser, args: argparse.Namespace
                     ) -> tuple[argparse.ArgumentParser, str] | None:
    """An option given ``--opt=--``, whose value Python 3.12's argparse drops (it leaves
    [] where one typed value belongs, and 3.13 reports the value as invalid): the parser
    that owns it and the error to report, or None."""
    parsers = [parser]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, "command", None))
            parsers += [chosen] if chosen is not None else []
    for p in parsers:
        for action in p._actions:
            if (action.option_strings and action.nargs is None and action.type is not None
                    and isinstance(getattr(args, action.dest, None), list)):
                return p, f"argument {'/'.join(action.option_strings)}: invalid value '--'"
    return None


def main(argv: list[str] | None = None) -> int:
    threads, command = _global_words(sys.argv[1:] if argv is None else argv)
    try:                                      # before the heavy imports (BLAS reads its env)
        configure_process(threads)
    except BayesAmbError as exc:
        sys.stderr.write(f"bayes-amb: error: {exc}\n")
        return 2
    parser = build_parser(command) if command in COMMAND_MODULES else overview_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:                 # a usage error (status 2), --help or --version
        return exc.code if isinstance(exc.code, int) else 2
    if (swallowed := _swallowed_value(parser, args)) is not None:
        try:
            swallowed[0].error(swallowed[1])
        except SystemExit as exc:
            return exc.code if isinstance(exc.code, int) else 2
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    install_compile_notice()                  # one line if the kernels are not compiled yet
    try:
        return int(args.func(args) or 0)
    except BayesAmbError as exc:
        sys.stderr.write(one_line(f"bayes-amb {args.command}: error: {exc}") + "\n")
        return 2
    except OSError as exc:
        sys.stderr.write(one_line(f"bayes-amb {args.command}: error: {exc.filename or ''}: "
                                  f"{exc.strerror or exc}") + "\n")
        return 2
    except KeyboardInterrupt:                 # Ctrl-C outside a study's own handling
        sys.stderr.write(f"bayes-amb {args.command}: interrupted\n")
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
