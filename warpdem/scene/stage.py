"""Scenes as USD stages: a :class:`SceneSpec` written to and read back from a stage, then built into a model.

Stage conventions (every attribute in the ``warpdem:`` namespace is checked: a missing, misspelt or
wrong-typed one is an error that names the prim and the attribute):

* ``/World`` (Xform, the default prim): ``warpdem:rig`` (token), ``warpdem:authoring`` (string, JSON of the
  rig parameters the stage was generated from), run settings ``warpdem:run:*`` and measurement settings
  ``warpdem:measure:*`` (see :class:`RunSpec`, :class:`MeasureSpec`).
* ``/World/PhysicsScene``: ``UsdPhysics.Scene`` (gravity direction and magnitude).
* ``/World/Materials/<name>``: ``UsdShade.Material`` with ``UsdPhysics.MaterialAPI`` (``physics:density``,
  ``physics:staticFriction``, ``physics:dynamicFriction``, ``physics:restitution`` of the material against
  itself) plus ``warpdem:youngsModulus`` or ``warpdem:shearModulus`` [Pa] and ``warpdem:poissonRatio``.
* ``/World/Materials/Pairs/<a>__<b>``: Scope with ``rel warpdem:pair:materials`` (two materials) and the
  contact law of that pair: ``warpdem:pair:law`` (hertz_mindlin | jkr | eepa), restitution, staticFriction,
  rollingFriction, rollingModel, rollingDamping, surfaceEnergy, pullOffForce, slopeExponent,
  plasticityRatio, tensileExponent, tangentialStiffnessMultiplier (what UsdPhysics lacks). A pair that
  follows another (a rig's base plate follows its walls) has ``rel warpdem:pair:follows`` to that pair and
  ``warpdem:pair:own`` (token[]: the fields it keeps, e.g. ``staticFriction``); see ``SceneSpec.pair_follows``.
* ``/World/Shapes/<name>``: Xform, ``warpdem:shape:kind`` = sphere | clump; a clump's spheres are child
  ``UsdGeom.Sphere`` prims (``radius`` and ``xformOp:translate`` in the body frame [m]).
* ``/World/Walls/<name>``: ``UsdGeom.Mesh`` in its own frame, its physics material bound with
  ``material:binding:physics``; motion as time-sampled ``xformOp:translate`` / ``xformOp:orient`` (the engine
  follows the samples: linear translation, slerped rotation); optional particle coating ``warpdem:coat:*``.
* ``/World/Factories/<name>``: ``UsdGeom.Cube`` (a box: ``size`` 1 scaled by ``xformOp:scale``) or
  ``UsdGeom.Cylinder`` (axis Z; with ``warpdem:factory:topRadius`` a frustum), ``xformOp:translate`` at its
  centre, purpose ``guide``, and ``warpdem:factory:*`` (mode fill | dynamic, material and shape
  relationships, count or mass, rate or massRate, start time, size distribution, seed, initial velocity).

Time codes: ``timeCodesPerSecond`` = :data:`TIME_CODES_PER_SECOND`, so time code = 100 x time [s].
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
from dataclasses import dataclass, field

import numpy as np

from warpdem.engine.checks import check, did_you_mean, enum_value, number_fields, optional_fields, short, typed_number
from warpdem.engine.keys import KeyGrammar
from warpdem.engine.materials import INTERACTION_ENUMS, INTERACTION_FIELDS, MATERIAL_SCALARS, Interaction, Material
from warpdem.engine.solver import CLUMP_CONTACT_MASSES
from warpdem.errors import FileSystemError, InputError

TIME_CODES_PER_SECOND = 100.0
NS = "warpdem:"


class StageError(InputError):
    """A stage is missing something the engine needs, or holds a value it cannot use."""


# ----------------------------------------------------------------------------------------------------
# the scene description
# ----------------------------------------------------------------------------------------------------
@dataclass
class ShapeSpec:
    """Particle shape: ``kind`` "sphere", or "clump" with spheres ``sphere_offset`` (s, 3) [m] and
    ``sphere_radius`` (s,) [m] in the body frame (a factory's size distribution scales the clump so that its
    volume-equivalent radius is the drawn size)."""

    name: str
    kind: str = "sphere"
    sphere_offset: np.ndarray | None = None
    sphere_radius: np.ndarray | None = None

    def template(self):
        """The ClumpTemplate of a clump shape (None for spheres)."""
        if self.kind == "sphere":
            return None
        from warpdem.engine.clumps import ClumpTemplate

        return ClumpTemplate.from_spheres(self.name, self.sphere_offset, self.sphere_radius)


@dataclass
class WallSpec:
    """Mesh wall: ``vertices`` (V, 3) [m] in its own frame, ``triangles`` (F, 3); motion keyframes ``times``
    (K,) [s], ``translations`` (K, 3) [m], ``rotations`` (K, 4) quaternions (x, y, z, w), or none (static at
    the identity pose); ``coat``: None or {"radius" [m], "material", "side" (+1/-1), "seed", "spacing" [m]}."""

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    material: str
    times: np.ndarray | None = None
    translations: np.ndarray | None = None
    rotations: np.ndarray | None = None
    coat: dict | None = None


@dataclass
class FactorySpec:
    """Particle factory over a region: ``region`` is ("box", lo (3,), hi (3,)) or ("cylinder", base_center (3,),
    radius, height, top_radius) (axis +z; top_radius None for a cylinder). ``sizes``: {"distribution": fixed |
    normal | lognormal, "radius" | "mean", "std", "low", "high" | "median", "sigma_log"} [m]."""

    name: str
    mode: str
    region: tuple
    material: str
    shape: str
    sizes: dict
    count: int | None = None
    mass: float | None = None
    rate: float | None = None
    mass_rate: float | None = None
    start_time: float = 0.0
    seed: int = 0
    initial_velocity: tuple = (0.0, 0.0, 0.0)
    interval: float | None = None


@dataclass
class RunSpec:
    """Run settings: ``duration`` [s]; ``dt_fraction`` of the Rayleigh time; a run stops early once the mean
    kinetic energy per particle stays below ``settle_energy`` [J] (0: never) for three outputs after
    ``settle_after`` [s] with every factory done; ``output_interval`` [s] between frames;
    ``impact_speed_min`` [m/s], ``clump_contact_mass`` ("shared" or "body", a token in USD),
    ``skin_fraction`` (the Verlet skin over the smallest radius), ``dt_margin`` (the fraction of the stiffest
    contact's stable step a step may use) and ``dt_levels`` (how often the step may halve to keep it) as in
    SolverOptions."""

    duration: float = 1.0
    dt_fraction: float = 0.2
    settle_energy: float = 0.0
    settle_after: float = 0.0
    output_interval: float = 0.05
    impact_speed_min: float = 0.05
    clump_contact_mass: str = "shared"
    skin_fraction: float = 0.4
    dt_margin: float = 0.5
    dt_levels: int = 6


@dataclass
class MeasureSpec:
    """What the run measures: ``kind`` angle_of_repose | press | impacts | drum. Angle of repose: the base height
    ``base_height`` [m] and pile axis ``center`` (x, y) [m]. Press: the ``piston`` wall, ``force_limit`` [N]
    (the run stops there) and ``backstop_height`` [m]. Impacts: the ``walls`` whose faces are counted and the
    phases (``phase_names``, ``phase_ends`` [s]). Drum: ``drum_center``, ``drum_axis``, ``drum_radius`` and
    ``average_from``."""

    kind: str = "angle_of_repose"
    base_height: float = 0.0
    center: tuple = (0.0, 0.0)
    piston: str = ""
    force_limit: float = 0.0
    backstop_height: float = 0.0
    walls: list = field(default_factory=list)
    phase_names: list = field(default_factory=list)
    phase_ends: list = field(default_factory=list)
    pile_apart: float = 1.0
    """Angle of repose: the widest surface gap [-, in units of r_i + r_j] between grains of one pile
    (``measure.pile_spheres``): grains further from the pile's main body lie apart on the plate and are not
    measured. 0: every grain that stands on the base through touching grains is the pile (the rule before
    issue 23's third stage)."""
    pour_radius: float = 0.0
    """Angle of repose: the radius [m] about ``center`` of what the pile was poured from or lifted out of (a
    funnel's outlet, a lifting cylinder's bore). A pile whose centre of mass lies further off the axis moved as a
    body after it was built, and the run warns (``suspect.off_axis_warning``); 0: not checked."""
    first_contact_window: float = 0.0
    """Impacts: how long [s] after the first impact on ``walls`` the impacts are also summed as the phase
    ``first_contacts`` (not reset, so the first phase still counts them): the first grains' fall, apart from
    the pile that builds up after. The window starts at the output tick that first sees an impact, so it
    covers up to one output interval more; 0: not split."""
    packing_time: float = 0.0
    """Angle of repose: the time [s] at which the bed's packing fraction and bulk density are measured, in the
    container it was poured into (the lifting cylinder before it lifts); 0: not measured."""
    packing_radius: float = 0.0
    """The container's inner radius [m] about ``center`` (see ``measure.packing_core``)."""
    packing_margin: float = 2.0
    """How far the measured core stays from the container's wall, its base and the free surface [particle
    diameters]."""
    packing_base: float | None = None
    """The height [m] of the container's base for the packing core; None: ``base_height`` (a container standing
    on the base plate, as the lifting cylinder; a funnel's fill rests on its closed gate instead)."""
    unload_speed: float = 0.0
    """Press: the speed [m/s] at which the piston retracts once the force reaches ``force_limit``, back to
    where its stroke began, recording the unloading branch; 0: the run stops at the force limit."""
    hold_time: float = 0.0
    """Press: how long [s] the piston holds still at the force limit before it retracts."""
    outlet_height: float | None = None
    """Angle of repose from a funnel: the height [m] of its outlet's lower edge; a body whose centre is below it
    has discharged, and the run reports the steady discharge rate (``measure.discharge_rate``). None: not
    measured."""
    drum_center: tuple = (0.0, 0.0, 0.0)
    """Drum: a point on the rotating drum's axis (its centre) [m]."""
    drum_axis: tuple = (0.0, 1.0, 0.0)
    """Drum: the direction of its angular velocity (right-hand rule), horizontal; the surface angle is positive
    when the bed rises on the side the wall carries up (``measure.drum_surface``)."""
    drum_radius: float = 0.0
    """Drum: its inner radius [m]."""
    average_from: float = 0.0
    """Drum: the time [s] from which every output frame's surface is measured and averaged (the rotation is
    steady by then)."""


def unload_keyframes(times, translations, t_stop: float, stop, hold: float, speed: float):
    """Keyframes of a press stroke that ends at time ``t_stop`` [s] at ``stop`` (x, y, z) [m], holds for ``hold``
    [s] and returns at ``speed`` [m/s] to where the stroke began.

    ``times`` (K,) and ``translations`` (K, 3) are the keyframes up to the stroke's planned end: the last one
    is replaced by the stop, and the stroke began at the one before it. Two keyframes follow the stop (the hold's
    end and the return; with no hold, the return's midpoint and end), so the count is K + 2 whatever the stop:
    the runner can move them to where the force limit ends a stroke without changing the wall's segments.

    Returns:
        (times (K + 2,) [s], translations (K + 2, 3) [m]).
    """
    t = [float(x) for x in times][:-1]
    tr = [np.asarray(x, dtype=float) for x in translations][:-1]
    start, stop = tr[-1], np.asarray(stop, dtype=float)
    back = float(np.linalg.norm(start - stop)) / speed
    if hold > 0:
        t += [t_stop, t_stop + hold, t_stop + hold + back]
        tr += [stop, stop, start]
    else:
        t += [t_stop, t_stop + back / 2, t_stop + back]
        tr += [stop, (stop + start) / 2, start]
    return np.array(t), np.array(tr)


@dataclass
class SceneSpec:
    """Everything a stage describes; :func:`write_stage` and :func:`read_stage` convert both ways."""

    rig: str
    materials: list
    pairs: list  # (material a, material b, Interaction)
    shapes: list
    walls: list
    factories: list
    run: RunSpec
    measure: MeasureSpec
    gravity: tuple = (0.0, 0.0, -9.81)
    authoring: dict = field(default_factory=dict)
    domain: tuple | None = None
    """((x, y, z) low, (x, y, z) high) [m]: bodies whose centre leaves this box are removed (see
    ``Model.domain``); None removes nothing. In USD: ``warpdem:domainMin`` and ``warpdem:domainMax`` on /World."""
    pair_follows: dict = field(default_factory=dict)
    """{(a, b): (c, d, own)}: pair (a, b) takes each override and per-world variation of pair (c, d) (both
    defined), but of the fields named in ``own`` (a tuple of Interaction fields it keeps): a rig's base plate
    follows its walls, less the rig's own plate friction. An override of (a, b) itself stays on (a, b)."""

    def material(self, name: str) -> Material:
        for m in self.materials:
            if m.name == name:
                return m
        raise StageError(f"material {name!r} is not defined; defined: {', '.join(m.name for m in self.materials)}")

    def shape(self, name: str) -> ShapeSpec:
        for s in self.shapes:
            if s.name == name:
                return s
        raise StageError(f"shape {name!r} is not defined; defined: {', '.join(s.name for s in self.shapes)}")

    def wall(self, name: str) -> WallSpec:
        for w in self.walls:
            if w.name == name:
                return w
        raise StageError(f"wall {name!r} is not defined; defined: {', '.join(w.name for w in self.walls)}")


# ----------------------------------------------------------------------------------------------------
# names: Python field <-> USD attribute
# ----------------------------------------------------------------------------------------------------
def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p.capitalize() for p in rest)


RUN_FIELDS = [f.name for f in dataclasses.fields(RunSpec)]
RUN_TOKENS = {"clump_contact_mass": CLUMP_CONTACT_MASSES}
"""Run settings that are words, with the words allowed (the others are numbers)."""
MEASURE_FIELDS = [f.name for f in dataclasses.fields(MeasureSpec)]
FACTORY_FIELDS = [
    "mode",
    "material",
    "shape",
    "count",
    "mass",
    "rate",
    "mass_rate",
    "start_time",
    "seed",
    "initial_velocity",
    "interval",
    "top_radius",
    "size_distribution",
    "size_radius",
    "size_mean",
    "size_std",
    "size_low",
    "size_high",
    "size_median",
    "size_sigma_log",
]
COAT_FIELDS = ["radius", "material", "side", "seed", "spacing"]

MEASURE_KINDS = ("angle_of_repose", "press", "impacts", "drum", "none")
"""The values of ``MeasureSpec.kind`` (a stage's ``warpdem:measure:kind``)."""
RUN_NUMBERS = number_fields(RunSpec)
"""Run settings an override sets (the numbers), with their types."""
MEASURE_NUMBERS = number_fields(MeasureSpec)
"""Measurement settings an override sets (the numbers), with their types."""
FACTORY_NUMBERS = number_fields(FactorySpec)
"""Factory settings an override sets (the numbers), with their types."""
OVERRIDES = KeyGrammar(
    {
        "material": MATERIAL_SCALARS,
        "interaction": INTERACTION_FIELDS,
        "run": tuple(RUN_FIELDS),
        "measure": tuple(MEASURE_NUMBERS),
        "factory": tuple(FACTORY_NUMBERS),
    }
)
"""The keys :func:`apply_overrides` takes (see :mod:`warpdem.engine.keys`); rig parameters are
:func:`warpdem.scene.rigs.load`'s."""

KNOWN = {
    "world": {NS + "rig", NS + "authoring", NS + "domainMin", NS + "domainMax"}
    | {NS + "run:" + _camel(f) for f in RUN_FIELDS}
    | {NS + "measure:" + _camel(f) for f in MEASURE_FIELDS},
    "material": {NS + "youngsModulus", NS + "shearModulus", NS + "poissonRatio"},
    "pair": {NS + "pair:materials", NS + "pair:follows", NS + "pair:own"}
    | {NS + "pair:" + _camel(f) for f in INTERACTION_FIELDS},
    "shape": {NS + "shape:kind"},
    "wall": {NS + "coat:" + _camel(f) for f in COAT_FIELDS},
    "factory": {NS + "factory:" + _camel(f) for f in FACTORY_FIELDS},
}


# ----------------------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------------------
def _ident(name: str) -> str:
    from pxr import Tf

    return Tf.MakeValidIdentifier(name)


def _usd_reason(error, undecodable: str) -> str:
    """USD's error text on one line, or ``undecodable`` where it quotes bytes Python cannot print (a file that
    is not UTF-8)."""
    try:
        return " ".join(str(error).split())
    except UnicodeDecodeError:
        return undecodable


def _usd_write(path, write):
    """``write()``, with USD's refusal to write ``path`` (a folder missing or a file in the way, no permission, a
    full disk) raised as FileSystemError naming the path."""
    from pxr import Tf

    try:
        return write()
    except Tf.ErrorException as e:
        reason = _usd_reason(e, "USD could not write it")
        tail = reason[reason.rfind(": '") + 3 :].rstrip("'") if ": '" in reason else reason
        raise FileSystemError(f"{path}: cannot be written: {tail[:300]}") from None


def write_stage(spec: SceneSpec, path=None):
    """Author ``spec`` as a USD stage; saved to ``path`` (.usda / .usdc / .usd) when given. Returns the stage."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

    stage = _usd_write(path, lambda: Usd.Stage.CreateNew(str(path))) if path else Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(TIME_CODES_PER_SECOND)
    end = max([float(w.times[-1]) for w in spec.walls if w.times is not None] + [spec.run.duration])
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(end * TIME_CODES_PER_SECOND)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    wp_ = world.GetPrim()
    wp_.CreateAttribute(NS + "rig", Sdf.ValueTypeNames.Token).Set(spec.rig)
    wp_.CreateAttribute(NS + "authoring", Sdf.ValueTypeNames.String).Set(json.dumps(spec.authoring, sort_keys=True))
    if spec.domain is not None:
        wp_.CreateAttribute(NS + "domainMin", Sdf.ValueTypeNames.Double3).Set(Gf.Vec3d(*spec.domain[0]))
        wp_.CreateAttribute(NS + "domainMax", Sdf.ValueTypeNames.Double3).Set(Gf.Vec3d(*spec.domain[1]))
    for f in RUN_FIELDS:
        if f in RUN_TOKENS:
            wp_.CreateAttribute(NS + "run:" + _camel(f), Sdf.ValueTypeNames.Token).Set(str(getattr(spec.run, f)))
        else:
            wp_.CreateAttribute(NS + "run:" + _camel(f), Sdf.ValueTypeNames.Double).Set(float(getattr(spec.run, f)))
    m = spec.measure
    wp_.CreateAttribute(NS + "measure:kind", Sdf.ValueTypeNames.Token).Set(m.kind)
    wp_.CreateAttribute(NS + "measure:baseHeight", Sdf.ValueTypeNames.Double).Set(float(m.base_height))
    wp_.CreateAttribute(NS + "measure:center", Sdf.ValueTypeNames.Double2).Set(Gf.Vec2d(*m.center))
    wp_.CreateAttribute(NS + "measure:forceLimit", Sdf.ValueTypeNames.Double).Set(float(m.force_limit))
    wp_.CreateAttribute(NS + "measure:backstopHeight", Sdf.ValueTypeNames.Double).Set(float(m.backstop_height))
    if m.outlet_height is not None:
        wp_.CreateAttribute(NS + "measure:outletHeight", Sdf.ValueTypeNames.Double).Set(float(m.outlet_height))
    if m.kind == "angle_of_repose":
        wp_.CreateAttribute(NS + "measure:pileApart", Sdf.ValueTypeNames.Double).Set(float(m.pile_apart))
    if m.pour_radius > 0:
        wp_.CreateAttribute(NS + "measure:pourRadius", Sdf.ValueTypeNames.Double).Set(float(m.pour_radius))
    if m.unload_speed > 0:
        for name, value in (("unloadSpeed", m.unload_speed), ("holdTime", m.hold_time)):
            wp_.CreateAttribute(NS + "measure:" + name, Sdf.ValueTypeNames.Double).Set(float(value))
    if m.packing_time > 0:
        for name, value in (
            ("packingTime", m.packing_time),
            ("packingRadius", m.packing_radius),
            ("packingMargin", m.packing_margin),
        ):
            wp_.CreateAttribute(NS + "measure:" + name, Sdf.ValueTypeNames.Double).Set(float(value))
        if m.packing_base is not None:
            wp_.CreateAttribute(NS + "measure:packingBase", Sdf.ValueTypeNames.Double).Set(float(m.packing_base))
    if m.kind == "drum":
        for name, value in (("drumCenter", m.drum_center), ("drumAxis", m.drum_axis)):
            wp_.CreateAttribute(NS + "measure:" + name, Sdf.ValueTypeNames.Double3).Set(Gf.Vec3d(*map(float, value)))
        for name, value in (("drumRadius", m.drum_radius), ("averageFrom", m.average_from)):
            wp_.CreateAttribute(NS + "measure:" + name, Sdf.ValueTypeNames.Double).Set(float(value))
    if m.piston:
        wp_.CreateRelationship(NS + "measure:piston").SetTargets([Sdf.Path(f"/World/Walls/{_ident(m.piston)}")])
    if m.walls:
        wp_.CreateRelationship(NS + "measure:walls").SetTargets(
            [Sdf.Path(f"/World/Walls/{_ident(w)}") for w in m.walls]
        )
    if m.phase_names:
        wp_.CreateAttribute(NS + "measure:phaseNames", Sdf.ValueTypeNames.StringArray).Set(list(m.phase_names))
        wp_.CreateAttribute(NS + "measure:phaseEnds", Sdf.ValueTypeNames.DoubleArray).Set(
            [float(t) for t in m.phase_ends]
        )
    if m.first_contact_window > 0:
        wp_.CreateAttribute(NS + "measure:firstContactWindow", Sdf.ValueTypeNames.Double).Set(
            float(m.first_contact_window)
        )

    scene = UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    g = np.asarray(spec.gravity, dtype=float)
    gm = float(np.linalg.norm(g))
    scene.CreateGravityDirectionAttr(Gf.Vec3f(*(g / gm if gm > 0 else (0.0, 0.0, -1.0))))
    scene.CreateGravityMagnitudeAttr(gm)

    UsdGeom.Scope.Define(stage, "/World/Materials")
    self_pair = {(a, b): ia for a, b, ia in spec.pairs if a == b}
    for mat in spec.materials:
        p = f"/World/Materials/{_ident(mat.name)}"
        shade = UsdShade.Material.Define(stage, p)
        api = UsdPhysics.MaterialAPI.Apply(shade.GetPrim())
        api.CreateDensityAttr(float(mat.density))
        ia = self_pair.get((mat.name, mat.name))
        if ia is not None:
            api.CreateStaticFrictionAttr(float(ia.static_friction))
            api.CreateDynamicFrictionAttr(float(ia.static_friction))
            api.CreateRestitutionAttr(float(ia.restitution))
        prim = shade.GetPrim()
        if mat.youngs_modulus is not None and mat.shear_modulus is None:
            prim.CreateAttribute(NS + "youngsModulus", Sdf.ValueTypeNames.Double).Set(float(mat.youngs_modulus))
        else:
            prim.CreateAttribute(NS + "shearModulus", Sdf.ValueTypeNames.Double).Set(float(mat.shear_modulus))
        prim.CreateAttribute(NS + "poissonRatio", Sdf.ValueTypeNames.Double).Set(float(mat.poisson_ratio))
    UsdGeom.Scope.Define(stage, "/World/Materials/Pairs")
    for a, b, ia in spec.pairs:
        prim = UsdGeom.Scope.Define(stage, f"/World/Materials/Pairs/{_ident(a)}__{_ident(b)}").GetPrim()
        prim.CreateRelationship(NS + "pair:materials").SetTargets(
            [Sdf.Path(f"/World/Materials/{_ident(a)}"), Sdf.Path(f"/World/Materials/{_ident(b)}")]
        )
        for f in INTERACTION_FIELDS:
            v = getattr(ia, f)
            if f in INTERACTION_ENUMS:
                prim.CreateAttribute(NS + "pair:" + _camel(f), Sdf.ValueTypeNames.Token).Set(v.name.lower())
            else:
                prim.CreateAttribute(NS + "pair:" + _camel(f), Sdf.ValueTypeNames.Double).Set(float(v))
        lead = spec.pair_follows.get((a, b))
        if lead is not None:
            prim.CreateRelationship(NS + "pair:follows").SetTargets(
                [Sdf.Path(f"/World/Materials/Pairs/{_ident(lead[0])}__{_ident(lead[1])}")]
            )
            if lead[2]:
                prim.CreateAttribute(NS + "pair:own", Sdf.ValueTypeNames.TokenArray).Set([_camel(f) for f in lead[2]])

    UsdGeom.Scope.Define(stage, "/World/Shapes")
    for sh in spec.shapes:
        x = UsdGeom.Xform.Define(stage, f"/World/Shapes/{_ident(sh.name)}")
        x.GetPrim().CreateAttribute(NS + "shape:kind", Sdf.ValueTypeNames.Token).Set(sh.kind)
        # shapes are definitions, not scene content: viewers draw them only through instancing
        UsdGeom.Imageable(x).CreatePurposeAttr(UsdGeom.Tokens.guide)
        if sh.kind == "clump":
            for k, (c, r) in enumerate(zip(np.asarray(sh.sphere_offset), np.asarray(sh.sphere_radius))):
                s = UsdGeom.Sphere.Define(stage, f"/World/Shapes/{_ident(sh.name)}/s{k}")
                s.CreateRadiusAttr(float(r))
                s.AddTranslateOp().Set(Gf.Vec3d(*map(float, c)))

    UsdGeom.Scope.Define(stage, "/World/Walls")
    for w in spec.walls:
        mesh = UsdGeom.Mesh.Define(stage, f"/World/Walls/{_ident(w.name)}")
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(w.vertices, dtype=np.float32)))
        tri = np.asarray(w.triangles, dtype=np.int32)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(tri), 3, dtype=np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(tri.reshape(-1)))
        mesh.CreateDoubleSidedAttr(True)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        prim = mesh.GetPrim()
        UsdPhysics.CollisionAPI.Apply(prim)
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(
            UsdShade.Material(stage.GetPrimAtPath(f"/World/Materials/{_ident(w.material)}")),
            UsdShade.Tokens.weakerThanDescendants,
            "physics",
        )
        t_op = mesh.AddTranslateOp()
        # double precision: a round trip through the stage returns the authored poses exactly
        o_op = mesh.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        if w.times is None:
            t_op.Set(Gf.Vec3d(0, 0, 0))
            o_op.Set(Gf.Quatd(1, 0, 0, 0))
        else:
            for t, p, q in zip(w.times, w.translations, w.rotations):
                code = float(t) * TIME_CODES_PER_SECOND
                t_op.Set(Gf.Vec3d(*map(float, p)), code)
                o_op.Set(Gf.Quatd(float(q[3]), float(q[0]), float(q[1]), float(q[2])), code)
        if w.coat:
            c = w.coat
            prim.CreateAttribute(NS + "coat:radius", Sdf.ValueTypeNames.Double).Set(float(c["radius"]))
            prim.CreateRelationship(NS + "coat:material").SetTargets(
                [Sdf.Path(f"/World/Materials/{_ident(c['material'])}")]
            )
            prim.CreateAttribute(NS + "coat:side", Sdf.ValueTypeNames.Int).Set(int(c.get("side", 1)))
            prim.CreateAttribute(NS + "coat:seed", Sdf.ValueTypeNames.Int).Set(int(c.get("seed", 0)))
            prim.CreateAttribute(NS + "coat:spacing", Sdf.ValueTypeNames.Double).Set(
                float(c.get("spacing") or 2.0 * c["radius"])
            )

    UsdGeom.Scope.Define(stage, "/World/Factories")
    for fac in spec.factories:
        p = f"/World/Factories/{_ident(fac.name)}"
        kind = fac.region[0]
        if kind == "box":
            lo, hi = np.asarray(fac.region[1], float), np.asarray(fac.region[2], float)
            g = UsdGeom.Cube.Define(stage, p)
            g.CreateSizeAttr(1.0)
            g.AddTranslateOp().Set(Gf.Vec3d(*((lo + hi) / 2)))
            g.AddScaleOp().Set(Gf.Vec3f(*(hi - lo)))
        else:
            base, radius, height, top = fac.region[1:5]
            g = UsdGeom.Cylinder.Define(stage, p)
            g.CreateAxisAttr(UsdGeom.Tokens.z)
            g.CreateRadiusAttr(float(radius))
            g.CreateHeightAttr(float(height))
            base = np.asarray(base, float)
            g.AddTranslateOp().Set(Gf.Vec3d(base[0], base[1], base[2] + height / 2))
        g.CreatePurposeAttr(UsdGeom.Tokens.guide)
        prim = g.GetPrim()
        _factory_attr(prim, "mode", "Token", fac.mode)
        prim.CreateRelationship(NS + "factory:material").SetTargets(
            [Sdf.Path(f"/World/Materials/{_ident(fac.material)}")]
        )
        prim.CreateRelationship(NS + "factory:shape").SetTargets([Sdf.Path(f"/World/Shapes/{_ident(fac.shape)}")])
        if kind == "cylinder" and fac.region[4] is not None:
            _factory_attr(prim, "topRadius", "Double", float(fac.region[4]))
        for name, value in (("count", fac.count), ("seed", fac.seed)):
            if value is not None:
                _factory_attr(prim, name, "Int", int(value))
        for name, value in (
            ("mass", fac.mass),
            ("rate", fac.rate),
            ("massRate", fac.mass_rate),
            ("startTime", fac.start_time),
            ("interval", fac.interval),
        ):
            if value is not None:
                _factory_attr(prim, name, "Double", float(value))
        _factory_attr(prim, "initialVelocity", "Double3", Gf.Vec3d(*map(float, fac.initial_velocity)))
        sz = dict(fac.sizes)
        _factory_attr(prim, "sizeDistribution", "Token", sz.pop("distribution"))
        for k, v in sz.items():
            _factory_attr(prim, "size" + k[0].upper() + _camel(k)[1:], "Double", float(v))
    if path:
        _usd_write(path, stage.GetRootLayer().Save)
    return stage


def _factory_attr(prim, name: str, type_name: str, value) -> None:
    """Author ``warpdem:factory:<name>`` of Sdf value type ``type_name`` on ``prim``."""
    from pxr import Sdf

    prim.CreateAttribute(NS + "factory:" + name, getattr(Sdf.ValueTypeNames, type_name)).Set(value)


# ----------------------------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------------------------
_NUMBER = {"double", "float", "half"}


class _Reader:
    def __init__(self, stage, where: str):
        self.stage = stage
        self.where = where

    def fail(self, prim, attr: str, msg: str):
        raise StageError(f"{self.where}: prim {prim.GetPath()}: attribute {attr!r} {msg}")

    def check_names(self, prim, role: str, also=()):
        """Every authored warpdem: attribute of ``prim`` must be known for its ``role`` (catches misspellings)."""
        known = KNOWN[role] | set(also)
        for prop in prim.GetAuthoredProperties():
            name = prop.GetName()
            if name.startswith(NS) and name not in known:
                hint = f"{did_you_mean(name, known)}; known: {', '.join(sorted(known))}"
                self.fail(prim, name, f"is not a warpdem attribute here{hint}")

    def get(self, prim, name: str, kind: str = "number", required: bool = True, default=None, time=None):
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            if required:
                self.fail(prim, name, f"is missing; expected a {kind}")
            return default
        tname = str(attr.GetTypeName())
        value = attr.Get() if time is None else attr.Get(time)
        if kind == "number":
            if tname not in _NUMBER:
                self.fail(prim, name, f"has type {tname}; expected double")
            value = float(value)
            if not math.isfinite(value):
                self.fail(prim, name, f"= {value!r} is not finite")
            return value
        if kind == "int":
            if tname not in ("int", "int64", "uint"):
                self.fail(prim, name, f"has type {tname}; expected int")
            return int(value)
        if kind == "token":
            if tname not in ("token", "string"):
                self.fail(prim, name, f"has type {tname}; expected token")
            return str(value)
        if kind == "string":
            if tname != "string":
                self.fail(prim, name, f"has type {tname}; expected string")
            return str(value)
        if kind == "vec3":
            if tname not in ("double3", "float3", "vector3d", "vector3f", "point3d", "point3f"):
                self.fail(prim, name, f"has type {tname}; expected double3")
            return tuple(float(v) for v in value)
        if kind == "vec2":
            if tname not in ("double2", "float2"):
                self.fail(prim, name, f"has type {tname}; expected double2")
            return tuple(float(v) for v in value)
        if kind == "string[]":
            if tname not in ("string[]", "token[]"):
                self.fail(prim, name, f"has type {tname}; expected string[]")
            return [str(v) for v in value]
        if kind == "double[]":
            if tname not in ("double[]", "float[]"):
                self.fail(prim, name, f"has type {tname}; expected double[]")
            return [float(v) for v in value]
        raise AssertionError(kind)

    def target(self, prim, name: str, required: bool = True, many: bool = False):
        rel = prim.GetRelationship(name)
        targets = rel.GetTargets() if rel else []
        if not targets:
            if required:
                self.fail(prim, name, "is missing; expected a relationship to a prim")
            return [] if many else None
        for t in targets:
            if not self.stage.GetPrimAtPath(t):
                self.fail(prim, name, f"targets {t}, which does not exist")
        return [self.stage.GetPrimAtPath(t) for t in targets] if many else self.stage.GetPrimAtPath(targets[0])


def _prim_name(prim) -> str:
    return prim.GetName()


def open_stage(path) -> Usd.Stage:  # noqa: F821 (pxr is imported where it is used)
    """The USD stage in file ``path``; a file that is missing, a folder, empty or not a stage USD can read
    raises StageError naming the file and USD's reason."""
    import os

    from pxr import Tf, Usd

    path = str(path)
    if not os.path.exists(path):
        raise StageError(f"{path}: no such file; expected a USD stage (.usda, .usdc or .usd)")
    if os.path.isdir(path):
        raise StageError(f"{path}: is a folder; expected a USD stage file (.usda, .usdc or .usd)")
    if os.path.getsize(path) == 0:
        raise StageError(f"{path}: is empty; expected a USD stage")
    try:
        stage = Usd.Stage.Open(path)
    except Tf.ErrorException as e:
        reason = _usd_reason(e, "it is not UTF-8 text or USD's binary format")
        for marker in ("Failed to open layer", "Could not open", "syntax error", "Error"):
            if marker in reason:
                reason = reason[reason.index(marker) :]
                break
        raise StageError(f"{path}: cannot be read as a USD stage: {reason[:300]}") from None
    except UnicodeDecodeError as e:
        raise StageError(f"{path}: cannot be read as a USD stage: {e}") from None
    if stage is None:
        raise StageError(f"{path}: cannot be read as a USD stage")
    return stage


def read_stage(path_or_stage) -> SceneSpec:
    """Read a stage written by :func:`write_stage` (or by hand, following the module's conventions)."""
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    if isinstance(path_or_stage, Usd.Stage):
        stage, where = path_or_stage, "stage"
    else:
        where = str(path_or_stage)
        stage = open_stage(where)
    r = _Reader(stage, where)
    world = stage.GetPrimAtPath("/World")
    if not world:
        raise StageError(f"{where}: no /World prim (the default prim holding the scene)")
    r.check_names(world, "world")
    rig = r.get(world, NS + "rig", "token")
    authoring = r.get(world, NS + "authoring", "string", required=False, default="{}") or "{}"
    try:
        authoring = json.loads(authoring)
    except ValueError as e:
        r.fail(world, NS + "authoring", f"= {authoring[:60]!r} is not allowed; expected a JSON object ({e})")
    if not isinstance(authoring, dict):
        r.fail(world, NS + "authoring", f"= {authoring!r} is not allowed; expected a JSON object of rig parameters")
    run = RunSpec(
        **{
            f: r.get(
                world,
                NS + "run:" + _camel(f),
                "token" if f in RUN_TOKENS else "number",
                required=(f == "duration"),
                default=getattr(RunSpec, f),
            )
            for f in RUN_FIELDS
        }
    )
    lo = r.get(world, NS + "domainMin", "vec3", required=False)
    hi = r.get(world, NS + "domainMax", "vec3", required=False)
    domain = None
    if (lo is None) != (hi is None):
        missing = "domainMax" if hi is None else "domainMin"
        r.fail(world, NS + missing, "is missing; a domain needs both warpdem:domainMin and warpdem:domainMax (double3)")
    if lo is not None:
        if not all(a < b for a, b in zip(lo, hi)):
            r.fail(
                world,
                NS + "domainMax",
                f"= {hi} is not allowed; expected greater than warpdem:domainMin = {lo} on every axis",
            )
        domain = (lo, hi)

    kind = r.get(world, NS + "measure:kind", "token", required=False, default="none")
    measure = MeasureSpec(
        kind=kind,
        base_height=r.get(world, NS + "measure:baseHeight", required=False, default=0.0),
        center=r.get(world, NS + "measure:center", "vec2", required=False, default=(0.0, 0.0)),
        force_limit=r.get(world, NS + "measure:forceLimit", required=False, default=0.0),
        backstop_height=r.get(world, NS + "measure:backstopHeight", required=False, default=0.0),
        phase_names=r.get(world, NS + "measure:phaseNames", "string[]", required=False, default=[]),
        phase_ends=r.get(world, NS + "measure:phaseEnds", "double[]", required=False, default=[]),
        first_contact_window=r.get(world, NS + "measure:firstContactWindow", required=False, default=0.0),
        packing_time=r.get(world, NS + "measure:packingTime", required=False, default=0.0),
        packing_radius=r.get(world, NS + "measure:packingRadius", required=False, default=0.0),
        packing_margin=r.get(world, NS + "measure:packingMargin", required=False, default=2.0),
        packing_base=r.get(world, NS + "measure:packingBase", required=False, default=None),
        unload_speed=r.get(world, NS + "measure:unloadSpeed", required=False, default=0.0),
        hold_time=r.get(world, NS + "measure:holdTime", required=False, default=0.0),
        outlet_height=r.get(world, NS + "measure:outletHeight", required=False, default=None),
        pile_apart=r.get(world, NS + "measure:pileApart", required=False, default=1.0),
        pour_radius=r.get(world, NS + "measure:pourRadius", required=False, default=0.0),
    )
    if kind == "drum":
        measure.drum_center = r.get(world, NS + "measure:drumCenter", "vec3")
        measure.drum_axis = r.get(world, NS + "measure:drumAxis", "vec3")
        measure.drum_radius = r.get(world, NS + "measure:drumRadius")
        measure.average_from = r.get(world, NS + "measure:averageFrom")
    if kind not in MEASURE_KINDS:
        r.fail(world, NS + "measure:kind", f"= {kind!r} is not allowed; expected " + ", ".join(MEASURE_KINDS))
    if kind == "press":
        measure.piston = _prim_name(r.target(world, NS + "measure:piston"))
    if kind == "impacts":
        measure.walls = [_prim_name(p) for p in r.target(world, NS + "measure:walls", many=True)]

    gravity = (0.0, 0.0, -9.81)
    for prim in stage.Traverse():
        if prim.IsA(UsdPhysics.Scene):
            s = UsdPhysics.Scene(prim)
            d = np.asarray(s.GetGravityDirectionAttr().Get() or (0, 0, -1), dtype=float)
            mag = s.GetGravityMagnitudeAttr().Get()
            # UsdPhysics: an unauthored or -inf magnitude means Earth's gravity
            mag = 9.81 if mag is None or (isinstance(mag, float) and math.isinf(mag) and mag < 0) else float(mag)
            if not (math.isfinite(mag) and mag >= 0):
                r.fail(
                    prim, "physics:gravityMagnitude", f"= {mag!r} is not allowed; expected a finite value >= 0 m/s^2"
                )
            if not (np.all(np.isfinite(d)) and np.linalg.norm(d) > 0):
                r.fail(
                    prim,
                    "physics:gravityDirection",
                    f"= {tuple(d.tolist())} is not allowed; expected a finite, non-zero direction",
                )
            gravity = tuple(float(v) for v in mag * d / max(np.linalg.norm(d), 1e-300))

    materials, names = [], {}
    mroot = stage.GetPrimAtPath("/World/Materials")
    if not mroot:
        raise StageError(f"{where}: no /World/Materials scope; expected one UsdShade.Material per material")
    for prim in mroot.GetChildren():
        if not prim.IsA(UsdShade.Material):
            continue
        r.check_names(prim, "material")
        if not prim.HasAPI(UsdPhysics.MaterialAPI):
            raise StageError(f"{where}: prim {prim.GetPath()}: needs UsdPhysics.MaterialAPI (physics:density)")
        density = r.get(prim, "physics:density")
        for attr, ok, allowed in (
            ("physics:restitution", lambda v: 0 <= v <= 1, "a coefficient in [0, 1]"),
            ("physics:staticFriction", lambda v: v >= 0, "a coefficient >= 0"),
            ("physics:dynamicFriction", lambda v: v >= 0, "a coefficient >= 0"),
        ):
            v = r.get(prim, attr, required=False)
            if v is not None and not ok(v):
                r.fail(
                    prim,
                    attr,
                    f"= {v!r} is not allowed; expected {allowed} (warpdem reads a pair's warpdem:pair: attributes "
                    "under /World/Materials/Pairs; this one is for other USD physics tools)",
                )
        kw = dict(
            name=prim.GetName(),
            density=density,
            poisson_ratio=r.get(prim, NS + "poissonRatio"),
            youngs_modulus=r.get(prim, NS + "youngsModulus", required=False),
            shear_modulus=r.get(prim, NS + "shearModulus", required=False),
        )
        if kw["youngs_modulus"] is None and kw["shear_modulus"] is None:
            r.fail(prim, NS + "shearModulus", "is missing (and so is warpdem:youngsModulus); expected one of them [Pa]")
        try:
            materials.append(Material(**kw))
        except ValueError as e:
            raise StageError(f"{where}: prim {prim.GetPath()}: {e}") from None
        names[prim.GetPath()] = prim.GetName()

    pairs, pair_prims, follows = [], {}, {}
    proot = stage.GetPrimAtPath("/World/Materials/Pairs")
    for prim in proot.GetChildren() if proot else []:
        r.check_names(prim, "pair")
        mats = r.target(prim, NS + "pair:materials", many=True)
        if len(mats) == 1:
            mats = mats * 2  # USD keeps a target once: one target is the material against itself
        if len(mats) != 2:
            r.fail(
                prim,
                NS + "pair:materials",
                f"has {len(mats)} targets; expected two materials (one for a material against itself)",
            )
        kw = {}
        for f in INTERACTION_FIELDS:
            name = NS + "pair:" + _camel(f)
            cls = INTERACTION_ENUMS.get(f)
            v = r.get(prim, name, "number" if cls is None else "token", required=False)
            if v is not None and cls is not None:
                try:
                    v = enum_value(cls, "", f, v)
                except ValueError:
                    r.fail(prim, name, f"= {v!r} is not allowed; expected " + ", ".join(m.name.lower() for m in cls))
            if v is not None:
                kw[f] = v
        try:
            ia = Interaction(**kw)
        except ValueError as e:
            raise StageError(f"{where}: prim {prim.GetPath()}: {e}") from None
        pairs.append((mats[0].GetName(), mats[1].GetName(), ia))
        pair_prims[prim.GetPath()] = pairs[-1][:2]
        lead = r.target(prim, NS + "pair:follows", required=False)
        if lead is not None:
            own = r.get(prim, NS + "pair:own", "string[]", required=False, default=[])
            fields = {_camel(f): f for f in INTERACTION_FIELDS}
            bad = [o for o in own if o not in fields]
            if bad:
                r.fail(prim, NS + "pair:own", f"names {bad[0]!r}; expected pair fields: " + ", ".join(fields))
            follows[pairs[-1][:2]] = (prim, lead, tuple(fields[o] for o in own))
    pair_follows = {}
    for key, (prim, lead, own) in follows.items():
        if lead.GetPath() not in pair_prims:
            r.fail(
                prim, NS + "pair:follows", f"targets {lead.GetPath()}, which is not a pair under /World/Materials/Pairs"
            )
        pair_follows[key] = (*pair_prims[lead.GetPath()], own)

    shapes = []
    sroot = stage.GetPrimAtPath("/World/Shapes")
    for prim in sroot.GetChildren() if sroot else []:
        r.check_names(prim, "shape")
        kind = r.get(prim, NS + "shape:kind", "token")
        if kind == "sphere":
            shapes.append(ShapeSpec(prim.GetName(), "sphere"))
        elif kind == "clump":
            off, rad = [], []
            for child in prim.GetChildren():
                if not child.IsA(UsdGeom.Sphere):
                    continue
                rad.append(r.get(child, "radius"))
                m = UsdGeom.Xformable(child).GetLocalTransformation()
                off.append(tuple(m.ExtractTranslation()))
            if not rad:
                r.fail(prim, NS + "shape:kind", "= 'clump' but the prim has no UsdGeom.Sphere children")
            shapes.append(ShapeSpec(prim.GetName(), "clump", np.asarray(off), np.asarray(rad)))
        else:
            r.fail(prim, NS + "shape:kind", f"= {kind!r} is not allowed; expected sphere or clump")

    walls = []
    wroot = stage.GetPrimAtPath("/World/Walls")
    for prim in wroot.GetChildren() if wroot else []:
        if not prim.IsA(UsdGeom.Mesh):
            continue
        walls.append(_read_wall(r, prim, names))

    factories = []
    froot = stage.GetPrimAtPath("/World/Factories")
    for prim in froot.GetChildren() if froot else []:
        factories.append(_read_factory(r, prim))

    spec = SceneSpec(
        rig=rig,
        materials=materials,
        pairs=pairs,
        shapes=shapes,
        walls=walls,
        factories=factories,
        run=run,
        measure=measure,
        gravity=gravity,
        authoring=authoring,
        domain=domain,
        pair_follows=pair_follows,
    )
    from .validate import check_scene, stage_origin

    return check_scene(spec, stage_origin(where))


def _read_wall(r: _Reader, prim, names) -> WallSpec:
    from pxr import Usd, UsdGeom, UsdShade

    r.check_names(prim, "wall")
    mesh = UsdGeom.Mesh(prim)
    pts = mesh.GetPointsAttr().Get()
    if pts is None or len(pts) == 0:
        r.fail(prim, "points", "is missing; expected the mesh vertices [m]")
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if counts.size == 0:
        r.fail(prim, "faceVertexCounts", "is missing; expected the faces")
    if counts.min() < 3 or counts.sum() != idx.size:
        r.fail(
            prim,
            "faceVertexCounts",
            f"= {short(counts)} is not allowed; expected faces of at least 3 vertices whose counts add up to the "
            f"{idx.size} faceVertexIndices",
        )
    if idx.min() < 0 or idx.max() >= len(pts):
        r.fail(prim, "faceVertexIndices", f"holds {int(idx.max())}; expected indices of the {len(pts)} points")
    # polygons become fans of triangles
    tris, at = [], 0
    for c in counts:
        for k in range(1, c - 1):
            tris.append((idx[at], idx[at + k], idx[at + k + 1]))
        at += c
    binding = UsdShade.MaterialBindingAPI(prim).GetDirectBinding("physics")
    mat_path = binding.GetMaterialPath()
    if not mat_path or mat_path not in names:
        r.fail(prim, "material:binding:physics", "is missing or not a material under /World/Materials")
    xf = UsdGeom.Xformable(prim)
    times = set()
    for op in xf.GetOrderedXformOps():
        if op.GetOpType() == UsdGeom.XformOp.TypeScale:
            r.fail(prim, op.GetOpName(), "scales the wall; bake the scale into the points (walls move rigidly)")
        times.update(op.GetTimeSamples())
        _check_op(r, prim, op)
    spec = WallSpec(
        prim.GetName(), np.asarray(pts, dtype=np.float64), np.asarray(tris, dtype=np.int64), names[mat_path]
    )
    samples = sorted(times) or [Usd.TimeCode.Default()]
    poses = []
    for code in samples:
        m = xf.ComputeLocalToWorldTransform(code)
        rot = np.array([[m[i][j] for j in range(3)] for i in range(3)], dtype=float)
        if not (np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) and abs(np.linalg.det(rot) - 1.0) < 1e-6):
            at = "its default" if code == Usd.TimeCode.Default() else f"time code {code}"
            r.fail(
                prim,
                "xformOpOrder",
                f"gives a pose at {at} that is not a rigid motion (a zero or non-unit quaternion, a NaN, a "
                f"shear): rotation rows {np.round(rot, 6).tolist()}; expected unit quaternions and finite values",
            )
        if not np.all(np.isfinite(np.array(m.ExtractTranslation()))):
            at = "its default" if code == Usd.TimeCode.Default() else f"time code {code}"
            r.fail(prim, "xformOpOrder", f"gives a translation at {at} that is not finite; expected finite values")
        q = (
            m.ExtractRotationQuat().GetNormalized()
            if hasattr(m, "ExtractRotationQuat")
            else m.ExtractRotation().GetQuat()
        )
        im = q.GetImaginary()
        poses.append((tuple(m.ExtractTranslation()), (im[0], im[1], im[2], q.GetReal())))
    if len(samples) > 1 or poses[0] != ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)):
        t = [0.0] if not times else [c / TIME_CODES_PER_SECOND for c in samples]
        spec.times = np.asarray(t, dtype=np.float64)
        spec.translations = np.asarray([p for p, _ in poses], dtype=np.float64)
        spec.rotations = np.asarray([q for _, q in poses], dtype=np.float64)
    if prim.GetAttribute(NS + "coat:radius"):
        coat_mat = r.target(prim, NS + "coat:material")
        spec.coat = {
            "radius": r.get(prim, NS + "coat:radius"),
            "material": coat_mat.GetName(),
            "side": r.get(prim, NS + "coat:side", "int", required=False, default=1),
            "seed": r.get(prim, NS + "coat:seed", "int", required=False, default=0),
            "spacing": r.get(prim, NS + "coat:spacing", required=False),
        }
        if spec.coat["radius"] <= 0:
            r.fail(prim, NS + "coat:radius", f"= {spec.coat['radius']} is not allowed; expected a radius > 0 m")
        if spec.coat["side"] not in (1, -1):
            r.fail(prim, NS + "coat:side", f"= {spec.coat['side']} is not allowed; expected 1 or -1")
    return spec


