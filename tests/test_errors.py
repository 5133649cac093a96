"""Every bad input a clear error (issue 22): a corpus of malformed and out-of-range inputs, each given to the
command line in-process as a hostile user would give it.

Each case is one row of :data:`CASES`: the route (``run``, ``stage``, ``scene``, ``study``, ``diagnose``,
``option``, ``blowup``), a builder of the argument list, the exit code :mod:`warpdem.errors` promises (2 bad input,
4 simulation failed, 5 file system, 6 device) and the words the message must hold: the field (the override key,
the USD attribute or prim path, the study table and key, the file name) and, where sensible, the value. For every
case :func:`warpdem.cli.main` must return that code without raising, and nothing it prints may be a traceback.

A correct implementation refuses every bad-input case before a simulation starts, so each takes well under a
second once Warp is up; only the blow-up simulates (a few spheres for a few steps). Scenes are the rigs' smoke
stages cut to 20 spheres and 0.05 s, written once per session and edited with pxr for the malformed-stage cases.
Cases that still simulate (accepted silently) or loop for ever are stopped by a SIGALRM guard of
:data:`GUARD_S` seconds and reported as such.
"""

from __future__ import annotations

import shutil
import signal
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from warpdem.cli import main
from warpdem.scene import rigs

Sdf = pytest.importorskip("pxr.Sdf")
Usd = pytest.importorskip("pxr.Usd")
Gf = pytest.importorskip("pxr.Gf")
Vt = pytest.importorskip("pxr.Vt")

GUARD_S = 60
"""Seconds a case may take before it is stopped as a hang (or as a silently accepted input that simulates)."""

TINY = {"count": 20, "duration": 0.05}
"""Rig parameters over the smoke set: a 20-sphere funnel run of 0.05 s (what an accepted input would run)."""


# ----------------------------------------------------------------------------------------------------
# the files the cases read, made on first use and shared by the session
# ----------------------------------------------------------------------------------------------------
def _edit(path: Path, fn) -> None:
    stage = Usd.Stage.Open(str(path))
    fn(stage)
    stage.GetRootLayer().Save()


def _world(stage):
    return stage.GetPrimAtPath("/World")


def _set(prim_path: str, attr: str, type_name: str, value):
    """An edit that (re)authors ``attr`` of Sdf type ``type_name`` on ``prim_path`` as ``value``."""

    def fn(stage):
        prim = stage.GetPrimAtPath(prim_path)
        assert prim, prim_path
        if prim.HasAttribute(attr):
            prim.RemoveProperty(attr)
        prim.CreateAttribute(attr, getattr(Sdf.ValueTypeNames, type_name)).Set(value)

    return fn


def _plate_samples(translations, orients):
    """Time samples (at 0 s, 0.01 s, ...) of the funnel plate's translate and orient ops."""

    def fn(stage):
        prim = stage.GetPrimAtPath(PLATE)
        t, o = prim.GetAttribute("xformOp:translate"), prim.GetAttribute("xformOp:orient")
        t.Clear()
        o.Clear()
        for k, (p, q) in enumerate(zip(translations, orients)):
            t.Set(Gf.Vec3d(*p), float(k))
            o.Set(Gf.Quatd(*q), float(k))

    return fn


def _plate_points(fn_points):
    def fn(stage):
        attr = stage.GetPrimAtPath(PLATE).GetAttribute("points")
        pts = [tuple(p) for p in attr.Get()]
        attr.Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in fn_points(pts)]))

    return fn


def _plate_faces(fn_faces):
    """Edit the plate's (faceVertexCounts, faceVertexIndices) lists."""

    def fn(stage):
        prim = stage.GetPrimAtPath(PLATE)
        ca, ia = prim.GetAttribute("faceVertexCounts"), prim.GetAttribute("faceVertexIndices")
        counts, idx = fn_faces(list(ca.Get()), list(ia.Get()))
        ca.Set(Vt.IntArray(counts))
        ia.Set(Vt.IntArray(idx))

    return fn


def _coat_plate(stage):
    prim = stage.GetPrimAtPath(PLATE)
    prim.CreateAttribute("warpdem:coat:radius", Sdf.ValueTypeNames.Double).Set(0.002)
    prim.CreateRelationship("warpdem:coat:material").SetTargets([Sdf.Path("/World/Materials/grain")])


def _all(*fns):
    def fn(stage):
        for f in fns:
            f(stage)

    return fn


PLATE = "/World/Walls/Plate"
POUR = "/World/Factories/pour"
GRAIN = "/World/Materials/grain"
PAIR = "/World/Materials/Pairs/grain__grain"
NAN = float("nan")

