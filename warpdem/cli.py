"""Command line: ``warpdem study | analyze | diagnose | run | scene new | verify | bench | audit``."""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings

from .errors import ExitCode, InputError, classify


def _plain_table(title, columns, rows) -> None:
    """Columns padded to their widest cell, nothing cut (for logs and pipes)."""
    cells = [[str(c) for c in columns]] + [[str(x) for x in r] for r in rows]
    widths = [max(len(r[j]) for r in cells) for j in range(len(columns))]
    print(title)
    for r in cells:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip())


def _table(title, columns, rows):
    if not sys.stdout.isatty():
        # rich cuts a table at 80 columns when it cannot see a terminal: a log would lose the cells
        _plain_table(title, columns, rows)
        return
    try:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=title)
        for c in columns:
            t.add_column(c)
        for r in rows:
            t.add_row(*[str(x) for x in r])
        Console().print(t)
    except ImportError:  # rich is a dependency, but keep the GPU machine (no rich) working
        _plain_table(title, columns, rows)


def _quiet_warp(device: str = "cpu"):
    from .engine.types import init_warp

    init_warp(device)


def cmd_verify(args) -> int:
    _quiet_warp(args.device)
    from .verify import cases as verify

    records = verify.run_all(args.device, args.case or None)
    rows = [
        (
            r.case,
            r.name,
            f"{r.value:.6g}",
            f"{r.expected:.6g}",
            r.unit,
            f"{r.error:.2e}" + ("" if not r.absolute else " abs"),
            f"{r.tolerance:.2e}",
            "pass" if r.passed else "FAIL",
        )
        for r in records
    ]
    _table(
        f"warpdem verify (device {args.device})",
        ["case", "quantity", "value", "expected", "unit", "error", "tolerance", "pass"],
        rows,
    )
    failed = [r for r in records if not r.passed]
    print(f"{len(records) - len(failed)} passed, {len(failed)} failed")
    if args.json:
        with open(args.json, "w") as f:
            json.dump([r.as_json() | {"device": args.device} for r in records], f, indent=1)
    return 1 if failed else 0


