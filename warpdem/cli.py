"""Command line: ``warpdem pile | verify | bench | audit``."""

from __future__ import annotations

import argparse
import json
import sys


def _table(title, columns, rows):
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
        print(title)
        print(" | ".join(columns))
        for r in rows:
            print(" | ".join(str(x) for x in r))


def _quiet_warp():
    import warp as wp

    wp.config.quiet = True
    wp.init()


def cmd_verify(args) -> int:
    _quiet_warp()
    from . import verify

    records = verify.run_all(args.device, args.case or None)
    rows = [(r.case, r.name, f"{r.value:.6g}", f"{r.expected:.6g}", r.unit,
             f"{r.error:.2e}" + ("" if not r.absolute else " abs"), f"{r.tolerance:.2e}",
             "pass" if r.passed else "FAIL") for r in records]
    _table(f"warpdem verify (device {args.device})",
           ["case", "quantity", "value", "expected", "unit", "error", "tolerance", "pass"], rows)
    failed = [r for r in records if not r.passed]
    print(f"{len(records) - len(failed)} passed, {len(failed)} failed")
    if args.json:
        with open(args.json, "w") as f:
            json.dump([r.as_json() | {"device": args.device} for r in records], f, indent=1)
    return 1 if failed else 0


def cmd_bench(args) -> int:
    _quiet_warp()
    from .bench import run_bench

    res = run_bench(args.device, args.count, args.steps, args.settle_steps, clumps=args.clumps, walls=args.walls,
                    law=args.law)
    rows = [(k, f"{v:.4g}" if isinstance(v, float) else str(v)) for k, v in res.items()]
    _table("warpdem bench: settled bed, Hertz-Mindlin with history", ["figure", "value"], rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump([{"name": k, "value": v, "unit": ""} for k, v in res.items()], f, indent=1)
    return 0


def cmd_pile(args) -> int:
    _quiet_warp()
    from .pile import run_pile

    res = run_pile(device=args.device, count=args.count, seed=args.seed)
    print(f"angle of repose: {res['angle_fit_deg']:.1f} deg (surface fit, mean of {res['slices']} slices, "
          f"SD {res['angle_fit_sd_deg']:.1f}); cone formula atan(2h/d): {res['angle_cone_deg']:.1f} deg")
    print(f"{res['spheres']} spheres, {res['simulated_s']:.2f} s simulated in {res['wall_s']:.1f} s wall")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)
    return 0


def cmd_audit(args) -> int:
    from .study.audit import main_audit

    return main_audit(args.json)


def main(argv=None) -> int:
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
    b.add_argument("--count", type=int, help="bodies (default 2000 on CPU, 1,000,000 on CUDA)")
    b.add_argument("--steps", type=int, help="timed steps")
    b.add_argument("--settle-steps", type=int, default=20000)
    b.add_argument("--clumps", type=int, default=0, help="8: every body an 8-sphere clump (count = clumps)")
    b.add_argument("--walls", default="planes", choices=["planes", "mesh"], help="box as planes or one mesh")
    b.add_argument("--law", default="HM", choices=["HM", "JKR", "EEPA"], help="contact law of every pair")
    b.set_defaults(fn=cmd_bench)
    pl = sub.add_parser("pile", help="pour a small pile on a plate and print its angle of repose")
    pl.add_argument("--device", default="cpu")
    pl.add_argument("--count", type=int, default=800)
    pl.add_argument("--seed", type=int, default=1)
    pl.add_argument("--json")
    pl.set_defaults(fn=cmd_pile)
    au = sub.add_parser("audit", help="recompute the seed papers' published statistics from their own data")
    au.add_argument("--json", help="write the records to this file ('-': JSON to stdout instead of the table)")
    au.set_defaults(fn=cmd_audit)
    args = p.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