def _check_op(r: _Reader, prim, op) -> None:
    """Every value of a wall's transform op, default and time samples, finite, and an orient op's quaternions of
    unit length (a zero quaternion would silently read as no rotation)."""
    from pxr import Gf, Usd, UsdGeom

    codes = [Usd.TimeCode.Default()] + [Usd.TimeCode(t) for t in op.GetTimeSamples()]
    for code in codes:
        v = op.Get(code)
        if v is None:
            continue
        at = "its default value" if code.IsDefault() else f"time code {code.GetValue():g}"
        if isinstance(v, (Gf.Quatd, Gf.Quatf, Gf.Quath)):
            q = np.array([*v.GetImaginary(), v.GetReal()], dtype=float)
            if not (np.all(np.isfinite(q)) and abs(np.linalg.norm(q) - 1.0) < 1e-3):
                r.fail(
                    prim,
                    op.GetOpName(),
                    f"at {at} = {short(q)} (x, y, z, w) is not allowed; expected a unit quaternion",
                )
            continue
        a = np.array(v, dtype=float) if not isinstance(v, Gf.Matrix4d) else np.array(v, dtype=float)
        if not np.all(np.isfinite(a)):
            r.fail(prim, op.GetOpName(), f"at {at} = {short(a)} is not allowed; expected finite values")
    if op.GetOpType() == UsdGeom.XformOp.TypeInvalid:
        r.fail(prim, op.GetOpName(), "is not a transform op USD knows")