STAGE_EDITS: dict[str, tuple[str, Callable]] = {
    # name: (base stage, edit)
    "wrong-type-duration": ("funnel", _set("/World", "warpdem:run:duration", "String", "0.05")),
    "nan-duration": ("funnel", _set("/World", "warpdem:run:duration", "Double", NAN)),
    "output-interval-0": ("funnel", _set("/World", "warpdem:run:outputInterval", "Double", 0.0)),
    "dt-fraction-5": ("funnel", _set("/World", "warpdem:run:dtFraction", "Double", 5.0)),
    "settle-energy-neg": ("funnel", _set("/World", "warpdem:run:settleEnergy", "Double", -1.0)),
    "base-height-nan": ("funnel", _set("/World", "warpdem:measure:baseHeight", "Double", NAN)),
    "bad-authoring-json": ("funnel", _set("/World", "warpdem:authoring", "String", '{"count": 20,')),
    "unknown-law-token": ("funnel", _set(PAIR, "warpdem:pair:law", "Token", "HERTZ")),
    "pair-restitution-2": ("funnel", _set(PAIR, "warpdem:pair:restitution", "Double", 2.0)),
    "material-restitution-2": ("funnel", _set(GRAIN, "physics:restitution", "Float", 2.0)),
    "density-negative": ("funnel", _set(GRAIN, "physics:density", "Float", -1.0)),
    "gravity-nan": ("funnel", _set("/World/PhysicsScene", "physics:gravityMagnitude", "Float", NAN)),
    "gravity-direction-zero": (
        "funnel",
        _set("/World/PhysicsScene", "physics:gravityDirection", "Vector3f", Gf.Vec3f(0, 0, 0)),
    ),
    "factory-count-neg": ("funnel", _set(POUR, "warpdem:factory:count", "Int", -10)),
    "factory-size-mean-neg": ("funnel", _set(POUR, "warpdem:factory:sizeMean", "Double", -0.002)),
    "factory-cannot-fit": (
        "funnel",
        _all(_set(POUR, "warpdem:factory:mode", "Token", "fill"), _set(POUR, "warpdem:factory:count", "Int", 100000)),
    ),
    "nan-keyframe": ("funnel", _plate_samples([(0, 0, 0), (NAN, 0, 0)], [(1, 0, 0, 0), (1, 0, 0, 0)])),
    "zero-quaternion": ("funnel", _plate_samples([(0, 0, 0), (0, 0, 0)], [(1, 0, 0, 0), (0, 0, 0, 0)])),
    "zero-area-wall": ("funnel", _plate_points(lambda pts: [(0.0, 0.0, 0.0)] * len(pts))),
    "coated-zero-area-wall": ("funnel", _all(_plate_points(lambda pts: [(0.0, 0.0, 0.0)] * len(pts)), _coat_plate)),
    "face-count-2": ("funnel", _plate_faces(lambda c, i: (c[:-1] + [2], i[:-1]))),
    "face-counts-past-indices": ("funnel", _plate_faces(lambda c, i: (c + [3, 3], i))),
    "face-index-out-of-range": ("funnel", _plate_faces(lambda c, i: (c, [99999] + i[1:]))),
    "phase-ends-decreasing": (
        "truck_tipper",
        _set("/World", "warpdem:measure:phaseEnds", "DoubleArray", Vt.DoubleArray([0.04, 0.02])),
    ),
    # not bad inputs: a pour at 300 m/s (spheres pass through the plate), a launch at 600 m/s (the blow-up case)
    "pour-300-m-s": ("funnel", _set(POUR, "warpdem:factory:initialVelocity", "Double3", Gf.Vec3d(0, 0, -300))),
    "blowup": ("funnel", _set(POUR, "warpdem:factory:initialVelocity", "Double3", Gf.Vec3d(0, 0, -600))),
}


