"""The seed calibrations end to end on several GPUs (issue 23), as two lanes run side by side; resumable.

    python docs/seeds/run_seeds.py --root DIR --budget SECONDS [--lane DEVICES=STEP,STEP,... ...] [--dry-run]

The steps: seed 001's wet-feed Plackett-Burman (wetfeed_pb), central composite with its verification replicates
(wetfeed_ccd) and that verification again with the seed's 25,000 grains (wetfeed_verify_large; its surface energy
stepped down there, wetfeed_large_gamma, and its friction, wetfeed_large_friction), then the die press at the central composite's chosen optimum, or its
closest point when the target is out of reach (die_press), and its surface-energy scan beyond the paper's range
(wetfeed_gamma_scan); seed 002's 2^(5-1) screening (phosphate_ffd),
Box-Behnken with its verification run (phosphate_bbd), its surface energy as printed and scaled by the coarse-graining
factor squared, and between (phosphate_gamma_scaled, phosphate_gamma_scan; the screening with it scaled by s,
phosphate_ffd_gamma_s), and the truck tipper, first contacts split from the rest of the loading (truck_tipper; with
the bucket turning over 6 s, truck_tipper_slow); seed 000's screening, steepest ascent and Box-Behnken, read with the
current pile rule (pellets_pb, pellets_steepest, pellets_bbd), and replicates at the Box-Behnken region's high corner
(pellets_verify); the screening and replicates at the paper's calibrated set with EDEM's standard rolling friction
(pellets_pb_standard, pellets_calibrated_standard), its steepest ascent and Box-Behnken (pellets_steepest_standard,
pellets_bbd_standard; the Box-Behnken again where our own path came nearest the target, pellets_bbd_standard_own), and
three verifications of our own with it: at that screening's chosen point, one steepest-descent step on, and on the
secant between them (pellets_verify_standard, pellets_verify_standard_step, pellets_verify_standard_secant); the reach
diagnoses of seeds 000 and 001's one angle each (seed000_reach, seed001_reach: ``warpdem diagnose
studies/diagnose/seed00N_*.toml``); seed 001's press and reach diagnosis with the model the sixteenth stage
recalibrated (die_press_standard_scaled, with a fuller die die_press_standard_scaled_80, seed001_reach_standard_scaled),
and the press, with the fuller die, at the set that landed with the seed's 25,000 grains (die_press_seed_size_80), its
further fills (die_press_seed_size_80_s2 to _s6), with a stiffer feed (die_press_seed_size_80_stiff) and with the
sixteenth stage's surface energy (die_press_seed_size_80_gamma), and the
rolling-model check at that size (seed001_reach_large_confirm6, docs/seeds/001/reach_large/ copied into its folder).
A lane runs its steps in order on its devices (a study on several goes through the distributed executor); lanes run
side by side and may share a device, but two processes on one GPU time-slice it: on one H200 (2026-12-01) a
25,000-grain study beside a one-world press took 1,076 s where it had taken 516 s alone, and the press about 1,113 s
against about 700 s (together 1,113 s against 1,214 s one after the other). Give each lane its own devices where
its wall time is to be reported. The default, for 4 GPUs: seed 001 on cuda:0, seed 002 on the other three.

Every step is a ``warpdem`` command that resumes where it stopped: each gets ``--stop-after`` the time left of
``--budget`` less :data:`STOP_MARGIN` and exits 3 when it stops, which ends its lane for this call. Run the same
command again (on the same machine, whose DIR is kept) to go on. The results land in DIR/<step>/; this script
prints each command and its exit code.

To bring the results back from a GPU machine, pack DIR without the launches' checkpoints
(``tar czf OUT/seeds.tgz -C DIR --exclude='checkpoint*.npz' .``): the studies' ``runs/*.npz`` final states are
what ``warpdem analyze --remeasure`` reads again. The wet feed's are small; the lifting cylinder's are about 2 MB
each (the Box-Behnken's pack was 64 MB, over a call's 16 MiB a file: split it, or leave ``*.npz`` out).
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

STOP_MARGIN = 90
"""Seconds a step may run beyond its ``--stop-after``: once it has run out each launch goes on to its next output
tick, saves its checkpoint and the cluster shuts down, and the pack that follows needs time too. On 4 H200s, with
no margin (and a study's clock then started only once its Dask cluster was up, the workers' first kernel compile
included), ``--budget 500`` (plus the wheels' install) took 543 s, and ``--budget 530`` overran a 600 s call, which
lost the machine and its checkpoints. Wrapping the script in ``timeout`` keeps the pack that follows: a killed
launch loses at most its last minute, since launches checkpoint every 60 s. A study's analysis after its last run
is not bounded by ``--stop-after``: seed 000's Box-Behnken (211,500 spheres a world) was still drawing its pile
pictures 146 s after its last run (11 of 17 done) when ``timeout`` ended it; give such a step that much more."""

PRESS_KEYS = {
    "X1": "interaction.feed.feed.rolling_friction",
    "X2": "interaction.feed.feed.static_friction",
    "X3": "interaction.feed.feed.surface_energy",
}
"""The central composite's factors (wetfeed_ccd.toml, the funnel's grain-grain pair) as the die press's feed-feed
pair; the CCD's fixed values are the press's own (restitution 0.15, the steel pair's 0.1, 0.2 and 0.45)."""


RUNNING: set = set()
"""The steps' processes now running: ended, by their pids, when this script gets SIGTERM. ``timeout`` signals
the whole process group, but ``kill PID`` of this script alone used to leave its running step behind, still
writing into DIR while the next call started the same step again."""

STOPPING = threading.Event()
"""Set on SIGTERM, so that no lane starts its next step."""


def end_steps(signum, frame) -> None:
    """SIGTERM: end each running step (it keeps its last checkpoint, at most a minute old) and exit."""
    STOPPING.set()
    for proc in list(RUNNING):
        proc.terminate()
    for proc in list(RUNNING):
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
    raise SystemExit(128 + signum)


def ccd_optimum(root: Path) -> dict:
    """The central composite's calibrated values of its factors, as press overrides: the chosen optimum (the
    verification's), or the analysis's closest point when no point reaches the target."""
    summary = json.loads((root / "wetfeed_ccd" / "analysis" / "summary.json").read_text())["aor_deg"]
    point = summary.get("chosen") or summary.get("closest")
    if not point:
        raise SystemExit("the central composite's analysis has neither a chosen nor a closest point")
    return {key: float(point[f]) for f, key in PRESS_KEYS.items()}


def study(name: str, devices: str, root: Path) -> list:
    """A study's command line (without ``--stop-after``)."""
    cmd = ["-m", "warpdem.cli", "study", f"studies/{name}.toml", "--device", devices]
    return cmd + ["--out", str(root / name), "--no-progress"]


def diagnosis(name: str, devices: str, root: Path) -> list:
    """A diagnosis's command line (without ``--stop-after``): studies/diagnose/NAME.toml into ``root/name``."""
    cmd = ["-m", "warpdem.cli", "diagnose", f"studies/diagnose/{name}.toml", "--device", devices]
    return cmd + ["--out", str(root / name), "--no-progress"]


def rig(name: str, device: str, root: Path, sets=()) -> list:
    """A full-size rig run (benchmarks/rigs_full.py: the GPU machine has no usd-core to read a stage); its
    results land in ``root/name``."""
    cmd = ["benchmarks/rigs_full.py", "--rig", name, "--device", device, "--out", str(root)]
    for k, v in sets:
        cmd += ["--set", f"{name}.{k}={v:.6g}" if isinstance(v, float) else f"{name}.{k}={v}"]
    return cmd


STANDARD_ROLLING = (
    ("interaction.feed.feed.rolling_model", "standard"),
    ("interaction.feed.steel.rolling_model", "standard"),
)
"""EDEM's standard rolling friction on the die press's feed pairs, as overrides (the model seed 001 was
recalibrated with)."""
SCALED_SET = (
    ("interaction.feed.feed.rolling_friction", 0.2752),
    ("interaction.feed.feed.static_friction", 0.5904),
    ("interaction.feed.feed.surface_energy", 0.1052),
    *STANDARD_ROLLING,
)
"""Seed 001's set from the sixteenth stage (its step in X3 past the scaled composite's optimum, within 1 deg at
6,000 grains) with EDEM's standard rolling friction, as the die press's overrides."""
FULLER_FILL = ("fill_height", 0.0835)
"""The press's fill height [m] that settles the less cohesive bed near the seed's 80 mm: at 0.08 m it settled at
76.6 mm (the rig sizes its grain count for the packing of 0.42 measured at 0.65 J/m^2), so 0.08 x 80 / 76.6."""

FILL_SEEDS = (2, 3, 4, 5, 6)
"""The rig seeds of the seed-size press's further fills (studies/wetfeed_press_seed_size.toml's S); 2 and 3 ran in
the twenty-first and twenty-fifth stages through rigs_full.py with the same overrides."""
STIFF_FEED = ("material.feed.shear_modulus", 1.0e8)
"""The feed's shear modulus [Pa] for the stiff press: ten times the seed's 10 MPa, so that the contacts at 300 N
stay within Hertz's small overlaps (the seed's modulus gives a mean of 31-33 % of a radius)."""

SIXTEENTH_GAMMA = ("interaction.feed.feed.surface_energy", dict(SCALED_SET)["interaction.feed.feed.surface_energy"])
"""The sixteenth stage's surface energy [J/m^2] (0.1052) in place of the final set's 0.0909: the two sets differ
in X1 (0.2752, 0.2470) and X3, and their presses from the rig's fill seed 1 read compression ratios of 0.625 and
0.592. At the seed's pile size the funnel moves 38.9 deg per J/m^2 of X3 and 67.6 deg per unit of X1 (eighteenth,
nineteenth stages), so had X3 moved the press, this set could have landed both. It read 0.602 (twenty-seventh
stage): within the fills' scatter of the final set's, as was the sixteenth stage's set."""

SEED_SIZE_STUDY = "wetfeed_verify_large_standard_scaled_friction"
"""The study whose point landed within 1 deg of seed 001's angle with the seed's 25,000 grains (nineteenth stage):
the press's calibrated set is read from its design, so that the two cannot drift apart."""


def seed_size_set() -> tuple:
    """Seed 001's set calibrated at the seed's size (:data:`SEED_SIZE_STUDY`'s one design point) with EDEM's
    standard rolling friction, as the die press's overrides."""
    import tomllib

    path = Path(__file__).resolve().parents[2] / "studies" / f"{SEED_SIZE_STUDY}.toml"
    points = {tuple(sorted(p.items())) for p in tomllib.loads(path.read_text())["design"]["points"]}
    if len(points) != 1:
        raise SystemExit(f"{path}: [design] points hold {len(points)} settings; one point (its replicates) expected")
    (point,) = points
    return tuple((PRESS_KEYS[f], float(v)) for f, v in point) + STANDARD_ROLLING


def replaced(sets: tuple, override: tuple) -> tuple:
    """``sets`` (KEY, VALUE pairs) with ``override``'s key given its value, in place; the key must be there."""
    key, value = override
    if key not in dict(sets):
        raise KeyError(f"{key} is not among the overrides {[k for k, _ in sets]}")
    return tuple((k, value if k == key else v) for k, v in sets)


STEPS = {
    # the wet feed's surface energy doubled from 0.5 to 8 J/m^2, beyond the paper's range (no verification)
    "wetfeed_gamma_scan": lambda dev, root: study("wetfeed_gamma_scan", dev, root) + ["--no-verify"],
    # at the central composite's optimum: built when the step starts, after the composite has run
    "die_press": lambda dev, root: lambda: rig("die_press", dev.split(",")[-1], root, ccd_optimum(root).items()),
    # seeds 000 and 001 give one angle each, out of their base models' reach: which candidates reach it
    "seed000_reach": lambda dev, root: diagnosis("seed000_pellets", dev, root),
    "seed001_reach": lambda dev, root: diagnosis("seed001_wetfeed", dev, root),
    "seed001_reach_standard_scaled": lambda dev, root: diagnosis("seed001_wetfeed_standard_scaled", dev, root),
    "die_press_standard_scaled": lambda dev, root: rig(
        "die_press", dev.split(",")[-1], root / "die_press_standard_scaled", SCALED_SET
    ),
    "die_press_standard_scaled_80": lambda dev, root: rig(
        "die_press", dev.split(",")[-1], root / "die_press_standard_scaled_80", (*SCALED_SET, FULLER_FILL)
    ),
    # the press at the set that landed within 1 deg with the seed's 25,000 grains, the die filled for an 80 mm bed
    "die_press_seed_size_80": lambda dev, root: rig(
        "die_press", dev.split(",")[-1], root / "die_press_seed_size_80", (*seed_size_set(), FULLER_FILL)
    ),
    # more fills of that press, the rig's own seed (fill 1 is die_press_seed_size_80): the press's scatter
    **{
        f"die_press_seed_size_80_s{n}": lambda dev, root, n=n: rig(
            "die_press",
            dev.split(",")[-1],
            root / f"die_press_seed_size_80_s{n}",
            (*seed_size_set(), FULLER_FILL, ("seed", n)),
        )
        for n in FILL_SEEDS
    },
    # the same press with the feed's shear modulus ten times the seed's: how much the soft contacts compress
    "die_press_seed_size_80_stiff": lambda dev, root: rig(
        "die_press",
        dev.split(",")[-1],
        root / "die_press_seed_size_80_stiff",
        (*seed_size_set(), FULLER_FILL, STIFF_FEED),
    ),
    # the same press with the sixteenth stage's surface energy: did X3 or X1 lower the final set's press?
    "die_press_seed_size_80_gamma": lambda dev, root: rig(
        "die_press",
        dev.split(",")[-1],
        root / "die_press_seed_size_80_gamma",
        (*replaced(seed_size_set(), SIXTEENTH_GAMMA), FULLER_FILL),
    ),
    # the rolling-model check at the seed's 25,000 grains; copy docs/seeds/001/reach_large/ into its folder first
    "seed001_reach_large_confirm6": lambda dev, root: diagnosis("seed001_wetfeed_large_confirm6", dev, root),
    "truck_tipper": lambda dev, root: rig("truck_tipper", dev.split(",")[-1], root),
    # the same tipper with the bucket turning over 6 s instead of 1.5 s: the first contacts' speed falls towards
    # the free fall from the lip as the turn slows (tipper_dump.py), which seed 002 does not give
    "truck_tipper_slow": lambda dev, root: rig(
        "truck_tipper", dev.split(",")[-1], root / "truck_tipper_slow", [("dump_duration", 6.0)]
    ),
}
"""The steps that are not a plain study: each one's command line on a lane's devices (a rig run takes the lane's
last device). Any other step name is the study ``studies/NAME.toml``, run as it is (:func:`step`); its header says
which stage of which seed it encodes."""

STUDIES = Path(__file__).resolve().parents[2] / "studies"
"""Where a plain study step's file lives."""


def step(name: str, devices: str, root: Path):
    """Step ``name``'s command line (or, for the die press, a function that builds it once the composite has
    run): from :data:`STEPS`, else the study ``studies/NAME.toml``; None when it is neither."""
    if name in STEPS:
        return STEPS[name](devices, root)
    if (STUDIES / f"{name}.toml").is_file():
        return study(name, devices, root)
    return None


LANES = ["cuda:0=wetfeed_pb,wetfeed_ccd,die_press", "cuda:1,cuda:2,cuda:3=phosphate_ffd,phosphate_bbd,truck_tipper"]
"""The default lanes, for a 4-GPU machine: DEVICES=STEP,STEP,... each."""


def parse_lane(text: str, root: Path) -> list:
    devices, _, names = text.partition("=")
    steps = [(n, step(n, devices, root)) for n in names.split(",")] if devices and names else []
    unknown = [n for n, args in steps if args is None]
    if not steps or unknown:
        raise SystemExit(
            f"--lane {text!r}: expected DEVICES=STEP,STEP,... with each step one of {', '.join(STEPS)} or a study "
            f"studies/NAME.toml" + (f"; not found: {', '.join(unknown)}" if unknown else "")
        )
    return steps


def run_lane(name: str, steps: list, root: Path, deadline: float, dry: bool, log) -> None:
    for step, args in steps:
        done = root / f"{step}.done"
        if done.exists():
            log(f"[{name}] {step}: done before")
            continue
        if STOPPING.is_set():
            return
        left = int(deadline - time.time()) - STOP_MARGIN
        if left < 30:
            log(f"[{name}] {step}: {left} s left, not started")
            return
        if callable(args) and dry:
            log(f"[{name}] {step}: at the central composite's optimum, once it is analysed")
            continue
        argv = args() if callable(args) else args
        cmd = [sys.executable, *argv, "--stop-after", str(left)]
        log(f"[{name}] {step}: {' '.join(cmd)}")
        if dry:
            continue
        t0 = time.time()
        with open(root / f"{step}.log", "a") as fh:
            proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT)
            RUNNING.add(proc)
            if STOPPING.is_set():  # SIGTERM came between the check above and the start
                proc.terminate()
            rc = proc.wait()
            RUNNING.discard(proc)
        log(f"[{name}] {step}: exit {rc} after {time.time() - t0:.1f} s")
        if rc != 0:
            return
        done.write_text(f"{time.time() - t0:.1f}\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True)
    ap.add_argument("--budget", type=float, required=True, help="wall seconds for this call")
    ap.add_argument("--lane", action="append", help=f"DEVICES=STEP,STEP,... (default: {' '.join(LANES)})")
    ap.add_argument("--dry-run", action="store_true")
    a = ap.parse_args(argv)
    a.root.mkdir(parents=True, exist_ok=True)
    deadline = time.time() + a.budget
    lock = threading.Lock()

    def log(msg):
        with lock:
            print(time.strftime("%H:%M:%S"), msg, flush=True)

    lanes = [(chr(65 + k), parse_lane(t, a.root)) for k, t in enumerate(a.lane or LANES)]
    signal.signal(signal.SIGTERM, end_steps)
    threads = [threading.Thread(target=run_lane, args=(n, s, a.root, deadline, a.dry_run, log)) for n, s in lanes]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