def _read_factory(r: _Reader, prim) -> FactorySpec:
    from pxr import UsdGeom

    r.check_names(prim, "factory")
    P = NS + "factory:"
    xf = UsdGeom.Xformable(prim).GetLocalTransformation()
    center = np.asarray(xf.ExtractTranslation(), dtype=float)
    if prim.IsA(UsdGeom.Cube):
        size = r.get(prim, "size", required=False, default=2.0)
        scale = np.array([np.linalg.norm(np.asarray(xf.GetRow3(k))) for k in range(3)]) * size
        region = ("box", tuple(center - scale / 2), tuple(center + scale / 2))
    elif prim.IsA(UsdGeom.Cylinder):
        axis = r.get(prim, "axis", "token", required=False, default="Z")
        if axis != "Z":
            r.fail(prim, "axis", f"= {axis!r} is not allowed; expected Z (factories stand upright)")
        radius, height = r.get(prim, "radius"), r.get(prim, "height")
        top = r.get(prim, P + "topRadius", required=False)
        region = ("cylinder", tuple(center - (0, 0, height / 2)), radius, height, top)
    else:
        raise StageError(
            f"{r.where}: prim {prim.GetPath()}: a factory must be a UsdGeom.Cube or UsdGeom.Cylinder, "
            f"not {prim.GetTypeName()}"
        )
    mode = r.get(prim, P + "mode", "token")
    if mode not in ("fill", "dynamic"):
        r.fail(prim, P + "mode", f"= {mode!r} is not allowed; expected fill or dynamic")
    dist = r.get(prim, P + "sizeDistribution", "token")
    need = {"fixed": ["radius"], "normal": ["mean", "std", "low", "high"], "lognormal": ["median", "sigma_log"]}
    if dist not in need:
        r.fail(prim, P + "sizeDistribution", f"= {dist!r} is not allowed; expected fixed, normal or lognormal")
    sizes = {"distribution": dist}
    used = need[dist] + (["low", "high"] if dist == "lognormal" else [])
    for k in ("radius", "mean", "std", "low", "high", "median", "sigma_log"):
        name = P + "size" + k[0].upper() + _camel(k)[1:]
        if k not in used and prim.GetAttribute(name).HasAuthoredValue():
            r.fail(
                prim,
                name,
                f"is authored, but a {dist!r} size distribution does not use it; expected only "
                + ", ".join(P + "size" + u[0].upper() + _camel(u)[1:] for u in used),
            )
    for k in used:
        v = r.get(prim, P + "size" + k[0].upper() + _camel(k)[1:], required=k in need[dist])
        if v is not None:
            sizes[k] = v
    fac = FactorySpec(
        name=prim.GetName(),
        mode=mode,
        region=region,
        material=r.target(prim, P + "material").GetName(),
        shape=r.target(prim, P + "shape").GetName(),
        sizes=sizes,
        count=r.get(prim, P + "count", "int", required=False),
        mass=r.get(prim, P + "mass", required=False),
        rate=r.get(prim, P + "rate", required=False),
        mass_rate=r.get(prim, P + "massRate", required=False),
        start_time=r.get(prim, P + "startTime", required=False, default=0.0),
        seed=r.get(prim, P + "seed", "int", required=False, default=0),
        initial_velocity=r.get(prim, P + "initialVelocity", "vec3", required=False, default=(0.0, 0.0, 0.0)),
        interval=r.get(prim, P + "interval", required=False),
    )
    if (fac.count is None) == (fac.mass is None):
        r.fail(prim, P + "count", "and warpdem:factory:mass: expected exactly one of them")
    if mode == "dynamic" and (fac.rate is None) == (fac.mass_rate is None):
        r.fail(prim, P + "rate", "and warpdem:factory:massRate: a dynamic factory needs exactly one of them")
    return fac