def _raw_stage(base: Path, name: str, path: Path) -> Path:
    """Stages that are not USD at all (or broken text)."""
    text = base.read_text()
    if name == "empty":
        path.write_bytes(b"")
    elif name == "garbage":
        path.write_bytes(b"\x00\x17this is not a stage at all\n" * 20)
    elif name == "truncated":
        path.write_text(text[: len(text) // 2])
    elif name == "non-utf8":
        path.write_bytes(text.replace('"grain"', '"gr\udcffain"', 1).encode("utf-8", "surrogateescape"))
    elif name == "folder":
        path.mkdir()
    elif name == "missing":
        pass
    else:
        raise AssertionError(name)
    return path


STUDY = """\
[study]
name = "bad"
rig = "funnel"
smoke = true
seed = 1

[fixed]
count = 20
duration = 0.05
{fixed}

[[factors]]
name = "A"
parameter = "{a_parameter}"
low = {a_low}
high = {a_high}

[[factors]]
name = "B"
parameter = "interaction.grain.grain.rolling_friction"
low = 0.05
high = 0.3

[design]
kind = "full_factorial"

[[responses]]
name = "height"
measure = "pile_height_m"
unit = "m"
"""

STUDY_DEFAULTS = {"fixed": "", "a_parameter": "interaction.grain.grain.static_friction", "a_low": 0.2, "a_high": 0.8}

DATA = """\
[diagnose]
name = "bad_pile"
rig = "funnel"
smoke = true
seed = 3

[fixed]
count = 20
duration = 0.05
{fixed}

[[parameters]]
name = "mu_s"
parameter = "interaction.grain.grain.static_friction"
low = {low}
high = 1.0

[experiments]
file = "experiments.csv"
"""

DATA_DEFAULTS = {"fixed": "", "low": 0.2}

CSV = """\
id,replicate,split,particle_radius,angle_fit_deg
r2,1,train,0.002,24.0
r2,2,train,0.002,25.0
r3,1,test,0.003,27.5
r25,1,train,0.0025,30.0
r25,2,train,0.0025,31.0
"""


class Corpus:
    """The session's input files, each made on first request under ``root``."""

    def __init__(self, root: Path):
        self.root = root
        self.cache: dict[str, Path] = {}

    def _once(self, key: str, make) -> Path:
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]

    def rig(self, rig: str) -> Path:
        """The rig's smoke stage, cut to :data:`TINY` where the rig has those parameters (the funnel)."""

        def make():
            path = self.root / f"{rig}.usda"
            rigs.new(rig, path, TINY if rig == "funnel" else None, smoke=True)
            return path

        return self._once("rig:" + rig, make)

    def stage(self, name: str) -> Path:
        """A stage edited by :data:`STAGE_EDITS`, or a broken file (:func:`_raw_stage`)."""

        def make():
            path = self.root / "stages" / f"{name}.usda"
            path.parent.mkdir(exist_ok=True)
            if name in STAGE_EDITS:
                rig, edit = STAGE_EDITS[name]
                shutil.copy(self.rig(rig), path)
                _edit(path, edit)
                return path
            return _raw_stage(self.rig("funnel"), name, path)

        return self._once("stage:" + name, make)

    def study(self, name: str, raw: bytes | None = None, **fields) -> Path:
        """Study file ``name``: :data:`STUDY` with ``fields``, or the bytes ``raw``."""

        def make():
            path = self.root / "studies" / f"{name}.toml"
            path.parent.mkdir(exist_ok=True)
            if raw is None:
                path.write_text(STUDY.format(**{**STUDY_DEFAULTS, **fields}))
            else:
                path.write_bytes(raw)
            return path

        return self._once("study:" + name, make)

    def data(self, name: str, raw: bytes | None = None, csv: str = CSV, **fields) -> Path:
        """Diagnosis file ``name`` (in a folder of its own, with its experiments.csv)."""

        def make():
            folder = self.root / "data" / name
            folder.mkdir(parents=True)
            path = folder / "data.toml"
            (folder / "experiments.csv").write_text(csv)
            if raw is None:
                path.write_text(DATA.format(**{**DATA_DEFAULTS, **fields}))
            else:
                path.write_bytes(raw)
            return path

        return self._once("data:" + name, make)


@dataclass
class Ctx:
    """What an argument builder gets: the session's corpus and the case's own empty folder."""

    corpus: Corpus
    tmp: Path

    @property
    def out(self) -> str:
        return str(self.tmp / "out")

    def run(self, stage: Path | str, *extra: str) -> list[str]:
        """``warpdem run STAGE`` without frames into the case's folder, then ``extra``."""
        return ["run", str(stage), "--no-frames", "--checkpoint", "0", "--out", self.out, *extra]

    def run_set(self, *sets: str) -> list[str]:
        """``warpdem run`` of the tiny funnel with ``--set`` overrides."""
        return self.run(self.corpus.rig("funnel"), *[a for s in sets for a in ("--set", s)])

    def study(self, path: Path | str, *extra: str) -> list[str]:
        return ["study", str(path), "--out", self.out, "--no-progress", "--no-verify", "--checkpoint", "0", *extra]

    def diagnose(self, path: Path | str, *extra: str) -> list[str]:
        return ["diagnose", str(path), "--out", self.out, "--no-progress", *extra]

    def scene(self, rig: str, *sets: str, output: str | None = None) -> list[str]:
        out = output or str(self.tmp / f"{rig}.usda")
        return ["scene", "new", rig, "--smoke", "-o", out, *[a for s in sets for a in ("--set", s)]]


# ----------------------------------------------------------------------------------------------------
# the cases
# ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    route: str
    name: str
    argv: Callable[[Ctx], list[str]]
    rc: int
    needles: tuple[str, ...]

    @property
    def id(self) -> str:
        return f"{self.route}:{self.name}"


def _set_case(name: str, sets: str | tuple, needles: tuple, rc: int = 2) -> Case:
    sets = (sets,) if isinstance(sets, str) else sets
    return Case("run-set", name, lambda c: c.run_set(*sets), rc, needles)


def _stage_case(name: str, needles: tuple, rc: int = 2, extra: tuple = ()) -> Case:
    return Case("stage", name, lambda c: c.run(c.corpus.stage(name), *extra), rc, needles)


def _scene_case(name: str, sets: str | tuple, needles: tuple, rig: str = "funnel", rc: int = 2) -> Case:
    sets = (sets,) if isinstance(sets, str) else sets
    return Case("scene", name, lambda c: c.scene(rig, *sets), rc, needles)


def _study_case(name: str, needles: tuple, rc: int = 2, **fields) -> Case:
    return Case("study", name, lambda c: c.study(c.corpus.study(name, **fields)), rc, needles)


def _study_raw(name: str, make_raw: Callable[[], bytes], needles: tuple) -> Case:
    return Case("study", name, lambda c: c.study(c.corpus.study(name, raw=make_raw())), 2, needles)


def _data_case(name: str, needles: tuple, rc: int = 2, **fields) -> Case:
    return Case("diagnose", name, lambda c: c.diagnose(c.corpus.data(name, **fields)), rc, needles)


def _study_text(**fields) -> str:
    return STUDY.format(**{**STUDY_DEFAULTS, **fields})


def _folder(c: Ctx, name: str) -> str:
    path = c.tmp / name
    path.mkdir()
    return str(path)


CASES: list[Case] = [
    # ---- warpdem run STAGE --set ...: material, interaction, run, measure, factory keys and rig parameters
    _set_case("density-negative", "material.grain.density=-1", ("material.grain.density", "-1")),
    _set_case("density-zero", "material.grain.density=0", ("material.grain.density", "0")),
    _set_case("density-bool", "material.grain.density=true", ("material.grain.density", "true")),
    _set_case("density-nan", "material.grain.density=nan", ("material.grain.density", "nan")),
    _set_case("density-inf", "material.grain.density=inf", ("material.grain.density", "inf")),
    _set_case("density-word", "material.grain.density=abc", ("material.grain.density", "abc")),
    _set_case("poisson-0.6", "material.grain.poisson_ratio=0.6", ("material.grain.poisson_ratio", "0.6")),
    _set_case("shear-modulus-negative", "material.grain.shear_modulus=-1e6", ("material.grain.shear_modulus",)),
    _set_case("material-unknown", "material.sand.density=1000", ("material.sand", "grain")),
    _set_case("material-field-unknown", "material.grain.colour=1", ("material.grain.colour",)),
    _set_case("restitution-2", "interaction.grain.grain.restitution=2.0", ("interaction.grain.grain.restitution", "2")),
    _set_case(
        "friction-negative",
        "interaction.grain.grain.static_friction=-0.1",
        ("interaction.grain.grain.static_friction", "-0.1"),
    ),
    _set_case(
        "rolling-friction-nan",
        "interaction.grain.grain.rolling_friction=nan",
        ("interaction.grain.grain.rolling_friction", "nan"),
    ),
    _set_case("law-unknown", "interaction.grain.grain.law=HERTZ", ("interaction.grain.grain.law", "HERTZ")),
    _set_case(
        "restitution-bool", "interaction.grain.grain.restitution=true", ("interaction.grain.grain.restitution", "true")
    ),
    _set_case("duration-negative", "run.duration=-1", ("run.duration", "-1")),
    _set_case("duration-zero", "run.duration=0", ("run.duration", "0")),
    _set_case("duration-word", "run.duration=abc", ("run.duration", "abc")),
    _set_case("duration-inf", "run.duration=inf", ("run.duration", "inf")),
    _set_case("dt-fraction-5", "run.dt_fraction=5", ("run.dt_fraction", "5")),
    _set_case("dt-fraction-bool", "run.dt_fraction=true", ("run.dt_fraction", "true")),
    _set_case("dt-levels-fraction", "run.dt_levels=2.5", ("run.dt_levels", "2.5")),
    _set_case("skin-fraction-nan", "run.skin_fraction=nan", ("run.skin_fraction", "nan")),
    _set_case("settle-energy-negative", "run.settle_energy=-1", ("run.settle_energy", "-1")),
    _set_case("clump-contact-mass-word", "run.clump_contact_mass=heavy", ("run.clump_contact_mass", "heavy")),
    _set_case("run-key-unknown", "run.durations=1", ("run.durations",)),
    _set_case("base-height-nan", "measure.base_height=nan", ("measure.base_height", "nan")),
    _set_case("force-limit-negative", "measure.force_limit=-5", ("measure.force_limit", "-5")),
    _set_case("packing-margin-negative", "measure.packing_margin=-1", ("measure.packing_margin", "-1")),
    _set_case("measure-word", "measure.base_height=abc", ("measure.base_height", "abc")),
    _set_case("factory-count-fraction", "factory.pour.count=1.5", ("factory.pour.count", "1.5")),
    _set_case("factory-count-negative", "factory.pour.count=-10", ("factory.pour.count", "-10")),
    _set_case("factory-rate-zero", "factory.pour.rate=0", ("factory.pour.rate", "0")),
    _set_case("factory-count-bool", "factory.pour.count=true", ("factory.pour.count", "true")),
    _set_case("factory-unknown", "factory.hopper.count=5", ("factory.hopper", "pour")),
    _set_case("rig-count-negative", "count=-5", ("count", "-5")),
    _set_case("rig-count-fraction", "count=1.5", ("count", "1.5")),
    _set_case("rig-count-bool", "count=true", ("count", "true")),
    _set_case("rig-radius-nan", "particle_radius=nan", ("particle_radius", "nan")),
    _set_case("rig-cone-angle-200", "cone_angle=200", ("cone_angle", "200")),
    _set_case("rig-parameter-unknown", "x=abc", ("'x'",)),
    _set_case("rig-particle-word", "particle=cube", ("particle", "cube")),
    _set_case("malformed-no-equals", "run.duration", ("--set", "run.duration")),
    _set_case("malformed-empty-key", "=5", ("--set", "=5")),
    _set_case("malformed-double-dot", "run..duration=1", ("run..duration",)),
    # hang-prone (loops for ever today): the output interval
    _set_case("output-interval-zero", "run.output_interval=0", ("run.output_interval", "0")),
    _set_case("output-interval-negative", "run.output_interval=-1", ("run.output_interval", "-1")),
    _set_case("output-interval-tiny", "run.output_interval=1e-9", ("run.output_interval", "1e-09")),
    # ---- warpdem run of a malformed stage
    _stage_case("missing", ("missing.usda",)),
    _stage_case("folder", ("folder.usda",)),
    _stage_case("empty", ("empty.usda",)),
    _stage_case("garbage", ("garbage.usda",)),
    _stage_case("truncated", ("truncated.usda",)),
    _stage_case("non-utf8", ("non-utf8.usda",)),
    _stage_case("wrong-type-duration", ("warpdem:run:duration", "string")),
    _stage_case("nan-duration", ("warpdem:run:duration", "nan")),
    _stage_case("output-interval-0", ("warpdem:run:outputInterval", "0")),
    _stage_case("dt-fraction-5", ("warpdem:run:dtFraction", "5")),
    _stage_case("settle-energy-neg", ("warpdem:run:settleEnergy", "-1")),
    _stage_case("base-height-nan", ("warpdem:measure:baseHeight", "nan")),
    _stage_case("bad-authoring-json", ("warpdem:authoring",)),
    _stage_case("unknown-law-token", ("warpdem:pair:law", "HERTZ")),
    _stage_case("pair-restitution-2", ("/World/Materials/Pairs/grain__grain", "2")),
    _stage_case("material-restitution-2", (GRAIN, "physics:restitution", "2")),
    _stage_case("density-negative", (GRAIN, "-1")),
    _stage_case("gravity-nan", ("physics:gravityMagnitude", "nan")),
    _stage_case("gravity-direction-zero", ("physics:gravityDirection",)),
    _stage_case("factory-count-neg", (POUR, "warpdem:factory:count", "-10")),
    _stage_case("factory-size-mean-neg", (POUR, "warpdem:factory:sizeMean")),
    _stage_case("factory-cannot-fit", (POUR, "100000")),
    _stage_case("nan-keyframe", (PLATE, "translate", "nan")),
    _stage_case("zero-quaternion", (PLATE, "orient")),
    _stage_case("zero-area-wall", (PLATE, "area")),
    _stage_case("coated-zero-area-wall", (PLATE, "area")),
    _stage_case("face-count-2", (PLATE, "faceVertexCounts")),
    _stage_case("face-counts-past-indices", (PLATE, "faceVertex")),
    _stage_case("face-index-out-of-range", (PLATE, "faceVertexIndices", "99999")),
    _stage_case("phase-ends-decreasing", ("warpdem:measure:phaseEnds",), extra=("--set", "run.duration=0.05")),
    # ---- warpdem scene new RIG --set ...
    _scene_case("count-negative", "count=-5", ("count", "-5")),
    _scene_case("count-fraction", "count=1.5", ("count", "1.5")),
    _scene_case("count-bool", "count=true", ("count", "true")),
    _scene_case("radius-nan", "particle_radius=nan", ("particle_radius", "nan")),
    _scene_case("duration-inf", "duration=inf", ("duration", "inf")),
    _scene_case("cone-angle-200", "cone_angle=200", ("cone_angle", "200")),
    _scene_case("particle-word", "particle=cube", ("particle", "cube")),
    _scene_case("parameter-unknown", "nosuch=1", ("nosuch",)),
    _scene_case("output-interval-zero", "output_interval=0", ("output_interval", "0")),
    _scene_case("malformed-no-equals", "count", ("--set", "count")),
    _scene_case("press-force-limit-negative", "force_limit=-1", ("force_limit", "-1"), rig="die_press"),
    _scene_case("drum-rpm-nan", "rpm=nan", ("rpm", "nan"), rig="rotating_drum"),
    Case(
        "scene",
        "output-under-a-file",
        lambda c: c.scene("funnel", output=str(c.corpus.rig("funnel")) + "/x.usda"),
        5,
        ("x.usda",),
    ),
    # ---- warpdem study FILE
    Case("study", "missing", lambda c: c.study(c.tmp / "nope.toml"), 2, ("nope.toml",)),
    Case("study", "folder", lambda c: c.study(_folder(c, "dir.toml")), 2, ("dir.toml",)),
    _study_raw("empty", lambda: b"", ("empty.toml",)),
    _study_raw(
        "non-utf8",
        lambda: _study_text().replace('"bad"', '"b\udce9d"').encode("utf-8", "surrogateescape"),
        ("non-utf8.toml",),
    ),
    _study_raw("utf16", lambda: _study_text().encode("utf-16"), ("utf16.toml",)),
    _study_raw("bad-toml", lambda: _study_text().replace("seed = 1", "seed = = 1").encode(), ("bad-toml.toml", "TOML")),
    _study_case("fixed-dt-fraction-5", ("[fixed]", "run.dt_fraction", "5"), fixed='"run.dt_fraction" = 5'),
    _study_case("fixed-duration-negative", ("[fixed]", "run.duration", "-1"), fixed='"run.duration" = -1.0'),
    _study_case("fixed-duration-zero", ("[fixed]", "run.duration", "0"), fixed='"run.duration" = 0.0'),
    _study_case("fixed-settle-energy-negative", ("[fixed]", "run.settle_energy"), fixed='"run.settle_energy" = -1.0'),
    _study_case(
        "fixed-factory-count-negative", ("[fixed]", "factory.pour.count", "-10"), fixed='"factory.pour.count" = -10'
    ),
    _study_case(
        "fixed-factory-count-fraction", ("[fixed]", "factory.pour.count", "1.5"), fixed='"factory.pour.count" = 1.5'
    ),
    _study_case(
        "fixed-base-height-nan", ("[fixed]", "measure.base_height", "nan"), fixed='"measure.base_height" = nan'
    ),
    _study_case("fixed-force-limit-negative", ("[fixed]", "measure.force_limit"), fixed='"measure.force_limit" = -5.0'),
    _study_case(
        "fixed-density-bool", ("[fixed]", "material.grain.density", "true"), fixed='"material.grain.density" = true'
    ),
    _study_case("factor-seed-fraction", ("seed", "1.5"), a_parameter="seed", a_low=1.5, a_high=3),
    _study_case("fixed-run-key-unknown", ("[fixed]", "run.durations"), fixed='"run.durations" = 1.0'),
    _study_case(
        "factor-density-1e308",
        ("material.grain.density", "e+308"),
        a_parameter="material.grain.density",
        a_low=400.0,
        a_high=1e308,
    ),
    _study_case(
        "factor-wall-friction-1e308",
        ("interaction.grain.steel.static_friction", "e+308"),
        a_parameter="interaction.grain.steel.static_friction",
        a_low=0.05,
        a_high=1e308,
    ),
    _study_case(
        "factor-density-negative-low",
        ("material.grain.density", "-100"),
        a_parameter="material.grain.density",
        a_low=-100.0,
        a_high=500.0,
    ),
    _study_case(
        "factor-duration-zero-low",
        ("run.duration", "0"),
        a_parameter="run.duration",
        a_low=0.0,
        a_high=0.05,
    ),
    _study_case(
        "fixed-output-interval-zero", ("[fixed]", "run.output_interval", "0"), fixed='"run.output_interval" = 0.0'
    ),
    _study_case(
        "fixed-output-interval-tiny", ("[fixed]", "run.output_interval", "1e-09"), fixed='"run.output_interval" = 1e-9'
    ),
    # ---- warpdem diagnose FILE
    Case("diagnose", "missing", lambda c: c.diagnose(c.tmp / "nope.toml"), 2, ("nope.toml",)),
    Case("diagnose", "folder", lambda c: c.diagnose(_folder(c, "dir.toml")), 2, ("dir.toml",)),
    Case(
        "diagnose",
        "utf16",
        lambda c: c.diagnose(c.corpus.data("utf16", raw=DATA.format(**DATA_DEFAULTS).encode("utf-16"))),
        2,
        ("data.toml",),
    ),
    Case(
        "diagnose",
        "csv-word",
        lambda c: c.diagnose(c.corpus.data("csv-word", csv=CSV.replace("24.0", "twenty"))),
        2,
        ("experiments.csv", "twenty"),
    ),
    _data_case("parameter-low-negative", ("interaction.grain.grain.static_friction", "-0.5"), low=-0.5),
    _data_case("fixed-dt-fraction-5", ("[fixed]", "run.dt_fraction", "5"), fixed='"run.dt_fraction" = 5'),
    _data_case(
        "fixed-output-interval-zero", ("[fixed]", "run.output_interval", "0"), fixed='"run.output_interval" = 0.0'
    ),
    # ---- command-line options
    Case("option", "run-device-gpu", lambda c: c.run_set() + ["--device", "gpu"], 2, ("device", "gpu")),
    Case("option", "run-device-cuda99", lambda c: c.run_set() + ["--device", "cuda:99"], 6, ("cuda:99",)),
    Case(
        "option", "run-checkpoint-negative", lambda c: c.run_set() + ["--checkpoint", "-5"], 2, ("--checkpoint", "-5")
    ),
    Case("option", "run-checkpoint-nan", lambda c: c.run_set() + ["--checkpoint", "nan"], 2, ("--checkpoint", "nan")),
    Case(
        "option", "run-stop-after-negative", lambda c: c.run_set() + ["--stop-after", "-1"], 2, ("--stop-after", "-1")
    ),
    Case(
        "option",
        "study-device-gpu",
        lambda c: c.study(c.corpus.study("valid")) + ["--device", "gpu"],
        2,
        ("device", "gpu"),
    ),
    Case(
        "option",
        "study-checkpoint-negative",
        lambda c: c.study(c.corpus.study("valid")) + ["--checkpoint", "-5"],
        2,
        ("--checkpoint", "-5"),
    ),
    Case(
        "option",
        "diagnose-stop-after-negative",
        lambda c: c.diagnose(c.corpus.data("valid")) + ["--stop-after", "-1"],
        2,
        ("--stop-after", "-1"),
    ),
    # ---- a run that blows up: 20 spheres launched at 600 m/s (above the 500 m/s velocity limit)
    Case("blowup", "launch-600-m-s", lambda c: c.run(c.corpus.stage("blowup")), 4, ("step", "sphere")),
]


# ----------------------------------------------------------------------------------------------------
# the test
# ----------------------------------------------------------------------------------------------------
class CaseTimeout(BaseException):
    """Raised by the guard's alarm inside a case that ran past :data:`GUARD_S` (a BaseException, so that no
    ``except Exception`` of the command line turns it into an exit code)."""


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Corpus:
    return Corpus(tmp_path_factory.mktemp("corpus"))


def _guarded(argv: list[str]):
    """``main(argv)`` under a SIGALRM guard: (exit code, None) or (None, what happened instead)."""

    def alarm(signum, frame):
        raise CaseTimeout(f"still running after {GUARD_S} s (a hang, or an accepted input that simulates)")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(GUARD_S)
    try:
        return main(argv), None
    except CaseTimeout as e:
        return None, f"HANG: {e}"
    except SystemExit as e:
        return None, f"main raised SystemExit({e.code!r}) instead of returning an exit code"
    except BaseException as e:  # noqa: BLE001 - any escape is the finding
        try:
            text = str(e)
        except Exception as inner:  # noqa: BLE001 - pxr errors whose text is not UTF-8
            text = f"<str() failed: {type(inner).__name__}: {inner}>"
        return None, f"main raised {type(e).__name__}: {text}"
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_corpus_covers_every_route():
    """At least 60 cases, every route represented, ids unique."""
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids))
    assert len(CASES) >= 60
    assert {c.route for c in CASES} == {"run-set", "stage", "scene", "study", "diagnose", "option", "blowup"}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_a_clear_error(case: Case, corpus: Corpus, tmp_path, capsys):
    """The command line returns the promised exit code, prints no traceback, and names the field and value."""
    argv = case.argv(Ctx(corpus, tmp_path))
    rc, escaped = _guarded(argv)
    out = capsys.readouterr()
    text = out.out + out.err
    assert escaped is None, f"{escaped}\n--- output ---\n{text[-3000:]}"
    assert "Traceback" not in text, text[-3000:]
    assert rc == case.rc, f"exit code {rc}, expected {case.rc}\n--- output ---\n{text[-3000:]}"
    missing = [n for n in case.needles if n not in text]
    assert not missing, f"the message does not name {missing}\n--- output ---\n{text[-3000:]}"


