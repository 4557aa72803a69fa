"""Run every command of the user guide (README.md and the docs/ pages) as written.

    .venv/bin/python tools/run_guide_commands.py --list              # the commands, per page
    git clone -q . /tmp/guide_clone && (cd /tmp/guide_clone && make demo)
    .venv/bin/python tools/run_guide_commands.py --run [--pages README,plan] [--heavy]

Commands are the lines of code blocks (fenced or indented) and the inline spans that start
with `bayes-amb`, `make`, `python`, `PYTHONPATH=`, `.venv/bin/`, `source` or `studies/*.sh`,
backslash continuations joined as bash joins them (a `for ... done` loop is one command;
`P=...` lines are prefixed to the page's later commands). Lines such as `bayes-amb
identify: error: ...` are outputs the page shows: INSTANCE gives the command that should
print them. A synopsis (`NAME.csv`, `DIR`, `[--rig FILE]`, `...`) or a bare command name
runs as the concrete instance in INSTANCE ("=TEXT": the run of TEXT elsewhere). Commands
in NOT_RUN are too long to run here: their options are checked against `--help` instead,
unless --long is given (then they run as written too, but for those whose inputs are the
records of another long run: "needs ...").

Each page runs in OUT/<page>/ in page order (SETUP copies or makes what it needs first: the
user's own files come from studies/own_rig_scenario.sh); README, getting_started and any
command that needs the repository (`make`, `PYTHONPATH=.`, `studies/`, `.venv/bin/`,
`reports/demo/`, `tests/`) run in CLONE, a fresh clone where `make demo` made .venv.
BIN (default CLONE/.venv/bin) leads PATH, so `python` is the package's Python. Results go
to OUT/results.json (a command already run in the same folder is not run again unless
--force) and the table to OUT/table.md.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md"] + [f"docs/{p}.md" for p in (
    "getting_started guide your_rig own_data identify diagnose answers plan studies "
    "honest_numbers benchmarks rig_file results layout validation method").split()]
START = re.compile(r"^([A-Z_]+=\S+\s+)*(bayes-amb(\s|$)|make\s|python\s|PYTHONPATH=|\.venv/bin/|"
                   r"studies/\S+\.sh|source\s+\S*activate|for .*; do)|^[A-Z]+=\S+(\s+#.*)?$")
OUTPUT = re.compile(r"^bayes-amb(\s[\w-]+)?: ")          # a message the page shows
PLACEHOLDER = re.compile(r"\[|\.\.\.|\b(NAME|DIR|RUN_DIR|FILE|REC|ROTOR|BEFORE|AFTER|N|S|CH|SD|"
                         r"COMMAND|BIN_DIR|WORK_DIR|RPM)\b")
REPO = re.compile(r"^make\s|PYTHONPATH=\.|studies/|\.venv/bin/|reports/demo/|tests/|benchmarks\.|"
                  r"bayes-amb bench")
CLONE_PAGES = ("README", "getting_started", "studies")
SCENARIO = "bash $CLONE/studies/own_rig_scenario.sh $BIN $OUT/own_rig"
HELP = "{} --help"                                       # a bare command name: its --help
# (page, command as written) -> what is run instead
INSTANCE = {
    ("README", ".venv/bin/bayes-amb"): ".venv/bin/bayes-amb --help",
    ("getting_started", "bayes-amb --threads N COMMAND"): "bayes-amb --threads 1 params",
    ("getting_started", "bayes-amb demo --out reports/demo"): "=make demo",
    ("getting_started", "bayes-amb: compiling kernels once (about 30 s; cached for later runs) ..."):
        "rm -rf /tmp/gr_cache && NUMBA_CACHE_DIR=/tmp/gr_cache bayes-amb identify paper.csv "
        "--params k_By --map-only --out /tmp/gr_cache_run",
    ("guide", "bayes-amb model [--rig FILE] [--speed-rpm N] [--json]"):
        "bayes-amb model --rig small_rotor --speed-rpm 24000 --json",
    ("guide", "bayes-amb params [--json]"): "bayes-amb params --json",
    ("guide", "bayes-amb controller [--dt S] [--export FILE] [--json]"):
        "bayes-amb controller --dt 1e-4 --export ctrl.json --json",
    ("guide", "bayes-amb simulate ... -o NAME.csv"): "bayes-amb simulate --duration 0.5 -o name.csv",
    ("guide", "bayes-amb identify NAME.csv --params k_By,c_By [--rig FILE] [--[no-]initial-state] "
              "--out DIR"): "bayes-amb identify name.csv --params k_By,c_By --rig reference "
                            "--no-initial-state --out runs/name",
    ("guide", "bayes-amb diagnose NAME.csv [--params k_By,c_By] [--rig FILE] --out DIR"):
        "bayes-amb diagnose name.csv --params k_By,c_By --rig reference --out runs/name",
    ("guide", "bayes-amb study studies/NAME.toml --out DIR"):
        "=bayes-amb study studies/noise.toml --out runs/noise # process pool (2 workers)",
    ("guide", "bayes-amb bench [--json] [--quick]"): "bayes-amb bench --json --quick",
    ("guide", "bayes-amb report RUN_DIR [--study DIR] [--out DIR]"):
        "bayes-amb report runs/name --study $CLONE/runs/noise --out report_name",
    ("guide", "bayes-amb plan [--duration S] [--channels CH] [--target NAME=SD] [--noise-from "
              "REC.csv [--[no-]initial-state]]"):
        "bayes-amb plan --duration 1 --channels By --noise-from name.csv --no-initial-state",
    ("guide", "bayes-amb demo [--out DIR]"): "=make demo",
    ("your_rig", "bayes-amb simulate --port r2"): "bayes-amb simulate --port r2 --duration 0.2 -o r2.csv",
    ("your_rig", "bayes-amb demo --import-formats --out DIR"):
        "bayes-amb demo --import-formats --out import_dir && ls import_dir/*.toml",
    ("your_rig", "studies/own_rig_scenario.sh BIN_DIR WORK_DIR"): "=" + SCENARIO,
    ("own_data", "bayes-amb rig from-ross ROTOR.toml --speed-rpm RPM -o my_rig.toml"):
        "bayes-amb rig from-ross my_rotor.toml --speed-rpm 18000 -o my_rig_ross.toml",
    ("own_data", "bayes-amb import-controller --from-ross"):
        "bayes-amb import-controller --from-ross my_rotor.toml --rig my_rig.toml --dt 1e-4 "
        "-o ctrl_ross.json",
    ("own_data", "bayes-amb identify"):
        "bayes-amb identify reports/import/rec_tdms.csv --params k_By,c_By --out runs/tdms",
    ("identify", "bayes-amb compare runs/joint_last_month runs/joint # records over time"):
        "bayes-amb compare runs/joint_mcmc runs/joint",
    ("identify", "bayes-amb compare BEFORE AFTER"): "=bayes-amb compare runs/joint_mcmc runs/joint",
    ("identify", "bayes-amb report DIR"): "bayes-amb report runs/joint",
    ("diagnose", "bayes-amb report RUN_DIR"):      # RUN_DIR: an identification's, diagnosed into
        "bayes-amb identify realistic.csv --params k_By --map-only --out runs/diag "
        "&& bayes-amb report runs/diag",
    ("diagnose", ".venv/bin/python -m benchmarks.foreign.benchmark --out runs/foreign [--per-kind 4] "
                 "[--kinds control,actuator_lag,...] # resumable"):
        ".venv/bin/python -m benchmarks.foreign.benchmark --out runs/foreign1 --per-kind 1 "
        "--kinds actuator_lag",
    ("answers", "bayes-amb report"): "bayes-amb report runs/paper",
    ("studies", "bayes-amb study: interrupted by SIGINT: 4 of 9 replicates are saved in "
                "runs/noise/results.jsonl; resume with: bayes-amb study studies/noise.toml --out "
                "runs/noise --resume"):
        "timeout -s INT 25 bayes-amb study studies/noise.toml --out runs/noise_int",
    ("studies", "bayes-amb simulate: error: argument --dt: value -0.001 out of range: must be > 0 "
                "and <= 0.01 s"): "bayes-amb simulate --dt -1e-3 -o x.csv",
    ("studies", "bayes-amb model: error: option --speed-rpm: value 70000 out of range: must be in "
                "0..63000 rpm"): "bayes-amb model --speed-rpm 70000",
    ("studies", "bayes-amb identify: error: argument --walkers: value 2 out of range: must be >= 4"):
        "bayes-amb identify paper.csv --walkers 2 --out runs/w",
    ("studies", "bayes-amb simulate: error: /nonexistent_dir/x.csv: No such file or directory"):
        "bayes-amb simulate --duration 0.1 -o /nonexistent_dir/x.csv",
    ("rig_file", "bayes-amb identify: error: option --rig: rig file small_rotor is not the rig "
                 "embedded in recording r.csv ('small_rotor' against 'reference'); first difference "
                 "shaft.youngs_modulus: 205000000000.0 against 211000000000.0 (file against "
                 "recording)"): "bayes-amb identify r.csv --params k_By --rig small_rotor --out runs/r",
    ("results", "python -m bayes_amb.results.schema"):
        "python -m bayes_amb.results.schema > /tmp/results_now.md && diff -q /tmp/results_now.md "
        "$CLONE/docs/results.md",
}
MENTIONS = {"bayes-amb", "bayes-amb import", "bayes-amb import-controller", "bayes-amb answers",
            "bayes-amb report", "bayes-amb study", "bayes-amb diagnose", "bayes-amb identify"}
NOT_RUN = {      # (page, command start) -> why; the options are checked against --help
    ("diagnose", "PYTHONPATH=. python studies/nonlinear_foreign.py"): "10-24 records diagnosed, ~30-60 min",
    ("diagnose", ".venv/bin/python -m benchmarks.foreign.benchmark --out runs/foreign --per-kind 4"):
        "78 records diagnosed, ~1.5 h on 2 cores",
    ("diagnose", "bayes-amb study studies/concealed.toml"): "55 diagnoses, ~4 min",
    ("identify", "PYTHONPATH=. python studies/coloured_noise.py"): "50 foreign records, ~30-60 min",
    ("plan", "PYTHONPATH=. python studies/plan_check.py"): "400 (100) records identified, ~40 min",
    ("plan", "PYTHONPATH=. python studies/plan_detect.py"): "7 effects, a diagnosis each, ~10 min",
    ("plan", "PYTHONPATH=. python studies/"): "needs the 160-200 foreign records of runs/cf50, "
                                              "runs/oc50b or runs/ctl80 (hours)",
    ("honest_numbers", "PYTHONPATH=. python studies/noise_check_foreign.py"):
        "needs runs/cf50 or runs/f31 (133-160 foreign records, hours)",
    ("honest_numbers", ".venv/bin/python -m benchmarks.foreign.benchmark"):
        "133 (or 8) foreign records identified and diagnosed, ~2 h (~15 min)",
    ("studies", "bayes-amb study studies/sbc.toml"): "200 posteriors, ~20 min (the page's own figure)",
    ("identify", "PYTHONPATH=. python studies/joint_foreign.py"): "16-20 groups of 3 foreign records, ~30-60 min",
    ("identify", "PYTHONPATH=. python studies/records_foreign.py"): "8-18 groups of 3 records diagnosed, ~30-60 min",
    ("honest_numbers", "PYTHONPATH=. python studies/amplitude_scan.py"): "needs runs/f27 (111 foreign records)",
    ("README", "make test"): "",
}
HEAVY = {"make test"}
LONG = False            # --long: the NOT_RUN commands run as written too (main sets it)
SETUP = {   # run in the page's folder before the page (or before PAGE:LINE)
    "README": [f"test -f $OUT/own_rig/my_rotor.toml || {SCENARIO}",
               "cp $OUT/own_rig/my_rotor.toml $CLONE/"],
    "README:92": ["bayes-amb simulate --rig my_rig.toml --controller ctrl.json --port r2 --set k_By=0.3 "
                  "--set c_By=0.2 --noise-rms 2e-7 --r2-rms 0.02 --duration 2 --seed 5 -o sim.csv "
                  "&& python $OUT/own_rig/to_daq.py && sed -i 's/18000.0/3000.0/' run17.toml "
                  "&& mv run17.mat daq_file.mat && mv run17.toml channels.toml"],
    "guide": [],
    "your_rig": ["cp $CLONE/bayes_amb/rig/data/small_rotor.toml my_rig.toml",
                 "cp $OUT/own_rig/{my_rotor.toml,K.mat,run17.mat,run17.toml} ."],
    "your_rig:94": ["cp $OUT/own_rig/my_rig.toml ."],
    "your_rig:122": ["cp ctrl.json ctrl_pid.json"],
    "your_rig:192": ["cp ctrl_pid.json ctrl.json && cp $OUT/own_rig/my_rig.toml ."],
    "own_data": ["cp $OUT/own_rig/{my_rotor.toml,my_rig.toml,ctrl.json,run17.mat,run17.toml} .",
                 "python -c 'import scipy.io; from bayes_amb.rig import load_rig; from bayes_amb."
                 "control.pid import PIDSettings, continuous_pid, pid_gains; A, B, C, D = "
                 "continuous_pid(pid_gains(load_rig(), PIDSettings())); scipy.io.savemat(\"K.mat\", "
                 "dict(A=A, B=B, C=-C, D=-D, Ts=0.0))'"],
    "diagnose": ["cp $OUT/guide/realistic.{csv,json} ."],
    "answers": ["mkdir -p runs && cp -r $CLONE/runs/paper runs/"],
    "plan": ["cp $OUT/guide/realistic.csv old_run.csv && cp $OUT/guide/realistic.json old_run.json"],
    "rig_file": ["cp $OUT/guide/name.csv r.csv && cp $OUT/guide/name.json r.json"],
}


def extract(page: str) -> list[dict]:
    """The page's commands in order: dicts with page, line, kind (block/inline), text."""
    lines = (ROOT / page).read_text(encoding="utf-8").splitlines()
    found, fenced, lang, prose, i = [], False, "", [], 0
    while i < len(lines):
        raw = lines[i]
        if raw.lstrip().startswith("```"):
            fenced, lang = not fenced, raw.strip()[3:]
            i += 1
            continue
        indented = not fenced and raw.startswith("    ") and raw.strip() and (
            not lines[i - 1].strip() or lines[i - 1].startswith("    "))
        if (fenced and lang in ("", "bash", "sh")) or indented:
            text, pad, start = raw.strip(), len(raw) - len(raw.lstrip()), i
            if START.match(text) or OUTPUT.match(text):
                while text.endswith("\\") and i + 1 < len(lines):   # bash drops backslash-newline
                    i += 1
                    text = text[:-1] + lines[i][pad:]
                if text.startswith("for "):
                    while not lines[i].strip().startswith("done") and i + 1 < len(lines):
                        i += 1
                        text += "\n" + lines[i].strip()
                text = "\n".join(" ".join(x.split()) for x in text.split("\n"))
                found.append(dict(page=page, line=start + 1, kind="block", text=text))
        elif not fenced:
            prose.append((i + 1, raw))
        i += 1
    joined, starts = "", []                              # inline spans, across line breaks
    for n, raw in prose:
        starts.append((len(joined), n))
        joined += raw + "\n"
    for m in re.finditer(r"`([^`]+)`", joined):
        text = " ".join(m.group(1).split())
        if (START.match(text) and not re.match(r"^[A-Z_]+=\S+$", text)) or OUTPUT.match(text):
            found.append(dict(page=page, line=max(n for p, n in starts if p <= m.start()),
                              kind="inline", text=text))
    return sorted(found, key=lambda c: c["line"])