# ----------------------------------------------------------------------------------------------------
# overrides and building
# ----------------------------------------------------------------------------------------------------
def apply_overrides(spec: SceneSpec, overrides: dict, where: str = "--set") -> SceneSpec:
    """Apply ``--set`` style overrides (values as strings or numbers) to a spec, in place: the keys of
    :data:`OVERRIDES` (``material.NAME.FIELD``, ``interaction.A.B.FIELD``, ``run.FIELD``, ``measure.FIELD``,
    ``factory.NAME.FIELD``), then check the whole scene (:func:`warpdem.scene.validate.check_scene`). Rig
    parameters (any other key) are handled by :func:`warpdem.scene.rigs.load`. A refused key or value raises
    StageError naming ``where`` (the route: "--set", "[fixed]"), the key, the value and what is allowed."""
    from .validate import check_scene

    defined = {"material": [m.name for m in spec.materials], "factory": [f.name for f in spec.factories]}
    keys = {text: OVERRIDES.parse(text, where, defined=defined, error=StageError) for text in overrides}
    # a pair that follows another keeps the fields these overrides set on it themselves
    explicit = {(frozenset(k.names), k.field) for k in keys.values() if k.kind == "interaction"}
    for text, raw in overrides.items():
        key = keys[text]
        try:
            _apply_override(spec, key, where, text, _parse(raw))
            if key.kind == "interaction":
                for a, b in pair_followers(spec, *key.names, key.field):
                    if (frozenset((a, b)), key.field) not in explicit:
                        _apply_override(spec, dataclasses.replace(key, names=(a, b)), where, text, _parse(raw))
        except StageError:
            raise
        except (TypeError, ValueError) as e:
            # a value the field's own check refuses (Material, Interaction): name the key
            raise StageError(f"{where} {text} = {raw!r}: {e}") from None
    if overrides:
        keys = {str(k) for k in overrides}
        check_scene(spec, lambda k: where if k in keys else "scene")
    return spec