@pytest.mark.parametrize(
    "name, argv, words",
    [
        # every sphere passes through the plate and leaves the domain; the run itself ends normally
        (
            "pour-300-m-s",
            lambda c: c.run(c.corpus.stage("pour-300-m-s")),
            ("lost", ("of 20 bodies", "left the domain")),
        ),
        # G = 10 Pa: the Rayleigh step is 9 ms, and a falling sphere jumps several radii per step
        (
            "soft-10-pa",
            lambda c: c.run_set("material.grain.shear_modulus=10"),
            ("fast", ("radii of the smallest sphere in one step", "lower run.dt_fraction")),
        ),
        # the funnel's outlet 1 mm above the plate: any pile reaches it
        (
            "pile-at-outlet",
            lambda c: c.run_set("measure.outlet_height=0.001"),
            ("outlet", ("reached the funnel's outlet", "raise outlet_height")),
        ),
    ],
)
def test_suspect_runs_warn(name, argv, words, corpus, tmp_path, capsys):
    """A run whose physics is suspect but that nothing stops ends with exit 0, prints a warning line (no source
    location, no traceback) and records it in the world's metrics, with the check's name."""
    import json

    rc, escaped = _guarded(argv(Ctx(corpus, tmp_path)))
    text = "".join(capsys.readouterr())
    assert escaped is None and rc == 0, (escaped, text[-2000:])
    check, needles = words
    lines = [part.splitlines()[0] for part in text.split("warning: ")[1:]]  # a progress bar may precede one
    assert any(all(n in line for n in needles) for line in lines), text[-2000:]
    assert "Traceback" not in text and "UserWarning" not in text
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert check in {w["check"] for w in metrics["metrics"][0]["warnings"]}
    assert any(needles[0] in line for line in metrics["info"]["warnings"])


def test_a_missing_dependency_names_the_package(tmp_path, monkeypatch, capsys):
    """An install without its dependencies (pip --no-deps, as on a machine with no index) fails at the first
    import of one: the command line names the package and how to install it, exit code 8, no traceback; an
    import of warpdem's own that fails stays a bug (70)."""
    import sys

    from warpdem.errors import ExitCode, classify

    # a study on two CPU processes needs Dask's distributed only once its first launch goes out
    monkeypatch.setitem(sys.modules, "distributed", None)
    out = tmp_path / "out"
    rc = main(["study", "studies/main_funnel_pb.toml", "--device", "cpu,cpu", "--out", str(out), "--no-progress"])
    text = "".join(capsys.readouterr())
    assert rc == ExitCode.MISSING_PACKAGE == 8, text[-2000:]
    assert "'distributed' is not installed" in text and "pip install" in text and "Traceback" not in text
    code, _ = classify(ModuleNotFoundError("No module named 'warpdem.nothing'", name="warpdem.nothing"))
    assert code == ExitCode.INTERNAL