def classify(c: dict) -> None:
    stem, text = Path(c["page"]).stem, c["text"]
    nr = [why for (p, s), why in NOT_RUN.items() if p == stem and text.startswith(s)]
    c["status"], c["run"] = "as written", text
    if re.match(r"^[A-Z]+=\S+(\s+#.*)?$", text):
        c["status"], c["run"] = "variable", ""
    elif (stem, text) in INSTANCE:
        c["status"], c["run"] = "instance", INSTANCE[(stem, text)]
    elif text in MENTIONS:
        c["status"], c["run"] = "command name: its --help", HELP.format(text)
    elif nr and text.split(" #")[0] not in HEAVY and LONG and not nr[0].startswith("needs"):
        c["status"] = "as written (long: " + nr[0] + ")"
    elif nr and text.split(" #")[0] not in HEAVY:
        c["status"], c["run"] = "not run: " + nr[0], optcheck(text)
    elif OUTPUT.match(text):
        c["status"], c["run"] = "output shown, no command", ""
    elif c["kind"] == "inline" and PLACEHOLDER.search(text):
        c["status"], c["run"] = "synopsis, no instance", ""
    if stem in ("README", "getting_started", "answers") and text.startswith("make test") \
            and c["kind"] == "inline" or (stem != "README" and text.startswith("make test")):
        c["status"], c["run"] = "instance", "=make test # the same set-up, then the test suite in 2 processes"