def pair_followers(spec: SceneSpec, a: str, b: str, field: str) -> list[tuple[str, str]]:
    """The pairs that take a change of pair (a, b)'s ``field`` too (:attr:`SceneSpec.pair_follows`)."""
    return [k for k, (c, d, own) in spec.pair_follows.items() if {c, d} == {a, b} and field not in own]


def _apply_override(spec: SceneSpec, key, where: str, text: str, value) -> None:
    """Set one parsed override ``key`` (written ``text``) to ``value`` in ``spec``; ``where`` names the route in a
    message. Numbers are
    not coerced: a bool or a word for a number, or a fraction for a count, is refused."""
    if key.kind == "material":
        m = spec.material(key.names[0])
        value = typed_number(where, text, value, float, error=StageError)
        spec.materials[spec.materials.index(m)] = m.with_value(key.field, value)
    elif key.kind == "interaction":
        a, b = key.names
        # an enum field takes the member's name: Interaction reads it
        for k, (pa, pb, ia) in enumerate(spec.pairs):
            if {pa, pb} == {a, b}:
                spec.pairs[k] = (pa, pb, dataclasses.replace(ia, **{key.field: value}))
                break
        else:
            spec.pairs.append((a, b, Interaction(**{key.field: value})))
    elif key.kind == "run":
        if key.field in RUN_TOKENS:
            check(value in RUN_TOKENS[key.field], where, text, value, " or ".join(RUN_TOKENS[key.field]), StageError)
            setattr(spec.run, key.field, value)
        else:
            setattr(spec.run, key.field, typed_number(where, text, value, RUN_NUMBERS[key.field], error=StageError))
    elif key.kind == "measure":
        kind, optional = MEASURE_NUMBERS[key.field], key.field in _OPTIONAL["measure"]
        setattr(spec.measure, key.field, typed_number(where, text, value, kind, optional, StageError))
    else:
        fac = next(f for f in spec.factories if f.name == key.names[0])
        kind, optional = FACTORY_NUMBERS[key.field], key.field in _OPTIONAL["factory"]
        setattr(fac, key.field, typed_number(where, text, value, kind, optional, StageError))


