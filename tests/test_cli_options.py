"""Every CLI option fails clearly (issue 19): a property test drives each subcommand's options
with hostile values, and a walk over the parsers checks that the help answers.

The fuzz calls ``bayes_amb.cli.main.main(argv)`` in-process (as tests/helpers.run_cli does).
Each command gets otherwise valid arguments whose input file does not exist, so a value
that passes its option's check ends at once on the missing file; a value that does not
ends on the option. Either way the command must end with exit 0 (``-h`` as a value asks for
help) or exit 2 with exactly one stderr line, never a traceback, never a stack of lines.
``derandomize=True`` fixes the examples, so a run is reproducible; 8 subcommands x 40-60
examples give over 300 cases per run, a few seconds in all.
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bayes_amb.cli.bench_cmd import selected
from bayes_amb.cli.main import COMMAND_MODULES, build_parser, main
from bayes_amb.cli.options import integer, range_text, real, seed

# Values that broke or could break option parsing: negative and scientific numbers, the
# non-finite floats, overflow, separators, signs alone, option-like strings, control
# characters, non-ASCII digits, empty and blank strings.
NASTY = ["-1e-3", "-1E-3", "1e-400", "1e400", "-1e400", "-0", "0", "0.0", "nan", "-nan",
         "NaN", "inf", "-inf", "Infinity", "1e", "e3", "--", "-", "", " ", "0x10", "1,2",
         "1_000", "١٢", "½", "-.5", "5.", "+3", " 7 ", "1e-3 ", "\x00", "a\x00b", "-x",
         "--dt", "-1", "-4294967296", "4294967296", "99999999999999999999999", "True",
         "k_By", "k_By=", "=0.5", "k_By=nan", "k_By=1e400", "wobble:x=1", "actuator_lag:",
         "actuator_lag:bandwidth_hz=-1e3", "normal(0.3", "normal(0,-1)", "uniform(1,0)",
         "/", ".", "..", "/dev/null", "/proc/self/nonexistent/x", "\n", "é", "💥"]

VALUES = st.one_of(
    st.sampled_from(NASTY),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**25), max_value=10**25).map(str),
    st.text(max_size=12),
)


def _check(argv: list[str], capsys) -> None:
    code = main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "Traceback" not in out, (argv, err)
    assert code in (0, 2), (argv, code, err)
    if code == 2:
        lines = err.splitlines()
        assert len(lines) == 1 and err.endswith("\n"), (argv, err)
        assert lines[0].startswith("bayes-amb"), (argv, err)
        assert out == "", (argv, out)


def _argv(base: list[str], option: str, value: str, joined: bool) -> list[str]:
    return [*base, f"{option}={value}"] if joined else [*base, option, value]


N_EXAMPLES = 45
COMMANDS = {
    "simulate": (["simulate", "--rig", "{miss}/rig.toml", "-o", "{tmp}/x.csv"],
                 ["--amplitude", "--r1-rms", "--r2-rms", "--r1-band-hz", "--r2-band-hz",
                  "--noise-rms", "--duration", "--dt", "--speed-rpm", "--seed", "--band",
                  "--set", "--effect", "--truth", "--excitation", "--rig", "--controller",
                  "--port", "-o"]),
    "identify": (["identify", "{miss}/rec.csv", "--params", "k_By", "--out", "{tmp}/run"],
                 ["--walkers", "--steps", "--seed", "--map-method", "--params", "--prior",
                  "--prior-file", "--out", "--rig"]),
    "diagnose": (["diagnose", "{miss}/rec.csv", "--out", "{tmp}/diag"],
                 ["--threshold", "--max-effects", "--steps", "--seed", "--effects", "--scan",
                  "--planes", "--params", "--prior", "--prior-file", "--rig"]),
    "study": (["study", "{miss}/s.toml", "--out", "{tmp}/study"],
              ["--workers", "--dask-local", "--scheduler", "--out"]),
    "controller": (["controller", "--rig", "{miss}/rig.toml"],
                   ["--dt", "--speed-rpm", "--export", "--rig"]),
    "model": (["model", "--rig", "{miss}/rig.toml"], ["--speed-rpm", "--rig"]),
    "report": (["report", "{miss}/run"], ["--pdf-backend", "--out", "--study", "--recording",
                                         "--rig"]),
    "params": (["params"], ["--rig"]),
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_hostile_option_values_fail_in_one_line(command, tmp_path, capsys):
    base, options = COMMANDS[command]
    base = [a.format(miss=tmp_path / "missing", tmp=tmp_path) for a in base]

    n_examples = max(N_EXAMPLES, 4 * len(options))

    @settings(max_examples=n_examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(option=st.sampled_from(options), value=VALUES, joined=st.booleans())
    def run(option, value, joined):
        _check(_argv(base, option, value, joined), capsys)
        ran.append(option)

    ran: list[str] = []
    run()
    assert len(ran) >= n_examples            # 8 commands x >= 45: the >= 300 cases of issue 19
    assert set(ran) == set(options)          # every option was tried


@settings(max_examples=30, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=VALUES, joined=st.booleans())
def test_hostile_seed_and_only_fail_before_any_work(value, joined, capsys):
    """demo and bench would run for minutes on a valid value: only invalid ones here."""
    try:
        seed(value)
        valid_seed = True
    except argparse.ArgumentTypeError:
        valid_seed = False
    if not valid_seed and value != "-h":
        _check(_argv(["demo", "--out", "/nonexistent/demo"], "--seed", value, joined), capsys)
    try:
        selected(value)
        valid_only = True
    except ValueError:
        valid_only = False
    assume(not valid_only)
    _check(_argv(["bench", "--quick"], "--only", value, joined), capsys)


# --- the error names the option as typed, with its range -----------------------------------

@pytest.mark.parametrize(("argv", "expected"), [
    (["simulate", "--dt", "-1e-3", "-o", "x.csv"],
     "bayes-amb simulate: error: argument --dt: value -0.001 out of range: must be > 0 and "
     "<= 0.01 s"),
    (["simulate", "--noise-rms", "-1e-7", "-o", "x.csv"],
     "bayes-amb simulate: error: argument --noise-rms: value -1e-07 out of range: must be "
     ">= 0 m"),
    (["simulate", "--duration", "-2", "-o", "x.csv"],
     "bayes-amb simulate: error: argument --duration: value -2 out of range: must be > 0 and "
     "<= 600 s"),
    (["simulate", "--amplitude", "0", "-o", "x.csv"],
     "bayes-amb simulate: error: argument --amplitude: value 0 out of range: must be > 0 A"),
    (["identify", "r.csv", "--params", "k_By", "--out", "r", "--walkers", "1"],
     "bayes-amb identify: error: argument --walkers: value 1 out of range: must be >= 4"),
    (["identify", "r.csv", "--params", "k_By", "--out", "r", "--steps", "1e3"],
     "bayes-amb identify: error: argument --steps: value '1e3' is not an integer"),
    (["diagnose", "r.csv", "--out", "r", "--max-effects", "-1"],
     "bayes-amb diagnose: error: argument --max-effects: value -1 out of range: must be >= 0"),
    (["study", "s.toml", "--out", "r", "--workers", "0"],
     "bayes-amb study: error: argument --workers: value 0 out of range: must be >= 1"),
    (["controller", "--dt", "-inf"],
     "bayes-amb controller: error: argument --dt: value '-inf' is not a finite number"),
    (["model", "--speed-rpm", "7e4"],
     "bayes-amb model: error: option --speed-rpm: value 70000 out of range: must be in "
     "0..63000 rpm"),
])
def test_errors_name_the_option_and_range(argv, expected, capsys):
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert (out, err) == ("", expected + "\n")


def test_range_text_wording():
    assert range_text(0, 63000, unit="rpm") == "in 0..63000 rpm"
    assert range_text(4) == ">= 4"
    assert range_text(0, 0.01, lo_open=True, unit="s") == "> 0 and <= 0.01 s"
    assert real(0)("1e-3") == 1e-3 and real()("-1E-3") == -1e-3
    assert integer(1)("+3") == 3
    for bad in ("nan", "inf", "-inf", "1e400"):
        with pytest.raises(argparse.ArgumentTypeError, match="not a finite number"):
            real()(bad)


# --- help that answers ----------------------------------------------------------------------

def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _renderings(default: object) -> set[str]:
    """How a default may be written in help: 0.5, 1e-4 (= 0.0001), 2, k_By,c_By."""
    if isinstance(default, float):
        out = {f"{default:g}", repr(default)}
        if default and not math.isnan(default):
            mant, _, exp = f"{default:.0e}".partition("e")
            out.add(f"{mant}e{int(exp)}")
        return out
    return {str(default)}


@pytest.mark.parametrize("command", sorted(_subparsers()))
def test_every_option_states_its_default(command):
    """Each option has help; an option with a default (not a plain flag) names it as
    "default <value>"; an option with choices lists them in its help."""
    p = _subparsers()[command]
    for a in p._actions:
        if not a.option_strings or isinstance(a, argparse._HelpAction):
            continue
        name = a.option_strings[-1]
        assert a.help, f"{command} {name}: no help"
        if isinstance(a, argparse._StoreTrueAction):
            assert "default" in a.help, f"{command} {name}: {a.help!r}"
            continue
        assert "default" in a.help or a.required, f"{command} {name}: {a.help!r}"
        if a.default not in (None, [], False):
            assert any(re.search(rf"default:? {re.escape(r)}\b", a.help)
                       for r in _renderings(a.default)), f"{command} {name}: {a.help!r}"
        for choice in a.choices or ():
            assert str(choice) in a.help, f"{command} {name}: {choice} not in {a.help!r}"


def test_simulate_help_lists_effects_and_parameters():
    from bayes_amb.simulate.effects import EFFECT_DEFAULTS

    text = _subparsers()["simulate"].format_help()
    flat = " ".join(text.split())
    for effect, params in EFFECT_DEFAULTS.items():
        assert f"{effect}:" in flat
        for k in params:
            assert f"{k}=" in flat, k


# --- a recording without excitation is refused, with the reason ---------------------------

def test_recording_without_excitation_is_refused(tmp_path, capsys):
    import csv

    from bayes_amb.io.recording import load_recording, require_excitation

    path = tmp_path / "r.csv"
    assert main(["simulate", "--truth", "reduced", "--dt", "1e-3", "--duration", "0.05",
                 "-o", str(path)]) == 0
    require_excitation(load_recording(path))            # the excited recording passes
    rows = list(csv.reader(path.open(newline="")))
    eta = [i for i, c in enumerate(rows[0]) if c.startswith("eta_")]
    assert len(eta) == 4
    for r in rows[1:]:
        for i in eta:
            r[i] = "0"
    with path.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    capsys.readouterr()
    expected = f"recording {path}: eta is zero on every channel: nothing to identify from"
    for argv in (["identify", str(path), "--params", "k_By", "--map-only", "--out",
                  str(tmp_path / "run")],
                 ["diagnose", str(path), "--out", str(tmp_path / "diag")]):
        assert main(argv) == 2
        out, err = capsys.readouterr()
        assert (out, err) == ("", f"bayes-amb {argv[0]}: error: {expected}\n")
    assert not (tmp_path / "run").exists() and not (tmp_path / "diag").exists()


def _all_parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
                 ) -> list[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """The top-level parser and every (nested) subparser, with the argv that reaches it."""
    out = [(path, parser)]
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, p in a.choices.items():
                out += _all_parsers(p, (*path, name))
    return out


def test_every_parser_formats_its_help():
    """Help text is %-formatted by argparse: a bare '%' in any help string (top-level
    command list included) crashed `bayes-amb --help` with a TypeError."""
    parsers = _all_parsers(build_parser())
    assert len(parsers) > 10 and parsers[0][0] == ()
    for path, p in parsers:
        text = p.format_help()
        assert text.startswith("usage:"), path


def _options(parser: argparse.ArgumentParser) -> list[tuple]:
    """Every option of a parser and its nested subparsers: flags, dest, default, choices."""
    return [(path, tuple(a.option_strings), a.dest, repr(a.default), repr(a.choices))
            for path, p in _all_parsers(parser) for a in p._actions
            if not isinstance(a, argparse._SubParsersAction)]


def test_one_commands_parser_is_that_command_of_the_whole_parser():
    """A run builds only its own command's parser (COMMAND_MODULES): the same options,
    defaults and choices as the command in the parser of every command, and every command
    of that parser has a module."""
    whole = {path[0]: p for path, p in _all_parsers(build_parser()) if len(path) == 1}
    assert set(whole) == set(COMMAND_MODULES)
    for name in COMMAND_MODULES:
        alone = {path[0]: p for path, p in _all_parsers(build_parser(name)) if len(path) == 1}
        assert name in alone
        assert _options(alone[name]) == _options(whole[name]), name


def test_a_light_command_does_not_import_the_heavy_libraries():
    """`bayes-amb params` builds its parser alone: neither python-control nor ArviZ (about
    3 s of imports before) is loaded, and the global --threads value is not taken for the
    command."""
    code = ("import sys; from bayes_amb.cli.main import main; rc = main(['--threads', '1', "
            "'params']); print(rc, 'control' in sys.modules, 'arviz' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "0 False False", out.stdout + out.stderr


def test_the_overview_is_the_whole_parsers_help_without_its_imports():
    """`bayes-amb --help` (and no command, or an unknown one) builds the overview from
    COMMAND_HELP: the same text as the parser of every command, and no command module,
    python-control or ArviZ imported."""
    from bayes_amb.cli.main import overview_parser
    assert overview_parser().format_help() == build_parser().format_help()
    code = ("import sys; from bayes_amb.cli.main import main; rc = main(['--help']); "
            "print(rc, 'control' in sys.modules, 'arviz' in sys.modules, "
            "any(m.endswith('_cmd') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "0 False False False", out.stdout + out.stderr


@pytest.mark.parametrize("argv", [["--help"], ["answers", "--help"], ["rig", "--help"]])
def test_help_exits_zero(argv, capsys):
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert out.startswith("usage: bayes-amb") and err == ""


# --- --rig on the commands that build a model from a recording ------------------------------

def test_rig_option_is_checked_against_the_recording(tmp_path, capsys):
    """The model comes from the rig embedded in the recording; --rig is a check: the same
    rig passes, another is refused in one line naming both, exit 2, nothing written."""
    rec = str(tmp_path / "r.csv")
    assert main(["simulate", "--truth", "reduced", "--dt", "1e-3", "--duration", "0.2",
                 "--set", "k_By=0.3", "-o", rec]) == 0
    capsys.readouterr()
    for argv in (["identify", rec, "--params", "k_By", "--map-only", "--out",
                  str(tmp_path / "id")],
                 ["diagnose", rec, "--params", "k_By", "--out", str(tmp_path / "dg")]):
        assert main([*argv, "--rig", "small_rotor"]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1, err
        assert ("option --rig: rig file small_rotor is not the rig embedded in recording "
                in err and "'small_rotor' against 'reference'" in err
                and "first difference shaft." in err), err
        assert not (tmp_path / argv[-1]).exists()
    assert main(["identify", rec, "--params", "k_By", "--map-only", "--out",
                 str(tmp_path / "id"), "--rig", "reference", "--json"]) == 0
    assert (tmp_path / "id" / "summary.json").is_file()
    capsys.readouterr()
    assert main(["answers", str(tmp_path / "id"), "--rig", "small_rotor"]) == 2
    assert "option --rig" in capsys.readouterr().err


@pytest.mark.parametrize("option", ["--r1-rms", "--amplitude", "--seed"])
def test_an_option_joined_to_a_double_dash_is_refused(option, tmp_path, capsys):
    """``--opt=--``: Python 3.12's argparse drops the value and leaves [] (3.13 calls it
    invalid); either way one line names the option, with status 2."""
    code = main(["simulate", f"{option}=--", "-o", str(tmp_path / "x.csv")])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.splitlines()) == 1 and option in err, err
    assert not (tmp_path / "x.csv").exists()