def optcheck(text: str) -> str:
    """A shell line that fails unless every --option of TEXT is in its program's --help."""
    m = re.match(r"^(.*?(?:python\s+(?:-m\s+\S+|\S+\.py)|bayes-amb(?:\s+[a-z][\w-]*(?=\s|$))+))", text)
    opts = sorted(set(re.findall(r"(?<!\S)(--[\w-]+)", text.split(" #")[0])))
    checks = " && ".join(f"grep -q -- '{o}\\b' /tmp/gr_help.txt || echo 'missing {o}' >&2" for o in opts)
    help_ = f"{m.group(1)} --help > /tmp/gr_help.txt"
    if not opts and m.group(1).endswith(".py"):                # no options: it would run
        return m.group(1).replace(" python ", " python -m py_compile ")
    return f"{help_} && ! ( {checks} ) 2>&1 | grep . >&2" if opts else help_


def bare(cmd: str) -> str:
    return cmd.split(" # ")[0].strip()


def cwd_of(stem: str, run: str, args) -> str:
    return args.clone if stem in CLONE_PAGES or REPO.search(run) else str(Path(args.out) / stem)


def shell(cmd: str, cwd: str, env: dict, timeout: float) -> dict:
    t0 = time.time()
    try:
        p = subprocess.run(["bash", "-c", cmd], cwd=cwd, env=env, capture_output=True,
                           text=True, timeout=timeout)
        rc, out, err = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as e:
        rc, out, err = "timeout", str(e.stdout or ""), str(e.stderr or "")
    return dict(rc=rc, seconds=round(time.time() - t0, 1), cwd=cwd, stdout=out[-6000:],
                stderr=err[-6000:])