_OPTIONAL = {"measure": optional_fields(MeasureSpec), "factory": optional_fields(FactorySpec)}


def _parse(raw):
    if not isinstance(raw, str):
        return raw
    try:
        return json.loads(raw)
    except ValueError:
        return raw


def _sizes(d: dict):
    from warpdem.engine.factories import FixedSize, LogNormal, TruncatedNormal

    dist = d["distribution"]
    if dist == "fixed":
        return FixedSize(d["radius"])
    if dist == "normal":
        return TruncatedNormal(d["mean"], d["std"], d["low"], d["high"])
    return LogNormal(d["median"], d["sigma_log"], d.get("low"), d.get("high"))


def _region(region):
    from warpdem.engine.factories import Box, Cone, Cylinder

    if region[0] == "box":
        return Box(region[1], region[2])
    base, radius, height, top = region[1:5]
    if top is None:
        return Cylinder(base, (0, 0, 1), radius, height)
    return Cone(base, (0, 0, 1), radius, top, height)


@contextlib.contextmanager
def _named(what: str):
    """Name the wall or factory whose engine check refused a value (the engine knows no scene names), by the
    prim a stage holds it on."""
    try:
        yield
    except StageError:
        raise
    except InputError as e:
        raise StageError(f"{what}: {e}") from None