def cmd_bench(args) -> int:
    _quiet_warp(args.device)
    from .verify.bench import UNITS, run_bench

    res = run_bench(
        args.device,
        args.count,
        args.steps,
        args.settle_steps,
        clumps=args.clumps,
        walls=args.walls,
        law=args.law,
        worlds=args.worlds,
        shuffle=args.shuffle,
        rolling=args.rolling,
    )
    rows = [(k, f"{v:.4g}" if isinstance(v, float) else str(v)) for k, v in res.items()]
    _table("warpdem bench: settled bed, Hertz-Mindlin with history", ["figure", "value"], rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump([{"name": k, "value": v, "unit": UNITS.get(k, "")} for k, v in res.items()], f, indent=1)
    return 0


def cmd_audit(args) -> int:
    from .study.audit import main_audit

    return main_audit(args.json)


def _sets(items) -> dict:
    out = {}
    for item in items or []:
        k, v = item.split("=", 1) if "=" in item else ("", "")
        if not k.strip():
            raise InputError(f"--set {item!r} is not allowed; expected NAME=VALUE")
        out[k.strip()] = v.strip()
    return out


def _named_scene(path: str, fn):
    """``fn``, whose refusal of a value (found while the scene is built) is prefixed with the stage ``path``."""

    def call(*a, **kw):
        try:
            return fn(*a, **kw)
        except InputError as e:
            if str(e).startswith(str(path)):
                raise
            raise InputError(f"{path}: {e}") from None

    return call


def cmd_run(args) -> int:
    _quiet_warp(args.device)
    from .scene import rigs
    from .scene.runner import RunStopped, check_stop_after, run_scene

    spec = rigs.load(args.scene, _sets(args.set))
    out = args.out or f"runs/{spec.rig}"
    check_stop_after(args.stop_after, out, frames=not args.no_frames)
    bar = None
    try:
        from tqdm import tqdm

        bar = tqdm(total=1000, desc=spec.rig, unit="", bar_format="{l_bar}{bar}| {elapsed}<{remaining} {postfix}")
    except ImportError:
        pass

    def progress(frac, msg):
        if bar is not None:
            bar.n = int(1000 * frac)
            bar.set_postfix_str(msg)
            bar.refresh()

    from .study.folder import naming

    try:
        with naming(out):
            res = _named_scene(args.scene, run_scene)(
                spec,
                device=args.device,
                out_dir=out,
                frames=not args.no_frames,
                progress=progress,
                checkpoint_every=args.checkpoint,
                stop_after=args.stop_after,
            )
    except RunStopped as e:
        print(str(e), file=sys.stderr)
        return ExitCode.STOPPED
    finally:
        if bar is not None:
            bar.close()
    info = res.info
    print(
        f"{info['rig']}: {info['spheres']} spheres ({info['clumps']} clumps, {info['glued_spheres']} glued), "
        f"{info['simulated_s']:.3f} s simulated in {info['wall_s']:.1f} s wall on {info['device']} "
        f"({info['steps']} steps, stop: {info['stop']})"
        + (f"; resumed from the checkpoint at {info['resumed_from_s']:.3f} s" if info.get("resumed_from_s") else "")
    )
    m = res.metrics[0]
    for k in (
        "angle_fit_deg",
        "angle_fit_sd_deg",
        "angle_image_deg",
        "angle_cone_deg",
        "max_displacement_m",
        "compression_ratio",
        "max_force_n",
        "fill_height_m",
        "inertial_number_max",
    ):
        if k in m and m[k] is not None:
            print(f"  {k}: {m[k]:.4g}")
    for phase, walls in m.get("phases", {}).items():
        for wall, s in walls.items():
            print(
                f"  {phase} / {wall}: {s['total_count']} impacts, max normal speed {s['max_speed_m_s']:.3g} m/s, "
                f"energy {s['total_energy_j']:.4g} J"
            )
    print(f"results in {out}/ (metrics.json, result.usdc, pile.png)")
    return 0


def _print_analysis(out, summary: dict) -> None:
    """The ANOVA table of each response (as report.md has it) and the fit statistics."""
    from pathlib import Path

    import pandas as pd

    for name, s in summary.items():
        if isinstance(s, dict) and "ci" in s:  # replicates, no model (execute.replicate_summary)
            from .study.execute import replicate_line

            print(f"{name}: {replicate_line(s)}")
            if "unflagged" in s:
                print(f"  {replicate_line(s['unflagged'])}")
        if not isinstance(s, dict) or "r2" not in s:
            continue
        path = Path(out) / "analysis" / f"anova_{name}.csv"
        if path.exists():
            tab = pd.read_csv(path, keep_default_na=False)
            for col in ("Sum of Squares", "Mean Square", "F-value"):
                tab[col] = [f"{float(v):.4g}" if v not in ("", None) else "" for v in tab[col]]
            print(f"\nANOVA for {name} ({s.get('model', '')} model)")
            print(tab.to_string(index=False))

        def f(v):
            return "n/a" if v is None else f"{v:.4f}"

        print(
            f"R^2 {f(s['r2'])}, adjusted R^2 {f(s['adj_r2'])}, predicted R^2 {f(s['pred_r2'])}, "
            f"adequate precision {f(s['adeq_precision'])}"
        )
        if s.get("equation_actual"):
            print(s["equation_actual"] if "=" in s["equation_actual"] else f"{name} = {s['equation_actual']}")
        if s.get("chosen"):
            print(
                "chosen settings (nearest the design centre on the target contour): "
                + ", ".join(f"{k} = {v:.4g}" for k, v in s["chosen"].items())
                + f"; predicted {s['predicted']:.4g}"
            )


def _print_plan(plan: dict) -> None:
    """The run table (coded and actual), the launches and the cost of :func:`execute.plan_study`."""
    study, tab, cost = plan["study"], plan["table"], plan["cost"]
    names = study.factor_names
    cols = ["run", "type", *names, *(f"{n} actual" for n in names), "seed", "status"]
    rows = [
        [r["run"], r["point_type"], *(f"{r[n]:g}" for n in names), *(f"{r[n + '_actual']:.6g}" for n in names)]
        + [r["world_seed"], r["status"]]
        for _, r in tab.iterrows()
    ]
    _table(f"{study.name}: {len(tab)} runs", cols, rows)
    _table(
        f"{cost['launches']} launch(es) of the {cost['pending']} pending run(s)",
        ["launch", "worlds", "runs", "particles per world", "simulated s (at most)"],
        [
            [k + 1, L["worlds"], ", ".join(map(str, L["runs"])), L["particles"] or "by mass", f"{L['duration_s']:g}"]
            for k, L in enumerate(plan["launches"])
        ],
    )
    particle_s = f"{cost['particle_s']:.4g}" if cost["particle_s"] is not None else "unknown (a factory gives a mass)"
    print(
        f"cost: {cost['simulated_s']:g} s simulated over the launches, {cost['world_s']:g} world-seconds, "
        f"{particle_s} particle-seconds; nothing was run (output folder {plan['out']})"
    )
    v = plan["verification"]
    if v is None:
        return
    runs = f"{v['replicates']} verification run(s) for {v['response']} = {v['target']:g}"
    if not v["analysed"]:
        print(f"then {runs} at the chosen settings, once every design run is finished and analysed")
    elif v["chosen"] is None:
        print(f"no {runs}: the analysis (analysis/summary.json) chose no settings that reach the target")
    else:
        at = ", ".join(f"{k} = {x:.4g}" for k, x in v["chosen"].items())
        print(f"then {runs} at {at} (analysis/summary.json): {v['finished']} of {v['replicates']} finished")


def cmd_study(args) -> int:
    _quiet_warp(args.device)
    from .study.execute import check_lines, plan_study, run_study

    if args.plan:
        _print_plan(plan_study(args.study, args.out, args.device))
        return 0
    res = run_study(
        args.study,
        args.out,
        device=args.device,
        progress=not args.no_progress,
        verify=not args.no_verify,
        checkpoint_every=args.checkpoint,
        stop_after=args.stop_after,
        scheduler=args.scheduler,
        shared_dir=args.shared_dir,
    )
    if res["stopped"]:
        print(
            f"{res['ran'] + res['skipped']} of {res['runs']} design runs finished; stopped at the wall-time "
            f"limit ({res['stopped']}); run the same command again to resume"
        )
        return ExitCode.STOPPED
    print(
        f"{res['runs']} runs ({res['ran']} run now in {res['batches']} batch(es), {res['skipped']} already "
        f"finished) in {res['wall_s']:.1f} s on {args.device}; results in {res['out']}/"
    )
    if res["analysis"]:
        _print_analysis(res["out"], res["analysis"])
        print(f"report: {res['out']}/analysis/report.md")
        if args.json:
            from .study.execute import _write_records, study_records
            from .study.spec import load_study

            study = load_study(args.study, check_scene=False)
            _write_records(args.json, study_records(res["out"], study, res["analysis"], res["checks"]))
    v = res.get("verification")
    if v:
        print(
            f"verification: {len(v['values'])} runs, mean {v['mean']:.4g} (SD {v['sd']:.3g}), target "
            f"{v['target']}, relative error {v['relative_error_pct']:.3g} %"
        )
        for line in check_lines(v.get("checks", []), key="replicate"):
            print(f"verification: check: {line}")
    return 0


def cmd_diagnose(args) -> int:
    _quiet_warp(args.device)
    from .diagnose.pipeline import diagnose

    res = diagnose(
        args.data,
        args.out,
        device=args.device,
        progress=not args.no_progress,
        stop_after=args.stop_after,
        scheduler=args.scheduler,
        shared_dir=args.shared_dir,
    )
    if res["stopped"]:
        print(f"stopped at the wall-time limit ({res['stopped']}); run the same command again to resume")
        return ExitCode.STOPPED
    words = {
        "adequate": "ADEQUATE: the calibrated base model fits the data within the noise",
        "cause": f"CAUSE: {res.get('cause')} ({res.get('cause_words')})",
        "ambiguous": f"AMBIGUOUS between {', '.join(res.get('tied') or [])}; measure "
        f"{res.get('separating_measurement')} to separate them",
        "unexplained": "UNEXPLAINED: the base model misfits and no candidate explains it",
    }
    # a reach diagnosis (no more measured values than free parameters) words its own verdicts
    print(res.get("verdict_words") or words[res["verdict"]])
    if res.get("mode") == "reach":
        for name, g in (res.get("gain") or {}).items():
            z = g["z_rms"]
            print(f"misfit on the data fitted, base -> base + {name}: {z['base']:.3g} -> {z['extended']:.3g} SD")
        if res.get("separating_measurement"):
            print(f"measure {res['separating_measurement']} to tell them apart")
        from warpdem.diagnose.reach import law_label

        for law in ((res.get("rolling_models") or {}).get("tried") or {}).values():
            for r, s in law["scatter"].items():
                g = law["gain"].get(r)
                vs = f", base / its variance {g['F']:.3g} (p {g['p_holm']:.2g})" if g else ""
                says = "repeats" if law["repeats"] else "does not repeat"
                print(f"rolling model {law_label(law)}: {r} SD {s['simulated_sd']:.3g}{vs}; {says}")
    else:
        for r, x in ((res.get("gain") or {}).get("rmse") or {}).items():
            p = x.get("noise_p")
            noise = f"; chi-square p against the noise: base {p['base']:.2g}, extended {p['extended']:.2g}" if p else ""
            print(
                f"held-out RMSE of {r}: base {x['base']:.4g}, extended {x['extended']:.4g} "
                f"({100 * x['reduction']:.0f} % lower{noise})"
            )
    print(
        f"{res['worlds']} simulated worlds ({res['launches']} launches now) in {res['wall_s']:.1f} s on {args.device}; "
        f"report: {res['out']}/report.md"
    )
    return 0


def cmd_analyze(args) -> int:
    from .study.execute import analyze, run_checks
    from .study.spec import StudyError, load_study

    if args.runs and not args.study:
        raise StudyError(f"--runs {args.runs}: give the study file its runs follow (--study STUDY.toml)")
    study = load_study(args.study, check_scene=False) if args.study else None
    if args.measure and not args.remeasure:
        raise StudyError(f"--measure {args.measure[0]}: give --remeasure too (the settings to measure again under)")
    measure = _sets(args.measure) if args.remeasure else None
    try:
        # checked once, for the report and the records alike; runs made elsewhere have no records to check
        flags = [] if args.runs else run_checks(args.out, study)
        summary = analyze(args.out, study, runs=args.runs, measure=measure, flags=flags)
    except FileNotFoundError as e:
        raise StudyError(str(e)) from None
    if args.excel:
        from .study.execute import export_excel

        print(f"workbook: {export_excel(args.out, args.excel)}")
    _print_analysis(args.out, summary)
    print(f"report: {args.out}/analysis/report.md")
    if args.json:
        from pathlib import Path

        from .study.execute import _write_records, study_records

        study = study or load_study(Path(args.out) / "study.toml", check_scene=False)
        _write_records(args.json, study_records(args.out, study, summary, flags))
    return 0


def cmd_scene(args) -> int:
    from .scene import rigs

    rigs.new(args.rig, args.output, _sets(args.set), smoke=args.smoke)
    print(f"wrote {args.output}")
    return 0


def _add_wall_time_options(parser, checkpoint: str, stop_after: str) -> None:
    """--checkpoint (default every 60 s of wall time) and --stop-after (default no limit), in seconds, with the
    command's own help texts."""
    parser.add_argument("--checkpoint", type=_seconds, default=60.0, metavar="SECONDS", help=checkpoint)
    parser.add_argument("--stop-after", type=_seconds, default=0.0, metavar="SECONDS", help=stop_after)


def _seconds(text: str) -> float:
    """A wall time option's value: finite seconds >= 0 (argparse names the option in its message)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value >= 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed; expected finite seconds >= 0 (0: off)")
    return value


def _count0(text: str) -> int:
    """A count option's value that may be 0: an integer >= 0."""
    if not text.strip().isdigit():
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed; expected an integer >= 0")
    return int(text)


def _count(text: str) -> int:
    """A count option's value: an integer >= 1."""
    if not text.strip().isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed; expected an integer >= 1")
    return int(text)


SCHEDULER_HELP = (
    "address of a Dask scheduler (tcp://HOST:8786; default: the environment variable WARPDEM_SCHEDULER): each "
    "launch becomes a task of its cluster (GPU=1 where the workers declare GPUs); results are written here as "
    "they arrive and a rerun sends only what is missing"
)

SHARED_HELP = (
    "with --scheduler: a folder every worker can write (a shared file system); launches checkpoint there, so a "
    "launch retried on another worker resumes; without it a retried launch starts again"
)


def main(argv=None) -> int:
    from .engine.keys import KeyGrammar
    from .scene import rigs
    from .scene.stage import OVERRIDES
    from .verify.bench import ROLLING_CHOICES

    p = argparse.ArgumentParser(prog="warpdem", description="DEM on NVIDIA Warp")
    sub = p.add_subparsers(dest="command", required=True)
    v = sub.add_parser("verify", help="run the analytic verification cases")
    v.add_argument("--device", default="cpu")
    v.add_argument("--json", help="write the records to this file")
    v.add_argument("--case", action="append", help="run only this case (repeatable)")
    v.set_defaults(fn=cmd_verify)
    b = sub.add_parser("bench", help="throughput of a settled bed")
    b.add_argument("--device", default="cpu")
    b.add_argument("--json")
    b.add_argument("--count", type=_count, help="bodies per world (default 2000 on CPU, 1,000,000 on CUDA)")
    b.add_argument("--steps", type=_count, help="timed steps")
    b.add_argument("--settle-steps", type=_count0, help="steps before timing (default: 0.2 s of simulated time)")
    b.add_argument("--clumps", type=_count0, default=0, help="8: every body an 8-sphere clump (count = clumps)")
    b.add_argument("--walls", default="planes", choices=["planes", "mesh"], help="box as planes or one mesh")
    b.add_argument("--law", default="HM", choices=["HM", "JKR", "EEPA"], help="contact law of every pair")
    b.add_argument("--worlds", type=_count, default=1, help="identical copies of the bed, batched in one model")
    b.add_argument("--shuffle", action="store_true", help="number the bodies in a random order (not row by row)")
    b.add_argument(
        "--rolling",
        default="none",
        choices=ROLLING_CHOICES,
        help="rolling model of every pair, mu_r = 0.1 (default: none)",
    )
    b.set_defaults(fn=cmd_bench)
    au = sub.add_parser("audit", help="recompute the seed papers' published statistics from their own data")
    au.add_argument("--json", help="write the records to this file ('-': JSON to stdout instead of the table)")
    au.set_defaults(fn=cmd_audit)
    r = sub.add_parser("run", help="run a scene (USD stage) and write metrics.json, result.usdc, pile.png")
    r.add_argument("scene")
    r.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help=f"override: {KeyGrammar({**OVERRIDES.fields, 'rig': None}).forms()} (a rig parameter regenerates "
        "the scene)",
    )
    r.add_argument("--device", default="cpu")
    r.add_argument("--out", help="output folder (default runs/RIG)")
    r.add_argument("--no-frames", action="store_true", help="skip the time-sampled USD and VTK")
    _add_wall_time_options(
        r,
        checkpoint="with --no-frames: save the run's state every SECONDS of wall time to DIR/checkpoint.npz; "
        "the same command resumes from it (default 60, 0: never)",
        stop_after="with --no-frames: stop by itself after SECONDS of wall time, saving a checkpoint "
        "(exit code 3); the same command resumes (0: no limit)",
    )
    r.set_defaults(fn=cmd_run)
    st = sub.add_parser("study", help="run (or resume) a design of experiments, then analyse and verify it")
    st.add_argument("study", help="study file, e.g. studies/main_funnel_pb.toml")
    st.add_argument(
        "--device",
        default="cpu",
        help="cpu, cuda, cuda:N, cuda:all, or a comma-separated list (cuda:0,cuda:1; cpu,cpu): with "
        "several, the runs are split into one launch per device, run at once on a local Dask cluster, one "
        "worker process each",
    )
    st.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    st.add_argument("--shared-dir", default=None, help=SHARED_HELP)
    st.add_argument("--out", help="output folder (default runs/NAME); rerunning resumes it")
    st.add_argument("--no-progress", action="store_true", help="no progress bar")
    st.add_argument("--no-verify", action="store_true", help="skip the verification runs at the optimum")
    st.add_argument(
        "--plan",
        action="store_true",
        help="print the run table (coded and actual, finished or pending), the launches and their cost; run nothing",
    )
    st.add_argument(
        "--json", help="write the analysis as records (name, value, expected, unit, pass) to this file ('-': stdout)"
    )
    _add_wall_time_options(
        st,
        checkpoint="save each launch's state every SECONDS of wall time (0: never); a rerun resumes from it",
        stop_after="stop by itself after SECONDS of wall time, saving the running launch's checkpoint "
        "(exit code 3); the same command resumes (0: no limit)",
    )
    st.set_defaults(fn=cmd_study)
    dg = sub.add_parser("diagnose", help="calibrate to measured data, test adequacy, name the cause of a misfit")
    dg.add_argument("data", help="measured-data file (TOML; schema in warpdem/diagnose/data.py)")
    dg.add_argument("--device", default="cpu", help="as for study: cpu, cuda, cuda:N, cuda:all or a list")
    dg.add_argument("--out", default=None, help="output folder (default runs/diagnose/<name>)")
    dg.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    dg.add_argument("--shared-dir", default=None, help=SHARED_HELP)
    dg.add_argument("--no-progress", action="store_true", help="no progress bar")
    dg.add_argument(
        "--stop-after",
        type=_seconds,
        default=0.0,
        metavar="SECONDS",
        help="stop by itself after SECONDS of wall time (exit code 3); the same command resumes (0: no limit)",
    )
    dg.set_defaults(fn=cmd_diagnose)
    an = sub.add_parser("analyze", help="fit, ANOVA, plots and report.md of a study folder")
    an.add_argument("out", help="a study's output folder (with --runs: where the analysis goes)")
    an.add_argument(
        "--study",
        help="analyse with this study file instead of the folder's copy (e.g. with a response added: it is read "
        "from the runs' stored metrics)",
    )
    an.add_argument(
        "--runs", help="a CSV run table made elsewhere (a column per factor in actual units and per response)"
    )
    an.add_argument(
        "--json", help="write the analysis as records (name, value, expected, unit, pass) to this file ('-': stdout)"
    )
    an.add_argument(
        "--excel", metavar="FILE.xlsx", help="also write the analysis as an Excel workbook (needs openpyxl)"
    )
    an.add_argument(
        "--remeasure",
        action="store_true",
        help="measure every run again from its stored final state (a pile's angles and height) before the analysis",
    )
    an.add_argument(
        "--measure",
        action="append",
        metavar="measure.FIELD=VALUE",
        help="with --remeasure: a measure setting to measure under (e.g. measure.base_height=0.001); repeatable",
    )
    an.set_defaults(fn=cmd_analyze)
    sc = sub.add_parser("scene", help="author scenes")
    scs = sc.add_subparsers(dest="scene_command", required=True)
    sn = scs.add_parser("new", help="write a rig's stage from parameters")
    sn.add_argument("rig", choices=list(rigs.RIGS))
    sn.add_argument("--set", action="append", metavar="NAME=VALUE", help="rig parameter")
    sn.add_argument("--smoke", action="store_true", help="start from the CPU smoke-test size")
    sn.add_argument("-o", "--output", required=True)
    sn.set_defaults(fn=cmd_scene)
    for parser in [p, *sub.choices.values(), *scs.choices.values()]:
        parser.add_argument(
            "--debug",
            action="store_true",
            default=argparse.SUPPRESS if parser is not p else False,
            help="show the traceback of an error (also: the environment variable WARPDEM_DEBUG=1)",
        )
    try:
        args = p.parse_args(argv)
    except SystemExit as e:  # argparse has printed its usage message; a caller of main() gets the code back
        return int(e.code or 0)
    debug = args.debug or os.environ.get("WARPDEM_DEBUG", "") not in ("", "0")
    shown = warnings.showwarning
    if not debug:  # a physics warning is a line for the user, not a source location
        warnings.showwarning = lambda message, *a, **k: print(f"warning: {message}", file=sys.stderr)
    try:
        return int(args.fn(args))
    except (Exception, KeyboardInterrupt) as e:
        if debug:
            raise
        code, message = classify(e)
        print(f"error: {message}", file=sys.stderr)
        return int(code)
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":
    sys.exit(main())