def run_page(page: str, cmds: list[dict], args, results: dict) -> None:
    stem = Path(page).stem
    here = Path(args.out) / stem
    here.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PATH=f"{args.bin}:{os.environ['PATH']}", BIN=args.bin,
               OUT=str(Path(args.out).resolve()), CLONE=args.clone, PYTHONUNBUFFERED="1")
    env.pop("VIRTUAL_ENV", None)
    store = Path(args.out) / "results.json"
    variables = []

    def go(cmd: str, cwd: str) -> None:
        key = f"{cwd} :: {bare(cmd)}"
        if key in results and not args.force:
            return
        print(f"[{stem}] {cmd}", flush=True)
        results[key] = shell("\n".join([*variables, cmd]), cwd, env, args.timeout)
        store.write_text(json.dumps(results, indent=1))
        print(f"    rc {results[key]['rc']}, {results[key]['seconds']} s", flush=True)

    for s in SETUP.get(stem, []):
        go(s, cwd_of(stem, "", args))
    for c in cmds:
        if c["status"] == "variable":
            variables.append(bare(c["text"]))
        if not c["run"] or c["run"].startswith("=") or (
                c["text"].split(" #")[0] in HEAVY and not args.heavy) or (
                args.match and not re.search(args.match, c["text"])):
            continue
        for s in SETUP.get(f"{stem}:{c['line']}", []):
            go(s, cwd_of(stem, "", args))
        go(c["run"], cwd_of(stem, c["run"], args))


