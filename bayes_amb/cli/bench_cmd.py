"""`bayes-amb bench`: the benchmarks, each against its baseline run side by side."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from bayes_amb.bench import BENCHMARKS, DEFAULT_BENCHMARKS, report, run_benchmarks
from bayes_amb.cli.common import emit
from bayes_amb.errors import BayesAmbError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run the benchmarks (ratios against baselines)",
                       description="Time the fast paths against their baselines in the same "
                       "process and print both and the ratio (speedup = baseline / ours). "
                       "Benchmarks: " + ", ".join(BENCHMARKS) + ". The default set ("
                       + ", ".join(DEFAULT_BENCHMARKS) + ") takes about 1.5 minutes; "
                       "'--only cli' (a README command in subprocesses with and without "
                       "OPENBLAS_NUM_THREADS=1) about 2; '--only study' (1000-replicate study "
                       "throughput) about 5; '--only plan' (the plan against one identification) "
                       "under 1; '--only rigs' (ROSS's test rig against the reference rig, "
                       "the same case) about 4; '--only answers' (the engineering answers, "
                       "one thread against the pool) about 2. BLAS threads are limited by "
                       "the tool itself (--threads, BAYES_AMB_THREADS).")
    p.add_argument("--only", default=None, metavar="NAME,...",
                   help="comma-separated benchmarks to run, of " + ", ".join(BENCHMARKS)
                   + " (default: all but cli, study)")
    p.add_argument("--quick", action="store_true",
                   help="smoke-test sizes (seconds; the figures are not representative; "
                   "default: full sizes)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.set_defaults(func=run)


def selected(only: str | None) -> list[str]:
    """Benchmark names of --only in BENCHMARKS order (the default set when None)."""
    if only is None:
        return list(DEFAULT_BENCHMARKS)
    names = [n.strip() for n in only.split(",") if n.strip()]
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown or not names:
        raise BayesAmbError(f"option --only: unknown benchmark {(unknown or [only])[0]!r}; "
                            f"known: {', '.join(BENCHMARKS)}")
    return [n for n in BENCHMARKS if n in names]


def _num(v: float | None, spec: str) -> str:
    """Format v, or "-" where the run gave no finite value (None)."""
    return "-" if v is None else format(v, spec)


def _us(v: float) -> str:
    return f"{v:.0f} us" if v < 1e4 else f"{v / 1e3:.1f} ms"


def _rows(d: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    rows = []
    if "likelihood" in d:
        r = d["likelihood"]
        rows.append(("likelihood", f"{_us(r['likelihood_us'])}/eval",
                     f"{_us(r['baseline_us'])}/eval", f"{r['speedup']:.1f}x"))
    if "posterior" in d:
        r = d["posterior"]
        rows.append(("posterior", f"{r['posterior_s']:.1f} s sampling ({r['wall_s']:.1f} total)",
                     f"~{r['baseline_posterior_s_estimated']:.0f} s (estimated)",
                     f"~{r['speedup_estimated']:.0f}x"))
    if "simulate" in d:
        r = d["simulate"]
        rows.append(("simulate", f"{r['simulate_s']:.3f} s", f"{r['baseline_s']:.3f} s",
                     f"{r['speedup']:.2f}x"))
    if "map" in d:
        lb, nm = d["map"]["lbfgs"], d["map"]["nelder_mead"]
        rows.append(("map", f"{lb['wall_s']:.2f} s, {lb['n_evals']} evals",
                     f"{nm['wall_s']:.2f} s, {nm['n_evals']} evals",
                     f"{d['map']['speedup']:.1f}x"))
    if "diagnose" in d:
        r = d["diagnose"]
        rows.append(("diagnose", f"{r['cpu_s']:.1f} s CPU ({r['wall_s']:.1f} s wall)",
                     f"{r['full_screen_cpu_s']:.1f} s CPU, full screens",
                     f"{r['speedup']:.1f}x"))
        if r.get("screens_cpu_s") is not None:
            rows.append(("nonlinear screens", f"{r['screens_cpu_s']:.2f} s CPU within it",
                         f"{r['cpu_s'] - r['screens_cpu_s']:.1f} s CPU for the rest",
                         f"+{100 * r['screens_rise']:.1f} % (target "
                         f"<= {100 * r['target_screens_rise']:.0f} %)"))
    if "cli" in d:
        r = d["cli"]
        rows.append(("cli", f"{r['default_s']:.1f} s without the variable",
                     f"{r['variable_s']:.1f} s with it", f"{r['ratio']:.2f}"))
    if "plan" in d:
        r = d["plan"]
        rows.append(("plan", f"{r['plan_s']:.2f} s (target {r['requirement_s']:g} s)",
                     f"{r['study_s']:.0f} s: 50 identifications of {r['identify_s']:.1f} s",
                     f"{r['speedup']:.0f}x"))
    if "transient" in d:
        r = d["transient"]
        rows.append(("transient", f"{r['fitted_s']:.1f} s, start transient fitted",
                     f"{r['noise_s']:.1f} s, taken as noise", f"{1 / r['cost']:.2f}x"))
    if "rigs" in d:
        r = d["rigs"]
        rows.append(("rigs", f"test rig: diagnose {r['test_rig']['diagnose_s']:.0f} s, "
                     f"{r['test_rig']['states']} states",
                     f"reference rig: {r['reference']['diagnose_s']:.0f} s, "
                     f"{r['reference']['states']} states",
                     f"{1 / r['ratios']['diagnose_s']:.2f}x"))
    if "answers" in d:
        r = d["answers"]["test_rig"]
        rows.append(("answers", f"test rig: {r['pool_s']:.1f} s on {r['pool_threads']} "
                     "threads", f"{r['serial_s']:.1f} s on one", f"{r['speedup']:.2f}x"))
    if "study" in d:
        r = d["study"]
        rows.append(("study", f"{r['n_replicates']} replicates in {r['wall_s']:.0f} s "
                     f"({r['workers']} workers)", "(no baseline)",
                     f"{r['s_per_1000'] / 60:.1f} min/1000"))
    return rows


def _details(d: dict[str, Any]) -> list[str]:
    out = []
    if "likelihood" in d:
        r = d["likelihood"]
        cpu = r["cpu_us"]
        out.append(f"likelihood: {r['n_params']} parameters, {r['n_samples']} samples x 4, "
                   f"batch {r['batch']}; baseline forced_response + iid Gaussian; residual "
                   f"DFT check {r['residual_rel_err']:.1e}; target {r['target_us']:g} us")
        out.append(f"  side by side, per evaluation, wall (CPU): compiled modal form (default)"
                   f" {r['likelihood_us']:.1f} us ({cpu['numba']:.1f}); previous path "
                   f"(BAYES_AMB_KERNEL=lapack) {r['previous_path_us']:.1f} us "
                   f"({cpu['lapack']:.1f}) = {r['previous_speedup']:.2f}x "
                   f"({r['cpu_previous_speedup']:.2f}x CPU); numpy path (BAYES_AMB_KERNEL="
                   f"numpy) {r['numpy_path_us']:.1f} us ({cpu['numpy']:.1f}) = "
                   f"{r['kernel_speedup']:.2f}x; log posterior checks against the numpy path "
                   f"{r['kernel_rel_err']:.1e} and {r['previous_rel_err']:.1e}")
    if "posterior" in d:
        r = d["posterior"]
        out.append(f"posterior: {r['n_params']} parameters, {r['n_samples']} samples, "
                   f"{'converged' if r['converged'] else 'NOT converged'}"
                   f"{' (fixed steps)' if r['fixed_steps'] else ''}, {r['steps']} steps x "
                   f"{r['walkers']} walkers = {_num(r['n_tau'], '.0f')} tau, max R-hat "
                   f"{_num(r['max_r_hat'], '.3f')}, min ESS {_num(r['min_ess'], '.0f')}, "
                   f"{_num(r['ess_per_s'], '.1f')} ESS/s; {r['likelihood_evals']} evaluations"
                   f" x {_us(r['baseline_eval_us'])} naive = the estimated baseline")
        de = r["de"]
        out.append(f"  side by side (issue 16, target {r['target_s']:g} s): Laplace mixture "
                   f"{r['cpu_s']:.1f} s CPU / {r['wall_s']:.1f} s wall, {r['steps']} steps; "
                   f"differential evolution alone (moves=\"de\", before) {de['cpu_s']:.1f} s "
                   f"CPU / {de['wall_s']:.1f} s wall, {de['steps']} steps, "
                   f"{de['likelihood_evals']} evaluations, "
                   f"{'converged' if de['converged'] else 'NOT converged'}, max R-hat "
                   f"{_num(de['max_r_hat'], '.3f')}, min ESS {_num(de['min_ess'], '.0f')}: "
                   f"{r['cpu_speedup']:.1f}x less CPU, {r['wall_speedup']:.1f}x less wall")
        out.append(f"  {'param':<6} {'true':>7} {'mean':>8} {'sd':>7} {'bias/sd':>8} "
                   f"{'R-hat':>6} {'ESS':>6}   {'mean':>8} {'sd':>7} (before)")
        for p, q in zip(r["parameters"], de["parameters"], strict=True):
            z = p["bias"] / p["sd"] if p["sd"] else None
            out.append(f"  {p['name']:<6} {p['true']:>7.3f} {p['mean']:>8.4f} {p['sd']:>7.4f} "
                       f"{_num(z, '>+8.2f')} {_num(p['r_hat'], '>6.3f')} "
                       f"{_num(p['ess_bulk'], '>6.0f')}   {q['mean']:>8.4f} {q['sd']:>7.4f}")
    if "simulate" in d:
        r = d["simulate"]
        ok = "met" if r["simulate_s"] < r["requirement_s"] else "NOT met"
        out.append(f"simulate: {r['n_states']}-state full truth, {r['n_samples']} samples; "
                   f"under {r['requirement_s']:g} s: {ok}; y check {r['max_rel_diff']:.1e}")
    if "map" in d:
        m = d["map"]
        out.append("map: paper's case (k_By = 0.5); " + "; ".join(
            f"{v['method']} theta {v['theta']:.6f} (error {v['abs_error']:.1e}, log post "
            f"{v['log_post']:.1f})" for v in (m["lbfgs"], m["nelder_mead"])))
    if "diagnose" in d:
        r = d["diagnose"]
        out.append(f"diagnose: {r['duration_s']:g} s at 10 kHz ({r['n_samples']} samples), "
                   f"hidden 2.5 kHz lag, default options (eight coefficients); verdict "
                   f"{r['verdict']!r}, named {', '.join(r['effects']) or 'nothing'}; "
                   f"baseline: the same diagnosis with every candidate screened fully (no "
                   f"pre-screening), same verdict and names; target median "
                   f"{r['target_median_s']:g} s CPU over the foreign benchmark")
    if "transient" in d:
        r = d["transient"]
        sds = ", ".join(f"{k} {v:.2f}" for k, v in r["sd_ratio"].items())
        out.append(f"transient: a record that starts mid-operation (cut 0.3 s after its "
                   f"start), {len(r['sd_ratio'])} coefficients, the user's defaults; fitted "
                   f"by the data check: {r['fitted_by_default']}; sampling "
                   f"{_sampled(r['posterior_s_fitted'], r['evals_fitted'])} against "
                   f"{_sampled(r['posterior_s_noise'], r['evals_noise'])}; "
                   f"{'converged' if r['converged'] else 'NOT converged'}"
                   f"; sd fitted / as noise: {sds}")
    if "rigs" in d:
        r = d["rigs"]
        out.append(f"rigs: the same case on ROSS's test rig (its own controllers, r2) and the "
                   f"reference rig (eta), {r['duration_s']:g} s of the full FE truth; test "
                   f"rig / reference (target diagnose <= {r['target_diagnose_ratio']:g}x):")
        for k in ("model_s", "eval_us", "identify_s", "diagnose_s", "diagnose_cpu_s"):
            unit = "us" if k.endswith("_us") else "s"
            out.append(f"  {k.rsplit('_', 1)[0]:<13} "
                       f"{r['test_rig'][k]:>9.2f} {unit}  {r['reference'][k]:>9.2f} {unit}  "
                       f"{r['ratios'][k]:.2f}x")
        for side in ("test_rig", "reference"):
            s = r[side]
            out.append(f"  {s['rig']}: {s['states']} states, valid to {s['validity_hz']:.0f}"
                       f" Hz; covered 8 coefficients: identify {s['covered_identify']}/8, "
                       f"diagnose {s['covered_diagnose']}/8 ({s['verdict']})")
    if "answers" in d:
        out.append("answers: the engineering answers (full FE model, posterior draws at "
                   "every speed), one thread against the pool:")
        for side in ("test_rig", "reference"):
            a = d["answers"][side]
            out.append(f"  {a['rig']}: {a['draws']} draws x {a['speeds']} speeds, "
                       f"{a['serial_s']:.1f} s on one thread, {a['pool_s']:.1f} s on "
                       f"{a['pool_threads']} ({a['speedup']:.2f}x); the same answers: "
                       f"{a['identical']}")
    if "cli" in d:
        r = d["cli"]
        out.append(f"cli: `{r['command']}`, {r['repeats']} runs per environment, interleaved;"
                   f" ratio = without / with OPENBLAS_NUM_THREADS=1 (target <= "
                   f"{r['target_ratio']:g}); with BAYES_AMB_THREADS=0 (no protection, as "
                   f"before issue 16) {r['unprotected_s']:.1f} s = {r['unprotected_ratio']:.2f}"
                   f"x; runs " + ", ".join(f"{k} " + "/".join(f"{t:.1f}" for t in v)
                                           for k, v in r["runs_s"].items()))
    return out


def format_text(d: dict[str, Any]) -> str:
    """The human-readable table of a `bench --json` dict."""
    env = d["environment"]
    head = (f"bayes-amb bench{' --quick' if d['quick'] else ''}: speedup = baseline / ours "
            f"(OPENBLAS_NUM_THREADS={env['OPENBLAS_NUM_THREADS']}, BAYES_AMB_THREADS="
            f"{env.get('BAYES_AMB_THREADS')}, {env['cpu_count']} CPUs)")
    rows = [("benchmark", "ours", "baseline", "speedup"), *_rows(d)]
    w = [max(len(r[i]) for r in rows) for i in range(4)]
    lines = [head, ""] + [f"{a:<{w[0]}}  {b:<{w[1]}}  {c:<{w[2]}}  {s:>{w[3]}}"
                          for a, b, c, s in rows]
    return "\n".join([*lines, "", *_details(d)])


def run(args: argparse.Namespace) -> int:
    results = {}
    for n in selected(args.only):
        if not args.json:
            sys.stderr.write(f"running {n}{' (quick)' if args.quick else ''} ...\n")
        results.update(run_benchmarks([n], quick=args.quick))
    data = report(results, args.quick)
    emit(data, format_text(data), args.json)
    return 0


def _sampled(wall_s: float, evals: int) -> str:
    """A run's sampling time and evaluations, or that it was not sampled (evals 0)."""
    return f"{wall_s:.1f} s ({evals} evaluations)" if evals else "not sampled"