def _follow_variations(spec: SceneSpec, variations: dict) -> dict:
    """``variations`` with each ``interaction.A.B.FIELD`` also given to the pairs that follow (A, B)
    (:attr:`SceneSpec.pair_follows`), unless they are varied themselves."""
    out = dict(variations)
    for target, values in variations.items():
        kind, *rest = target.split(".")
        if kind != "interaction" or len(rest) != 3:
            continue
        for a, b in pair_followers(spec, rest[0], rest[1], rest[2]):
            mine = [f"interaction.{a}.{b}.{rest[2]}", f"interaction.{b}.{a}.{rest[2]}"]
            if not any(m in variations for m in mine):
                out[mine[0]] = values
    return out


def world_seeds_move(spec: SceneSpec) -> bool:
    """True when a world seed changes the scene's run: it places the particles of the dynamic factories only (see
    :meth:`warpdem.ModelBuilder.seed_worlds`), so a scene whose particles all come from static fills (the die
    press's bed) runs the same whatever the seed."""
    return any(fac.mode == "dynamic" for fac in spec.factories)


def build(spec: SceneSpec, world_count: int = 1, variations: dict | None = None, world_seeds=None):
    """A :class:`warpdem.ModelBuilder` holding the scene (call ``finalize(device)`` on it).

    ``variations`` maps ``material.NAME.FIELD`` / ``interaction.A.B.FIELD`` to ``world_count`` values: one
    design point per world (see :meth:`warpdem.ModelBuilder.vary`); ``world_seeds`` gives each world's dynamic
    factories a placement seed (see :meth:`warpdem.ModelBuilder.seed_worlds`).
    """
    from warpdem.engine.builder import ModelBuilder
    from warpdem.engine.factories import DynamicFactory
    from warpdem.engine.motion import WallMotion

    from .validate import check_scene

    check_scene(spec)
    b = ModelBuilder(gravity=spec.gravity)
    if spec.domain is not None:
        b.set_domain(*spec.domain)
    for m in spec.materials:
        b.add_material(m)
    for a, c, ia in spec.pairs:
        b.set_interaction(a, c, ia)
    for w in spec.walls:
        with _named(f"wall /World/Walls/{w.name}"):
            motion = None if w.times is None else WallMotion.keyframes(w.times, w.translations, w.rotations)
            k = b.add_wall_mesh(w.vertices, w.triangles, w.material, name=w.name, motion=motion)
            if w.coat:
                c = w.coat
                b.coat_wall(
                    k,
                    c["radius"],
                    c["material"],
                    spacing=c.get("spacing"),
                    side=c.get("side", 1),
                    seed=c.get("seed", 0),
                )
    for fac in spec.factories:
        with _named(f"factory /World/Factories/{fac.name}"):
            shape = spec.shape(fac.shape)
            template = shape.template()
            sizes = _sizes(fac.sizes)
            region = _region(fac.region)
            density = spec.material(fac.material).density
            if fac.mode == "fill":
                b.fill(
                    region,
                    sizes,
                    fac.material,
                    count=fac.count,
                    mass=fac.mass,
                    seed=fac.seed,
                    template=template,
                    velocity=fac.initial_velocity,
                )
            else:
                ratio = 1.0 if template is None else template.bounding_radius / template.equivalent_radius
                df = DynamicFactory(
                    region,
                    sizes,
                    rate=fac.rate,
                    mass_rate=fac.mass_rate,
                    count=fac.count,
                    mass=fac.mass,
                    start_time=fac.start_time,
                    density=density,
                    seed=fac.seed,
                    initial_velocity=fac.initial_velocity,
                    interval=fac.interval,
                    bounding_ratio=ratio,
                    random_orientation=template is not None,
                )
                b.add_factory(df, fac.material, template)
    if world_count > 1 or variations or world_seeds is not None:
        b.replicate(world_count)
        for target, values in _follow_variations(spec, variations or {}).items():
            b.vary(target, values)
        if world_seeds is not None:
            b.seed_worlds(world_seeds)
    return b
