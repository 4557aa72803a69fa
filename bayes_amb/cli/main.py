"""Entry point of the `bayes-amb` console script.

User errors (BayesAmbError, bad options, missing files) give one line on stderr and exit
status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys

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


def build_parser() -> argparse.ArgumentParser:
    from bayes_amb.cli import model_cmd, params_cmd

    parser = _OneLineParser(prog="bayes-amb", description="Bayesian closed-loop "
                            "identification of rotors on active magnetic bearings.")
    parser.add_argument("--version", action="version", version=f"bayes-amb {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--threads", metavar="N", help="BLAS/OpenMP threads (default: "
                        f"${THREADS_ENV} or 1; 0 keeps the libraries' own default)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_OneLineParser)
    for mod in (model_cmd, params_cmd):
        mod.add_parser(sub)
    _add_optional_commands(sub)
    return parser


def _add_optional_commands(sub: argparse._SubParsersAction) -> None:
    """Commands of later pipeline stages register here when their modules exist."""
    import importlib

    for name in ("controller_cmd", "simulate_cmd", "identify_cmd", "study_cmd", "bench_cmd",
                 "diagnose_cmd", "library_cmd", "report_cmd", "demo_cmd", "import_cmd", "rig_cmd",
                 "answers_cmd", "plan_cmd", "compare_cmd"):
        try:
            mod = importlib.import_module(f"bayes_amb.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"bayes_amb.cli.{name}":
                raise
            continue
        mod.add_parser(sub)


def _threads_option(argv: list[str]) -> str | None:
    """The value of a global --threads N / --threads=N, read before anything imports numpy."""
    for i, arg in enumerate(argv):
        if arg == "--threads" and i + 1 < len(argv):
            return argv[i + 1]
        if arg.startswith("--threads="):
            return arg.partition("=")[2]
        if not arg.startswith("-"):
            return None                       # the command: global options come before it
    return None


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
    try:                                      # before the heavy imports (BLAS reads its env)
        configure_process(_threads_option(sys.argv[1:] if argv is None else argv))
    except BayesAmbError as exc:
        sys.stderr.write(f"bayes-amb: error: {exc}\n")
        return 2
    parser = build_parser()
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
