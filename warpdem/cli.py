"""Command line: ``warpdem run | scene new | pile | verify | bench | audit``."""

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


def _sets(items) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"--set {item!r}: expected name=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def cmd_run(args) -> int:
    _quiet_warp()
    from . import rigs
    from .runner import run_scene
    from .scene import StageError

    try:
        spec = rigs.load(args.scene, _sets(args.set))
    except StageError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    out = args.out or f"runs/{spec.rig}"
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

    res = run_scene(spec, device=args.device, out_dir=out, frames=not args.no_frames, progress=progress)
    if bar is not None:
        bar.close()
    info = res.info
    print(f"{info['rig']}: {info['spheres']} spheres ({info['clumps']} clumps, {info['glued_spheres']} glued), "
          f"{info['simulated_s']:.3f} s simulated in {info['wall_s']:.1f} s wall on {info['device']} "
          f"({info['steps']} steps, stop: {info['stop']})")
    m = res.metrics[0]
    for k in ("angle_fit_deg", "angle_fit_sd_deg", "angle_image_deg", "angle_cone_deg", "max_displacement_m",
              "compression_ratio", "max_force_n", "fill_height_m", "inertial_number_max"):
        if k in m and m[k] is not None:
            print(f"  {k}: {m[k]:.4g}")
    for phase, walls in m.get("phases", {}).items():
        for wall, s in walls.items():
            print(f"  {phase} / {wall}: {s['total_count']} impacts, max normal speed {s['max_speed_m_s']:.3g} m/s, "
                  f"energy {s['total_energy_j']:.4g} J")
    print(f"results in {out}/ (metrics.json, result.usdc, pile.png)")
    return 0


def cmd_scene(args) -> int:
    from . import rigs
    from .scene import StageError

    try:
        rigs.new(args.rig, args.output, _sets(args.set), smoke=args.smoke)
    except StageError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}")
    return 0


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
    r = sub.add_parser("run", help="run a scene (USD stage) and write metrics.json, result.usdc, pile.png")
    r.add_argument("scene")
    r.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="override: material.NAME.FIELD, interaction.A.B.FIELD, run.FIELD, measure.FIELD, "
                        "factory.NAME.FIELD, or a rig parameter (regenerates the scene)")
    r.add_argument("--device", default="cpu")
    r.add_argument("--out", help="output folder (default runs/RIG)")
    r.add_argument("--no-frames", action="store_true", help="skip the time-sampled USD and VTK")
    r.set_defaults(fn=cmd_run)
    sc = sub.add_parser("scene", help="author scenes")
    scs = sc.add_subparsers(dest="scene_command", required=True)
    sn = scs.add_parser("new", help="write a rig's stage from parameters")
    sn.add_argument("rig", choices=["funnel", "lifting_cylinder", "die_press", "truck_tipper"])
    sn.add_argument("--set", action="append", metavar="NAME=VALUE", help="rig parameter")
    sn.add_argument("--smoke", action="store_true", help="start from the CPU smoke-test size")
    sn.add_argument("-o", "--output", required=True)
    sn.set_defaults(fn=cmd_scene)
    args = p.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