def table(all_cmds: list[dict], results: dict, args) -> str:
    rows = ["| page | line | command | run as | rc | s | last stderr line |",
            "|---|---|---|---|---|---|---|"]
    cell = lambda s: s.replace("|", "\\|").replace("\n", "; ")  # noqa: E731
    for c in all_cmds:
        stem, run = Path(c["page"]).stem, c["run"]
        ref = run[1:] if run.startswith("=") else None
        hits = [r for k, r in results.items() if (ref and k.endswith(" :: " + bare(ref)))
                or k == f"{cwd_of(stem, run, args)} :: {bare(run)}"] if run else []
        r = hits[0] if hits else None
        errs = [x for x in (r["stderr"] if r else "").splitlines() if x.strip()
                and not re.search(r"REFPROP|warn|^\s", x, flags=re.I)]
        last = errs[-1][:140] if errs and r["rc"] != 0 else ""
        run_as = c["status"] if run == c["text"] else f"{c['status']}: `{cell(run)}`"
        rows.append(f"| {stem} | {c['line']} | `{cell(c['text'])}` | {run_as} | "
                    f"{r['rc'] if r else ''} | {r['seconds'] if r else ''} | {cell(last)} |")
    return "\n".join(rows) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="print the commands per page")
    ap.add_argument("--run", action="store_true", help="run them")
    ap.add_argument("--pages", default="", help="comma-separated page stems (default: all)")
    ap.add_argument("--out", default="/tmp/guide_run")
    ap.add_argument("--clone", default="/tmp/guide_clone")
    ap.add_argument("--bin", default="", help="default CLONE/.venv/bin")
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--heavy", action="store_true", help="also run `make test` and the like")
    ap.add_argument("--force", action="store_true", help="run again what was run")
    ap.add_argument("--match", default="",
                    help="run only the commands whose text matches this regular expression "
                         "(the pages' set-up still runs)")
    ap.add_argument("--long", action="store_true",
                    help="also run the long commands (NOT_RUN) as written, but for those that "
                         "need another long run's records")
    args = ap.parse_args()
    global LONG
    LONG = args.long
    args.bin = args.bin or f"{args.clone}/.venv/bin"
    wanted = set(filter(None, args.pages.split(",")))
    all_cmds = []
    for page in PAGES:
        cmds = extract(page)
        for c in cmds:
            classify(c)
        all_cmds += cmds
        if args.list and (not wanted or Path(page).stem in wanted):
            print(f"\n## {page}")
            for c in cmds:
                print(f"{c['line']:4d} {c['kind']:6s} {c['status'][:34]:34s} "
                      f"{c['text'].replace(chr(10), '; ')}"
                      + (f"\n{'':46s}-> {c['run']}" if c["run"] != c["text"] and c["run"] else ""))
    store = Path(args.out) / "results.json"
    results = json.loads(store.read_text()) if store.exists() else {}
    if args.run:
        for page in PAGES:
            if not wanted or Path(page).stem in wanted:
                run_page(page, [c for c in all_cmds if c["page"] == page], args, results)
    if results:
        (Path(args.out) / "table.md").write_text(table(all_cmds, results, args))
    listed = [c for c in all_cmds if c["status"] != "variable"]
    print(f"{len(listed)} commands listed on {len({c['page'] for c in listed})} pages")


if __name__ == "__main__":
    main()
