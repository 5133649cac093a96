"""The test rigs (the four of the seed papers and a rotating drum), generated as scenes from a few parameters.

Each rig is a frozen dataclass of parameters (SI units; defaults are the full-size rig) whose ``spec()``
returns a :class:`warpdem.scene.stage.SceneSpec`; :func:`new` writes it as a USD stage. ``SMOKE`` holds, per rig,
the overrides of a CPU-sized version (a few hundred particles) used by the tests and the main job;
``BEVERLOO_SMOKE`` those of a gated CPU-sized funnel whose discharge rate is checked against Beverloo's law.

* funnel (seeds 000, 001): ISO 4324:1977 funnel method -- outlet 10 mm, 75 mm above the base plate; a
  standard 60 deg laboratory funnel. ISO's 10 mm outlet suits powders (seed 001); pellets of seed 000 (6.3 mm)
  would jam it, so the default outlet is 40 mm (about six pellet sizes, Beverloo's free-flow range).
* lifting_cylinder (seed 002): 200 mm inner diameter, 300 mm high, lifted at 0.05 m/s, optional coating of
  glued particles on the cylinder and the base (seed 002 glues ore grains on both).
* die_press (seed 001): single pellet press -- die hole, feeding inlet, pressure bar (piston), backstop.
* truck_tipper (seed 002): dump body loaded by a bucket, then tilted about its rear hinge to discharge.
* rotating_drum (GranuDrum-like): horizontal cylinder 84 mm x 20 mm, partly filled, turning at constant rpm;
  dynamic angle of repose and surface fluctuation of the rolling bed.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass

import numpy as np

from warpdem.engine import geometry as geo
from warpdem.engine.checks import check, typed_number
from warpdem.engine.keys import is_rig_key
from warpdem.engine.materials import Interaction, Material
from warpdem.engine.types import ContactLaw, RollingModel
from warpdem.errors import InputError

from .stage import FactorySpec, MeasureSpec, RunSpec, SceneSpec, ShapeSpec, StageError, WallSpec, unload_keyframes


# ----------------------------------------------------------------------------------------------------
def _check_params(p) -> None:
    """Numbers must be finite; lengths, times and counts that name a size must be positive."""
    where = type(p).__name__
    for f in dataclasses.fields(p):
        v = getattr(p, f.name)
        if isinstance(v, bool) or isinstance(v, str):
            continue
        check(math.isfinite(v), where, f.name, v, "a finite number")
        if f.name in getattr(p, "_may_be_negative", ()):
            continue
        zero_ok = f.name in p._may_be_zero
        check(v > 0 or (v == 0 and zero_ok), where, f.name, v, "a value > 0" + (" (0 allowed)" if zero_ok else ""))


def _check_order(p, name: str, relation: str, bound_name: str, bound: float) -> None:
    """Refuse a parameter ``name`` of ``p`` that is not strictly ``relation`` ("more than", or "less than" /
    "below") ``bound``, named ``bound_name`` in the message."""
    v = getattr(p, name)
    check(
        v > bound if relation == "more than" else v < bound,
        type(p).__name__,
        name,
        v,
        f"{relation} {bound_name} = {bound}",
    )


def _bound_ratio(shape: ShapeSpec) -> float:
    """Bounding radius / volume-equivalent radius of a shape (1 for a sphere): how far a particle reaches from
    its centre, in the radii that the rigs' particle_radius and the factories' sizes give."""
    if shape.kind == "sphere":
        return 1.0
    t = shape.template()
    return t.bounding_radius / t.equivalent_radius


def _bound3(shape: ShapeSpec) -> float:
    """(bounding radius / equivalent radius)^3 of a shape: a static fill places clumps by their bounding
    spheres, so a fill region needs this much more room than the particles' own volume suggests."""
    return _bound_ratio(shape) ** 3


ASPECT_RATIO_MAX = 3.0
"""Largest ``aspect_ratio`` of a rig's rods (length / width)."""


def _check_aspect_ratio(p) -> None:
    """A rig's ``aspect_ratio`` lies in [1, ASPECT_RATIO_MAX], and only spheres are elongated (``particle``, where
    the rig has one)."""
    where = type(p).__name__
    check(
        1.0 <= p.aspect_ratio <= ASPECT_RATIO_MAX,
        where,
        "aspect_ratio",
        p.aspect_ratio,
        f"a length / width in [1, {ASPECT_RATIO_MAX:g}]",
    )
    particle = getattr(p, "particle", "sphere")
    if p.aspect_ratio != 1 and particle != "sphere":
        raise InputError(
            f"{where}: aspect_ratio = {p.aspect_ratio} is not allowed with particle = {particle!r}; expected 1 "
            "(only spheres are elongated into rods)"
        )


def _shape(kind: str, where: str, aspect_ratio: float = 1.0) -> tuple[ShapeSpec, float]:
    """Shape spec and its volume-equivalent radius at template scale [m]. A sphere with ``aspect_ratio`` > 1 is
    a rod (:func:`warpdem.engine.clumps.rod_template`) of the sphere's volume."""
    from warpdem.engine.clumps import pellet_template, phosphate_template, rod_template

    if kind == "sphere" and aspect_ratio == 1:
        return ShapeSpec("sphere", "sphere"), 1.0
    templates = {"pellet": pellet_template, "phosphate": phosphate_template}
    if kind == "sphere":
        name, t = "rod", rod_template(aspect_ratio)
    elif kind in templates:
        name, t = kind, templates[kind]()
    else:
        raise InputError(f"{where}: particle = {kind!r} is not allowed; expected sphere, " + ", ".join(templates))
    return ShapeSpec(name, "clump", np.asarray(t.sphere_offset), np.asarray(t.sphere_radius)), t.equivalent_radius


def _sizes(radius: float, spread: float) -> dict:
    """Radius normally distributed with relative SD ``spread``, truncated at +-2 SD (fixed when 0)."""
    if spread == 0:
        return {"distribution": "fixed", "radius": radius}
    return {
        "distribution": "normal",
        "mean": radius,
        "std": spread * radius,
        "low": radius * (1 - 2 * spread),
        "high": radius * (1 + 2 * spread),
    }


def _plate_domain(size_x: float, size_y: float, center, margin: float, top: float) -> tuple:
    """Domain over an open plate of ``size_x`` x ``size_y`` [m] whose top is at ``center`` [m]: a body that
    rolls off an edge is removed once its centre is ``2 margin`` beyond it or ``4 margin`` below the plate
    (``margin``: about a body's bounding radius [m]), instead of falling for ever; ``top``: its upper z [m]."""
    cx, cy, cz = center
    hx, hy = size_x / 2 + 2 * margin, size_y / 2 + 2 * margin
    return (cx - hx, cy - hy, cz - 4 * margin), (cx + hx, cy + hy, top)


def _settle_energy(material: Material, radius: float) -> float:
    """Kinetic energy per particle [J] below which a bed counts as settled: m g r / 1000, a thousandth of the
    work to lift the particle by its own radius."""
    return material.density * 4.0 / 3.0 * math.pi * radius**3 * 9.81 * radius * 1e-3


def _pose_samples(times, pose_fn):
    """Keyframes (times, translations (K, 3), rotations (K, 4) x,y,z,w) of ``pose_fn(t) -> (R 3x3, p 3)``."""
    tr, rot = [], []
    for t in times:
        R, p = pose_fn(float(t))
        tr.append(p)
        rot.append(_quat_from_matrix(R))
    rot = np.asarray(rot)
    # keep consecutive quaternions in one hemisphere so interpolation takes the short way
    for k in range(1, len(rot)):
        if np.dot(rot[k], rot[k - 1]) < 0:
            rot[k] = -rot[k]
    return np.asarray(times, dtype=np.float64), np.asarray(tr, dtype=np.float64), rot


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat()  # (x, y, z, w)


def _rot_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _about(R: np.ndarray, pivot) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R about the point ``pivot``: x -> R (x - pivot) + pivot."""
    pivot = np.asarray(pivot, dtype=float)
    return R, pivot - R @ pivot


def _compose(a, b):
    """Pose a after pose b: x -> Ra (Rb x + pb) + pa."""
    return a[0] @ b[0], a[0] @ b[1] + a[1]


def _smooth(s: float) -> float:
    """Smoothstep on [0, 1] (zero speed at both ends: no jolt to the particles)."""
    s = min(max(s, 0.0), 1.0)
    return s * s * (3 - 2 * s)


def _pour_rate(region_volume: float, particle_volume: float, bound3: float, height: float, speed: float) -> float:
    """Release rate [particles/s] a pour region of ``height`` [m] sustains when particles enter it at ``speed``
    [m/s] downward: half of what it holds at LOOSE_PACKING, renewed in the time a particle takes to fall
    through it. A faster rate would only be deferred by the factory (the region is full), so the pour's end
    time count / rate is what the run sees."""
    hold = region_volume * LOOSE_PACKING / bound3 / particle_volume
    t = (-speed + math.sqrt(speed**2 + 2 * 9.81 * height)) / 9.81
    return 0.5 * hold / t


POUR_INTERVAL = 0.01
"""Time between a pour's release batches [s]. Each release reads the particles back to the host to place the
batch clear of them, so one particle per batch (the factory's default) would stall a GPU run; at 0.01 s a
batch is a few dozen particles, which a pour region holds easily."""

LOOSE_PACKING = 0.25
"""Volume fraction a static (random sequential) fill reaches comfortably, walls included; fill regions are
sized with it and the particles settle to ~0.6."""

STEEL = Material("steel", density=7930.0, poisson_ratio=0.3, shear_modulus=7.7e10)
"""304 stainless steel of seed 000 (G = 77 GPa, nu = 0.3, 7930 kg/m^3)."""

ORE = Material("ore", density=2404.0, poisson_ratio=0.25, shear_modulus=2.5e6)
"""Phosphate ore of seed 002 (2404 kg/m^3, G = 2.5 MPa, nu = 0.25; its printed E = 1 MPa conflicts with G,
so G is kept)."""


def _ore_eepa(surface_energy: float = 1.0, pull_off_force: float = -0.009) -> Interaction:
    """Ore-ore contact at seed 002's optimum: EEPA, e 0.15, mu_s 0.7, constant-torque mu_r 0.3, surface energy
    [J/m^2] and pull-off force [N] as given (the seed's 1.0 and -0.009 by default)."""
    return Interaction(
        restitution=0.15,
        static_friction=0.7,
        rolling_friction=0.3,
        law=ContactLaw.EEPA,
        surface_energy=surface_energy,
        pull_off_force=pull_off_force,
        rolling_model=RollingModel.CONSTANT_TORQUE,
    )


ORE_LAWS = {
    "eepa": lambda p: _ore_eepa(p.surface_energy, p.pull_off_force),
    "hertz_mindlin": lambda p: dataclasses.replace(
        _ore_eepa(0.0, 0.0), law=ContactLaw.HERTZ_MINDLIN, plasticity_ratio=0.0
    ),
}
"""The lifting cylinder's ore-ore laws (``LiftingCylinder.law``): seed 002's EEPA, or elastic Hertz-Mindlin with
its friction and restitution."""


def _pairs(particle: str, wall: str, particle_particle: Interaction, particle_wall: Interaction) -> list:
    """A rig's three pairs: particle-particle, particle-wall and wall-wall (walls never touch each other, but
    every pair of materials needs a value)."""
    return [
        (particle, particle, particle_particle),
        (particle, wall, particle_wall),
        (wall, wall, Interaction(restitution=0.5, static_friction=0.3)),
    ]


PLATE = dataclasses.replace(STEEL, name="plate")
"""The base plate of the angle-of-repose rigs: steel's solid, a material of its own so that its contact with the
particles (``plate_static_friction``, ``plate_rolling_friction``) can differ from the other walls'."""


def _plate_pairs(p, particle: str, wall: str, particle_wall: Interaction) -> tuple[list, list, dict]:
    """The plate material; its pairs with the particles (the walls' interaction with the rig's plate friction
    and rolling friction where they are >= 0), the walls and itself; and the particles' plate pair following
    their wall pair (``SceneSpec.pair_follows``), so that an override or a factor of the particle-wall pair
    reaches the plate the pile rests on, less the friction the rig sets for the plate itself."""
    changes = {}
    if p.plate_static_friction >= 0:
        changes["static_friction"] = p.plate_static_friction
    if p.plate_rolling_friction >= 0:
        changes["rolling_friction"] = p.plate_rolling_friction
    walls = Interaction(restitution=0.5, static_friction=0.3)
    pairs = [
        (particle, "plate", dataclasses.replace(particle_wall, **changes)),
        (wall, "plate", walls),
        ("plate", "plate", walls),
    ]
    return [PLATE], pairs, {(particle, "plate"): (particle, wall, tuple(changes))}


def _sphere_pair(restitution: float, static_friction: float, rolling_friction: float, surface_energy: float = 0.0):
    """A contact of spheres with EPSD rolling resistance (spheres need it to rest in a pile): Hertz-Mindlin, or JKR
    when ``surface_energy`` [J/m^2] > 0 (a rig's cohesion switch)."""
    return Interaction(
        restitution=restitution,
        static_friction=static_friction,
        rolling_friction=rolling_friction,
        rolling_model=RollingModel.EPSD,
        law=ContactLaw.JKR if surface_energy > 0 else ContactLaw.HERTZ_MINDLIN,
        surface_energy=surface_energy,
    )


def _pour(name: str, region: tuple, material: str, shape: str, radius: float, spread: float, **kw) -> FactorySpec:
    """A dynamic factory releasing particles of ``radius`` [m] (relative SD ``spread``) into ``region`` in
    batches every POUR_INTERVAL; ``kw``: count or mass, rate, seed, initial_velocity as in FactorySpec."""
    return FactorySpec(name, "dynamic", region, material, shape, _sizes(radius, spread), interval=POUR_INTERVAL, **kw)


def _ore_pour(p, name: str, region: tuple, shape: ShapeSpec, rate: float, **amount) -> FactorySpec:
    """The ore pour of seed 002's rigs (``p``: their parameters): particles of ``p.particle_radius`` leave
    ``region`` at ``p.pour_speed`` [m/s] downward, ``rate`` per second; ``amount``: count and/or mass."""
    return _pour(
        name,
        region,
        "ore",
        shape.name,
        p.particle_radius,
        p.radius_spread,
        rate=rate,
        seed=p.seed,
        initial_velocity=(0.0, 0.0, -p.pour_speed),
        **amount,
    )


# ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Funnel:
    """Funnel angle of repose onto a 304 stainless plate (seeds 000 and 001).

    ``plate_static_friction`` and ``plate_rolling_friction`` (negative: the funnel's values) set the particles'
    contact with the plate, so that a data set can vary the base's friction alone.

    Geometry from ISO 4324:1977 (outlet 75 mm above the plate) with a 60 deg laboratory funnel; the outlet
    (10 mm in ISO, for powders) is 40 mm by default for the 6.3 mm pellets of seed 000. Particles (``count``
    of them at ``rate`` per second) rain into the funnel from above and pile on the plate; the run stops when
    the pile has settled. ``gate_time`` > 0 [s] closes the outlet with a steel plate (wall "Gate") while the
    funnel fills and settles, and opens it at that time (after the pour, count / rate): the funnel then
    discharges under its own head, as a hopper in Beverloo's law, and the fill's packing fraction and bulk
    density are measured just before it opens. 0: no gate, the funnel is fed while it discharges.
    ``output_interval`` [s]: time between outputs (the discharged-mass samples). Materials and pairs are seed 000's calibrated values (Hertz-Mindlin with
    constant-torque rolling friction); ``particle`` sphere | pellet (141-sphere clump of seed 000) |
    phosphate; ``particle_radius`` 0 keeps the clump's true size (a sphere needs one). ``aspect_ratio`` > 1
    (at most 3, spheres only) elongates the spheres into rods of that length / width and the same volume.
    """

    particle: str = "pellet"
    particle_radius: float = 0.0
    aspect_ratio: float = 1.0
    radius_spread: float = 0.03
    material: str = "pellet"
    surface_energy: float = 0.0
    count: int = 1500
    rate: float = 2000.0
    top_diameter: float = 0.15
    outlet_diameter: float = 0.04
    cone_angle: float = 60.0
    stem_length: float = 0.03
    outlet_height: float = 0.075
    plate_size: float = 0.4
    cell: float = 0.01
    duration: float = 2.5
    dt_fraction: float = 0.2
    seed: int = 1
    plate_static_friction: float = -1.0
    plate_rolling_friction: float = -1.0
    gate_time: float = 0.0
    output_interval: float = 0.05
    _may_be_zero = ("particle_radius", "radius_spread", "stem_length", "seed", "surface_energy", "gate_time")
    _may_be_negative = ("plate_static_friction", "plate_rolling_friction")

    def __post_init__(self):
        _check_aspect_ratio(self)
        _check_params(self)
        if self.material not in ("pellet", "feed"):
            raise InputError(f"Funnel: material = {self.material!r} is not allowed; expected pellet or feed")
        _check_order(self, "outlet_diameter", "less than", "top_diameter", self.top_diameter)
        if not 0 < self.cone_angle < 180:
            raise InputError(f"Funnel: cone_angle = {self.cone_angle} is not allowed; expected (0, 180) degrees")
        if self.gate_time > 0:
            # opened during the pour, the gate would only shorten the pour's fall: no hopper under its own head
            _check_order(self, "gate_time", "more than", "the pour's end count / rate [s]", self.count / self.rate)
            _check_order(self, "gate_time", "less than", "duration", self.duration)

    def spec(self) -> SceneSpec:
        shape, r_eq = _shape(self.particle, "Funnel", self.aspect_ratio)
        radius = self.particle_radius or (r_eq if self.particle != "sphere" else 0.0)
        if radius <= 0:
            raise InputError("Funnel: particle_radius = 0 is not allowed for spheres; expected a radius > 0 m")
        ct = RollingModel.CONSTANT_TORQUE
        if self.material == "pellet":
            # seed 000: feed pellets, calibrated (Hertz-Mindlin)
            grain = Material("grain", density=1330.0, poisson_ratio=0.35, shear_modulus=1.45e6)
            pp = Interaction(restitution=0.37, static_friction=0.55, rolling_friction=0.05, rolling_model=ct)
            pw = Interaction(restitution=0.45, static_friction=0.52, rolling_friction=0.03, rolling_model=ct)
        else:
            # seed 001: wet-sticky feed as spheres, calibrated optimum; JKR when surface_energy > 0
            grain = Material("grain", density=440.0, poisson_ratio=0.25, shear_modulus=10.0e6)
            # spheres need the elastic-plastic spring-dashpot rolling model to rest in a pile
            pp = _sphere_pair(0.15, 0.51, 0.21, self.surface_energy)
            pw = _sphere_pair(0.1, 0.45, 0.2)
        cone_h = geo.funnel_height(self.top_diameter, self.outlet_diameter, self.cone_angle)
        top_z = self.outlet_height + self.stem_length + cone_h
        fv, ft = geo.funnel(
            self.top_diameter,
            self.outlet_diameter,
            self.cone_angle,
            self.stem_length,
            self.outlet_height,
            min(self.cell, self.outlet_diameter / 4),
        )
        pv, pt = geo.grid_plate(self.plate_size, self.plate_size, max(self.cell, self.plate_size / 40))
        # a clump's bounding sphere, at least the 1.42 equivalent radii the pellet and phosphate scenes were made with
        bound = (
            radius * (1 + 2 * self.radius_spread) * (max(1.42, _bound_ratio(shape)) if shape.kind == "clump" else 1.0)
        )
        region = ("cylinder", (0.0, 0.0, top_z + 2 * bound), 0.4 * self.top_diameter, max(8 * bound, 0.02), None)
        fac = _pour(
            "pour",
            region,
            "grain",
            shape.name,
            radius,
            self.radius_spread,
            count=int(self.count),
            rate=self.rate,
            seed=int(self.seed),
        )
        plate, plate_pairs, follows = _plate_pairs(self, "grain", "steel", pw)
        walls = [WallSpec("Funnel", fv, ft, "steel"), WallSpec("Plate", pv, pt, "plate")]
        settle_after = self.count / self.rate
        measure = MeasureSpec(
            "angle_of_repose",
            base_height=0.0,
            center=(0.0, 0.0),
            outlet_height=self.outlet_height,
            pour_radius=self.outlet_diameter / 2,
        )
        if self.gate_time > 0:
            gate, opened = self._gate(radius, bound)
            walls.append(gate)
            # the fill rests in the funnel until the gate opens: the run must not stop as settled before
            settle_after = opened
            # the fill's core: one diameter from the wall where the core is narrowest, at its foot one diameter
            # above the gate (the cone widens above it)
            measure.packing_time = self.gate_time
            measure.packing_margin = 1.0
            foot = 0.25 * radius + measure.packing_margin * 2 * bound
            measure.packing_radius = self.outlet_diameter / 2 + foot * math.tan(math.radians(self.cone_angle / 2))
            measure.packing_base = float(gate.translations[0][2])
        return SceneSpec(
            rig="funnel",
            materials=[grain, STEEL, *plate],
            pairs=_pairs("grain", "steel", pp, pw) + plate_pairs,
            pair_follows=follows,
            shapes=[shape],
            walls=walls,
            factories=[fac],
            run=RunSpec(
                duration=self.duration,
                dt_fraction=self.dt_fraction,
                settle_energy=_settle_energy(grain, radius),
                settle_after=settle_after,
                output_interval=self.output_interval,
            ),
            measure=measure,
            domain=_plate_domain(self.plate_size, self.plate_size, (0.0, 0.0, 0.0), bound, top_z + 0.5),
        )

    def _gate(self, radius: float, bound: float) -> tuple[WallSpec, float]:
        """The gate under the outlet and the time [s] it has moved clear of the domain.

        A steel disc a bounding radius ``bound`` [m] wider than the outlet, a quarter particle ``radius`` [m]
        below its rim (no particle passes the gap). At ``gate_time`` it drops by ``h`` (four bounding radii, at
        most half its height above the plate) in a quarter of sqrt(h / g): faster than gravity, so the
        fill comes away from it instead of riding down on it. It then slides along +x, clearing the outlet's
        shadow within three quarters of sqrt(h / g): by then a grain released at rest has fallen h / 2, so
        nothing touches the gate after it opens. It goes on at that speed until it is wholly outside the domain
        (beyond the plate's edge, below the outlet's height), away from the pile the angle of repose is
        measured on.
        """
        r_gate = self.outlet_diameter / 2 + bound
        top = self.outlet_height - 0.25 * radius
        h = min(4.0 * bound, 0.5 * top)
        t_fall = math.sqrt(h / 9.81)
        t_drop = 0.25 * t_fall
        clear = r_gate + self.outlet_diameter / 2 + bound
        speed = clear / (0.75 * t_fall)
        # the domain ends 2 bounding radii past the plate's edge (_plate_domain)
        away = self.plate_size / 2 + 2 * bound + r_gate + bound
        t0, t1 = self.gate_time, self.gate_time + t_drop
        t2 = t1 + away / speed
        gv, gt = geo.disc(r_gate, min(self.cell, r_gate / 2), 0.0)
        times = np.array([0.0, t0, t1, t2])
        tr = np.array([[0.0, 0.0, top], [0.0, 0.0, top], [0.0, 0.0, top - h], [away, 0.0, top - h]])
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1))
        return WallSpec("Gate", gv, gt, "steel", times, tr, rot), float(t2)


@dataclass(frozen=True)
class LiftingCylinder:
    """Lifting-cylinder angle of repose (seed 002): 200 mm inner diameter, 300 mm high, lifted at 0.05 m/s.

    The cylinder stands on a base plate, is filled by a pour from a region ``pour_height`` tall just above its
    rim (particles leave it at ``pour_speed`` downward, so none falls more than the cylinder's height plus
    that region), settles for ``settle_time``, and is lifted by ``lift_height`` (default: its height + 20 mm)
    at ``lift_speed``; just before it lifts, the bed's packing fraction and bulk density are measured in a core
    ``packing_margin`` particle diameters from the wall, the base and the free surface. ``plate_static_friction`` and
    ``plate_rolling_friction`` (negative: the cylinder's values) set the particles' contact with the base plate
    (with ``coated``, only where the glued grains leave it bare). With ``coated`` the cylinder's
    inside and the base carry glued particles of the ore (seed 002 glues grains on both). Ore: seed 002's
    phosphate (2404 kg/m^3, G = 2.5 MPa, nu = 0.25; printed E = 1 MPa conflicts with G, so G is kept), EEPA
    between particles at seed 002's optimum (mu_s 0.7, mu_r 0.3, surface energy 1.0 J/m^2), 15-sphere clumps
    coarse-grained to ``particle_radius`` (seed: 0.39 mm mean). A monodisperse coarse bed packs near 0.6, so
    the 300 mm cylinder holds about 13 kg of it, not the seed's 15 kg: ``mass`` defaults to 11 kg.
    ``aspect_ratio`` > 1 (at most 3, with ``particle`` sphere) elongates the spheres into rods of that
    length / width and the volume of a sphere of ``particle_radius``.
    ``law`` swaps the ore-ore normal law (:data:`ORE_LAWS`): ``eepa`` (seed 002's, by default) or
    ``hertz_mindlin`` (elastic, no adhesion: ``surface_energy`` and ``pull_off_force`` unused), with the same
    friction and restitution; a rig parameter, so that a study or diagnosis can start from Hertz-Mindlin without
    deciding the pair's ``law`` override key.
    """

    particle: str = "phosphate"
    particle_radius: float = 0.005
    aspect_ratio: float = 1.0
    radius_spread: float = 0.1
    mass: float = 11.0
    count: int = 0
    inner_diameter: float = 0.2
    height: float = 0.3
    lift_speed: float = 0.05
    lift_height: float = 0.0
    surface_energy: float = 1.0
    pull_off_force: float = -0.009
    coated: bool = True
    coat_radius: float = 0.0
    base_size: float = 0.6
    pour_height: float = 0.2
    pour_speed: float = 1.5
    settle_time: float = 0.6
    after_lift: float = 2.0
    cell: float = 0.02
    dt_fraction: float = 0.2
    seed: int = 1
    packing_margin: float = 2.0
    plate_static_friction: float = -1.0
    plate_rolling_friction: float = -1.0
    law: str = "eepa"
    _may_be_zero = (
        "count",
        "mass",
        "lift_height",
        "coat_radius",
        "radius_spread",
        "seed",
        "surface_energy",
        "pour_speed",
    )
    _may_be_negative = ("pull_off_force", "plate_static_friction", "plate_rolling_friction")

    def __post_init__(self):
        _check_aspect_ratio(self)
        _check_params(self)
        if (self.count == 0) == (self.mass == 0):
            raise InputError(f"LiftingCylinder: count = {self.count}, mass = {self.mass}: expected exactly one > 0")
        if self.law not in ORE_LAWS:
            raise InputError(f"LiftingCylinder: law = {self.law!r} is not allowed; expected {', '.join(ORE_LAWS)}")

    def spec(self) -> SceneSpec:
        shape, _ = _shape(self.particle, "LiftingCylinder", self.aspect_ratio)
        r = self.particle_radius
        ore_steel = Interaction(restitution=0.15, static_friction=0.5, rolling_friction=0.1)
        plate, plate_pairs, follows = _plate_pairs(self, "ore", "steel", ore_steel)
        pairs = _pairs("ore", "steel", ORE_LAWS[self.law](self), ore_steel) + plate_pairs
        R, H = self.inner_diameter / 2, self.height
        lift = self.lift_height or H + 0.02
        coat_r = self.coat_radius or r
        margin = (2 * coat_r if self.coated else 0.0) + r * (1 + 2 * self.radius_spread) * max(
            1.45, _bound_ratio(shape)
        )
        v_mean = 4.0 / 3.0 * math.pi * r**3 * (1 + 3 * self.radius_spread**2)
        count = self.count or self.mass / (ORE.density * v_mean)
        pour_r = R - margin
        rate = _pour_rate(
            math.pi * pour_r**2 * self.pour_height, v_mean, _bound3(shape), self.pour_height, self.pour_speed
        )
        t0 = count / rate + self.settle_time
        t1 = t0 + lift / self.lift_speed
        cv, ct = geo.frustum(R, R, 0.0, H, self.cell)
        bv, bt = geo.grid_plate(self.base_size, self.base_size, max(self.cell, self.base_size / 30))
        times = np.array([0.0, t0, t1])
        cyl = WallSpec(
            "Cylinder",
            cv,
            ct,
            "steel",
            times,
            np.array([[0, 0, 0], [0, 0, 0], [0, 0, lift]], float),
            np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)),
        )
        base = WallSpec("Base", bv, bt, "plate")
        if self.coated:
            cyl.coat = {"radius": coat_r, "material": "ore", "side": 1, "seed": self.seed}
            base.coat = {"radius": coat_r, "material": "ore", "side": 1, "seed": self.seed + 1}
        region = ("cylinder", (0.0, 0.0, H + r), pour_r, self.pour_height, None)
        fac = _ore_pour(self, "pour", region, shape, rate, count=self.count or None, mass=self.mass or None)
        return SceneSpec(
            rig="lifting_cylinder",
            materials=[ORE, STEEL, *plate],
            pairs=pairs,
            pair_follows=follows,
            shapes=[shape],
            walls=[cyl, base],
            factories=[fac],
            run=RunSpec(
                duration=t1 + self.after_lift,
                dt_fraction=self.dt_fraction,
                settle_energy=_settle_energy(ORE, r),
                settle_after=t1,
                output_interval=0.05,
            ),
            measure=MeasureSpec(
                "angle_of_repose",
                base_height=2 * coat_r if self.coated else 0.0,
                packing_time=t0,
                packing_radius=R - (2 * coat_r if self.coated else 0.0),
                packing_margin=self.packing_margin,
                pour_radius=R,
            ),
            domain=_plate_domain(
                self.base_size, self.base_size, (0.0, 0.0, 0.0), margin, H + lift + self.pour_height + 0.5
            ),
        )


PRESS_LAWS = {
    "jkr": lambda p: {"law": ContactLaw.JKR, "surface_energy": p.surface_energy},
    "hertz_mindlin": lambda p: {"law": ContactLaw.HERTZ_MINDLIN},
    "eepa": lambda p: {
        "law": ContactLaw.EEPA,
        "surface_energy": p.surface_energy,
        "plasticity_ratio": p.plasticity_ratio,
    },
}
"""The die press's feed-feed laws (``DiePress.law``) and the Interaction fields each takes from the rig."""


@dataclass(frozen=True)
class DiePress:
    """Single pellet press (seed 001): die hole with a feeding inlet, a backstop under the die and a pressure
    bar (piston) driven down at ``piston_speed`` until the force reaches ``force_limit`` or the bar has
    travelled ``max_travel`` x the fill height. With ``unload`` (the default) the bar then holds for
    ``hold_time`` and retracts at ``piston_speed`` to where its stroke began, so the run records the unloading
    branch too (residual set, unloading stiffness); without it the run stops at the force limit.

    Wet feed of seed 001 (440 kg/m^3, G = 10 MPa, nu = 0.25, JKR at the calibrated optimum mu_s 0.51,
    mu_r 0.21, surface energy 0.65 J/m^2); the 0.1 mm particles are coarse-grained to ``particle_radius``.
    ``law`` swaps the feed-feed normal law to tell mechanisms apart: ``hertz_mindlin`` (elastic, no cohesion)
    or ``eepa`` (elasto-plastic, ``plasticity_ratio``, with ``surface_energy`` its adhesion; EEPA's other
    constants at their defaults), with the same friction.
    Speed-up: the seed presses at 20 mm/min; we press at ``piston_speed`` (0.1 m/s by default) and report the
    inertial number I = (v / H) d / sqrt(p / rho) of the compaction, which must stay below 1e-3 for
    quasi-static flow. The fill (``fill_height`` of settled bed) is made by a static fill of the die and
    ``settle_time`` of settling with the bar parked above the inlet; the bar then approaches at 10 x
    ``piston_speed`` to ``gap`` above the expected bed top and presses.
    """

    particle_radius: float = 0.0004
    radius_spread: float = 0.05
    die_diameter: float = 0.008
    fill_height: float = 0.08
    inlet_diameter: float = 0.016
    inlet_height: float = 0.01
    piston_speed: float = 0.1
    gap: float = 0.004
    force_limit: float = 300.0
    max_travel: float = 0.8
    settle_time: float = 0.4
    cell: float = 0.002
    dt_fraction: float = 0.2
    seed: int = 1
    unload: bool = True
    hold_time: float = 0.0
    law: str = "jkr"
    surface_energy: float = 0.65
    plasticity_ratio: float = 0.5
    _may_be_zero = ("radius_spread", "seed", "hold_time", "surface_energy", "plasticity_ratio")

    def __post_init__(self):
        _check_params(self)
        _check_order(self, "inlet_diameter", "more than", "die_diameter", self.die_diameter)
        if not 0 < self.max_travel < 1:
            raise InputError(f"DiePress: max_travel = {self.max_travel} is not allowed; expected a fraction in (0, 1)")
        if self.law not in PRESS_LAWS:
            raise InputError(f"DiePress: law = {self.law!r} is not allowed; expected {', '.join(PRESS_LAWS)}")
        if not self.plasticity_ratio < 1:
            raise InputError(
                f"DiePress: plasticity_ratio = {self.plasticity_ratio} is not allowed; expected a ratio in [0, 1)"
            )

    def spec(self) -> SceneSpec:
        r = self.particle_radius
        feed = Material("feed", density=440.0, poisson_ratio=0.25, shear_modulus=10.0e6)
        steel = Material("steel", density=7850.0, poisson_ratio=0.3, shear_modulus=7.0e10)
        ct = RollingModel.CONSTANT_TORQUE
        pairs = _pairs(
            "feed",
            "steel",
            Interaction(
                restitution=0.15,
                static_friction=0.51,
                rolling_friction=0.21,
                rolling_model=ct,
                **PRESS_LAWS[self.law](self),
            ),
            Interaction(restitution=0.1, static_friction=0.45, rolling_friction=0.2, rolling_model=ct),
        )
        R = self.die_diameter / 2
        # a die a few particles wide packs a static fill more loosely still (wall effect); the settled bed of
        # the cohesive feed packs at 0.42 (the smoke die, six diameters wide, at a converged step: a step the
        # stiffest contact does not allow shook it down to 0.58)
        packing_loose, packing_bed = 0.6 * LOOSE_PACKING, 0.42
        count = int(packing_bed * math.pi * R**2 * self.fill_height / (4.0 / 3.0 * math.pi * r**3))
        fill_region_h = self.fill_height * packing_bed / packing_loose
        die_h = fill_region_h + 2 * r
        dv, dt_ = geo.frustum(R, R, 0.0, die_h, self.cell)
        iv, it = geo.frustum(R, self.inlet_diameter / 2, die_h, die_h + self.inlet_height, self.cell)
        bv, bt = geo.disc(1.5 * R, self.cell, 0.0)
        pr = R - 0.25 * r  # clearance below a quarter radius: no particle slips past the bar
        pv, pt = geo.disc(pr, self.cell, 0.0, up=False)
        park = die_h + self.inlet_height + 2 * r
        start = self.fill_height + self.gap
        t_a = self.settle_time
        t_b = t_a + (park - start) / (10 * self.piston_speed)
        travel = self.max_travel * self.fill_height + self.gap
        t_c = t_b + travel / self.piston_speed
        times = np.array([0.0, t_a, t_b, t_c])
        heights = np.array([[0, 0, park], [0, 0, park], [0, 0, start], [0, 0, start - travel]], float)
        if self.unload:
            # the return as keyframes, which the runner moves to wherever the force limit ends the stroke
            times, heights = unload_keyframes(times, heights, t_c, heights[-1], self.hold_time, self.piston_speed)
        piston = WallSpec("Piston", pv, pt, "steel", times, heights, np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1)))
        fac = FactorySpec(
            "fill",
            "fill",
            ("cylinder", (0.0, 0.0, 0.0), R - 1.1 * r * (1 + 2 * self.radius_spread), fill_region_h, None),
            "feed",
            "sphere",
            _sizes(r, self.radius_spread),
            count=count,
            seed=self.seed,
        )
        return SceneSpec(
            rig="die_press",
            materials=[feed, steel],
            pairs=pairs,
            shapes=[ShapeSpec("sphere", "sphere")],
            walls=[
                WallSpec("Die", np.concatenate([dv, iv]), np.concatenate([dt_, it + len(dv)]), "steel"),
                WallSpec("Backstop", bv, bt, "steel"),
                piston,
            ],
            factories=[fac],
            # a sphere squeezed past the bar's rim leaves at tens of m/s (seed 001 at 300 N): removed once out
            # of the inlet's box or above the parked bar, instead of flying for ever and forcing a neighbour-list
            # rebuild every few steps (it took a third of the press's time); measure's escaped counts it
            domain=_plate_domain(self.inlet_diameter, self.inlet_diameter, (0.0, 0.0, 0.0), 1.1 * r, park + 4 * r),
            run=RunSpec(
                duration=float(times[-1]),
                dt_fraction=self.dt_fraction,
                output_interval=self.gap / self.piston_speed / 8,
            ),
            measure=MeasureSpec(
                "press",
                piston="Piston",
                force_limit=self.force_limit,
                backstop_height=0.0,
                unload_speed=self.piston_speed if self.unload else 0.0,
                hold_time=self.hold_time,
            ),
        )


@dataclass(frozen=True)
class TruckTipper:
    """Truck tipper (seed 002): a dump body (open top, tailgate) loaded by a bucket that pours ore from
    ``lip_height`` above the floor (seed 002's first impacts at 3.92 m/s mean a 0.78 m drop), then tilted
    by ``tilt_angle`` about its rear hinge while the tailgate swings open. Full-size geometry; the ore
    (seed 002's phosphate, EEPA between particles, JKR against the steel as in the seed) is coarse-grained
    to ``particle_radius`` (seed: 0.39 mm mean). The bucket is loaded by a pour from a region ``pour_height``
    tall just above it (particles leave it at ``pour_speed`` downward), so nothing falls past the bucket
    into the body before the dump; ``dump_start`` 0 starts the dump 0.5 s after the pour ends. Impacts on
    the body and the tailgate are counted per face,
    separately for loading and discharge; the first contacts, ``first_contact_window`` s from the output tick
    (0.1 s apart) that sees the first impact, are also summed apart as the phase ``first_contacts`` (seed
    002's 3.92 m/s is theirs); 0 does not split them.
    """

    particle: str = "phosphate"
    particle_radius: float = 0.02
    radius_spread: float = 0.1
    body_length: float = 5.5
    body_width: float = 2.3
    body_height: float = 1.2
    bucket_width: float = 2.0
    bucket_depth: float = 1.0
    bucket_height: float = 0.6
    bucket_x: float = 0.6
    lip_height: float = 0.78
    fill_fraction: float = 0.85
    pour_height: float = 0.4
    pour_speed: float = 1.0
    dump_start: float = 0.0
    dump_duration: float = 1.5
    dump_angle: float = 135.0
    load_settle: float = 1.5
    tilt_angle: float = 50.0
    tilt_duration: float = 6.0
    after_tilt: float = 2.0
    chassis_height: float = 1.2
    cell: float = 0.25
    dt_fraction: float = 0.2
    seed: int = 1
    first_contact_window: float = 0.1
    _may_be_zero = ("radius_spread", "seed", "bucket_x", "dump_start", "pour_speed", "first_contact_window")

    def __post_init__(self):
        _check_params(self)
        _check_order(self, "bucket_width", "less than", "body_width", self.body_width)
        _check_order(self, "lip_height", "below", "body_height + bucket_height", self.body_height + self.bucket_height)

    def spec(self) -> SceneSpec:
        shape, _ = _shape(self.particle, "TruckTipper")
        r = self.particle_radius
        ore_steel = Interaction(
            restitution=0.3,
            static_friction=0.5,
            rolling_friction=0.1,
            law=ContactLaw.JKR,
            surface_energy=0.1,
            rolling_model=RollingModel.CONSTANT_TORQUE,
        )
        L, W, H = self.body_length, self.body_width, self.body_height
        body_v, body_t = geo.open_box(L, W, H, self.cell, open_sides=("top", "rear"))
        gate_v, gate_t = geo.open_box(L, W, H, self.cell, open_sides=("top", "bottom", "front", "left", "right"))
        gd = max(self.cell, 0.5)
        ground_v, ground_t = geo.grid_plate(L + 12.0, W + 4.0, gd, z=-self.chassis_height, center=(L / 2 + 4.0, 0.0))
        # bucket: open box, pour edge (front top) at x = bucket_x + depth, z = lip_height
        bd, bw, bh = self.bucket_depth, self.bucket_width, self.bucket_height
        bx0 = self.bucket_x
        buck_v, buck_t = geo.open_box(
            bd, bw, bh, self.cell / 2, open_sides=("top",), origin=(bx0, 0.0, self.lip_height - bh)
        )
        edge = (bx0 + bd, 0.0, self.lip_height)
        margin = r * (1 + 2 * self.radius_spread) * 1.45
        area = (bd - 2 * margin) * (bw - 2 * margin)
        v_mean = 4.0 / 3.0 * math.pi * r**3 * (1 + 3 * self.radius_spread**2)
        # clumps settle to about 0.5 of the space (by equivalent-sphere volume): the bed tops out at the
        # fill fraction of the bucket and nothing spills before the dump
        count = int(0.5 * area * self.fill_fraction * (bh - margin) / v_mean)
        region = (
            "box",
            (bx0 + margin, -bw / 2 + margin, self.lip_height + r),
            (bx0 + bd - margin, bw / 2 - margin, self.lip_height + r + self.pour_height),
        )
        rate = _pour_rate(area * self.pour_height, v_mean, _bound3(shape), self.pour_height, self.pour_speed)
        t_dump0 = self.dump_start or count / rate + 0.5
        t_dump1 = t_dump0 + self.dump_duration
        t_load = t_dump1 + self.load_settle
        t_tilt1 = t_load + self.tilt_duration
        end = t_tilt1 + self.after_tilt
        step = 0.05

        def bucket_pose(t):
            a = math.radians(self.dump_angle) * _smooth((t - t_dump0) / self.dump_duration)
            R_, p = _about(_rot_y(a), edge)
            # once empty, the bucket backs away upward, clear of the tilting body
            lift = 3.0 * _smooth((t - t_dump1 - 0.3) / 0.7)
            return R_, p + (0.0, 0.0, lift)

        def body_pose(t):
            a = math.radians(self.tilt_angle) * _smooth((t - t_load) / self.tilt_duration)
            return _about(_rot_y(a), (L, 0.0, 0.0))

        def gate_pose(t):
            # the tailgate hangs from its top edge and swings open (outward, 100 deg) in the first second
            phi = math.radians(100.0) * _smooth((t - t_load) / 1.0)
            return _compose(body_pose(t), _about(_rot_y(-phi), (L, 0.0, H)))

        tb = np.unique(np.r_[np.arange(0.0, t_dump1 + 1.0 + step, step), t_dump1 + 1.0])
        tt = np.unique(np.r_[0.0, np.arange(t_load, t_tilt1 + step, step), t_tilt1])
        bucket = WallSpec("Bucket", buck_v, buck_t, "steel", *_pose_samples(tb, bucket_pose))
        body = WallSpec("Body", body_v, body_t, "steel", *_pose_samples(tt, body_pose))
        gate = WallSpec("Tailgate", gate_v, gate_t, "steel", *_pose_samples(tt, gate_pose))
        ground = WallSpec("Ground", ground_v, ground_t, "steel")
        fac = _ore_pour(self, "load", region, shape, rate, count=count)
        return SceneSpec(
            rig="truck_tipper",
            materials=[ORE, STEEL],
            pairs=_pairs("ore", "steel", _ore_eepa(), ore_steel),
            shapes=[shape],
            walls=[body, gate, bucket, ground],
            factories=[fac],
            run=RunSpec(duration=end, dt_fraction=self.dt_fraction, output_interval=0.1),
            measure=MeasureSpec(
                "impacts",
                walls=["Body", "Tailgate"],
                phase_names=["loading", "discharge"],
                phase_ends=[t_load, end],
                first_contact_window=self.first_contact_window,
            ),
            domain=_plate_domain(
                L + 12.0,
                W + 4.0,
                (L / 2 + 4.0, 0.0, -self.chassis_height),
                margin,
                self.lip_height + bh + self.pour_height + 4.0,
            ),
        )


GLASS = Material("glass", density=2500.0, poisson_ratio=0.25, shear_modulus=1.0e7)
"""Glass beads: soda-lime glass's density (2500 kg/m^3) and Poisson ratio, with a shear modulus of 10 MPa
instead of glass's 26 GPa (the funnel's feed has the same): the rotating bed's contact forces are set by gravity,
overlaps stay below 0.5 % of a radius at the drum's depth, and the time step is 50 times longer."""

DRUM = Material("drum", density=2700.0, poisson_ratio=0.33, shear_modulus=2.6e10)
"""Aluminium (2700 kg/m^3, G = 26 GPa, nu = 0.33): the drum and, as the material ``window`` with its own pair,
its end walls."""


def _segment_level(fill: float) -> float:
    """Height [drum radii] above the axis of the level surface of a bed filling ``fill`` of a circle's area: the
    circular segment's area (theta - sin theta) / 2 at central angle theta equals fill pi."""
    from scipy.optimize import brentq

    theta = brentq(lambda t: t - math.sin(t) - 2 * math.pi * fill, 0.0, 2 * math.pi)
    return -math.cos(theta / 2)


def _drum_y(vertices: np.ndarray) -> np.ndarray:
    """Vertices of a mesh built about the z axis turned about x by -90 deg to lie along y: (x, y, z) -> (x, z, -y),
    a proper rotation, so the winding (the particle side) is kept."""
    return np.column_stack([vertices[:, 0], vertices[:, 2], -vertices[:, 1]])


@dataclass(frozen=True)
class RotatingDrum:
    """Rotating drum (GranuDrum-like): a horizontal cylinder, axis along y through the origin, with two square end
    walls,
    ``fill_fraction`` full and turning at ``rpm`` about +y (right-hand rule: the wall at the bottom moves toward
    -x and lifts the bed on the -x side). Full size is GranuDrum's cell: 84 mm inner diameter, 20 mm wide
    (GranuDrum turns at 2 to 60 rpm; 10 rpm by default).

    Particles: glass-bead-like spheres (:data:`GLASS`) of ``particle_radius`` (1 mm, coarse next to the
    instrument's powders: a free-flowing reference bed), ``radius_spread``, with a moderately damped
    (restitution 0.6), frictional (mu_s 0.4) contact and a little rolling resistance (EPSD, mu_r 0.02, as for
    the funnel's spheres, which need it to rest); cohesionless by default (``surface_energy`` 0; > 0: JKR).
    ``aspect_ratio`` > 1 (at most 3) elongates them into rods of that length / width and the same volume.
    The drum is aluminium (:data:`DRUM`) with mu_s 0.6 against the beads: a smooth drum lets the bed slide
    instead of turning with it. The end walls are a material of their own, ``window``, whose contact with the
    beads is the drum's unless ``window_static_friction`` (negative: the drum's) sets it: their friction raises
    the dynamic angle of a narrow drum.

    Fill: ``fill_fraction`` of the drum's volume as a bed packed at 0.6, i.e. count = fill_fraction x drum
    volume x 0.6 / mean particle volume, poured from a box above the bed's level (particles leave it at
    ``pour_speed`` downward) and left to settle for ``settle_time``. Then the drum, its end walls with it,
    turns at a constant angular velocity (keyframes every 45 deg, each segment an exact constant rotation about
    the axis); after ``steady_after`` revolutions every output, ``frame_interval`` apart, is a frame of the
    ``drum`` measurement for ``measure_revolutions`` more revolutions, and the run ends.

    Facets: the drum is a polygon of n sides with n large enough that its sagitta R (1 - cos(pi / n)) is at
    most 5 % of a particle radius, so a facet corner rises less than that above the circle: the wall reads as a
    circle to the particles (its normal turns by at most 180 / n deg from radial), and facets do not act as
    lifters. ``cell`` [m] caps the facets' size along the drum and around it.
    """

    particle_radius: float = 0.001
    aspect_ratio: float = 1.0
    radius_spread: float = 0.05
    inner_diameter: float = 0.084
    width: float = 0.02
    fill_fraction: float = 0.4
    rpm: float = 10.0
    surface_energy: float = 0.0
    window_static_friction: float = -1.0
    pour_speed: float = 0.5
    settle_time: float = 0.5
    steady_after: float = 1.0
    measure_revolutions: float = 2.0
    frame_interval: float = 0.2
    cell: float = 0.004
    dt_fraction: float = 0.2
    seed: int = 1
    _may_be_zero = ("radius_spread", "seed", "surface_energy", "pour_speed", "steady_after")
    _may_be_negative = ("window_static_friction",)

    def __post_init__(self):
        _check_aspect_ratio(self)
        _check_params(self)
        if not self.fill_fraction <= 0.6:
            raise InputError(
                f"RotatingDrum: fill_fraction = {self.fill_fraction} is not allowed; expected a fraction of the "
                "drum's volume in (0, 0.6] (the pour needs the drum's upper part)"
            )
        _check_order(self, "particle_radius", "less than", "width / 4", self.width / 4)
        _check_order(self, "particle_radius", "less than", "inner_diameter / 20", self.inner_diameter / 20)
        if not 0 < self.rpm <= 120:
            raise InputError(f"RotatingDrum: rpm = {self.rpm} is not allowed; expected (0, 120] revolutions/min")
        if not self.radius_spread < 0.25:
            raise InputError(
                f"RotatingDrum: radius_spread = {self.radius_spread} is not allowed; expected a relative SD in [0, 0.25)"
            )

    def spec(self) -> SceneSpec:
        r, R, W = self.particle_radius, self.inner_diameter / 2, self.width
        shape, _ = _shape("sphere", "RotatingDrum", self.aspect_ratio)
        pp = _sphere_pair(0.6, 0.4, 0.02, self.surface_energy)
        pw = _sphere_pair(0.6, 0.6, 0.02)
        pwin = (
            pw
            if self.window_static_friction < 0
            else dataclasses.replace(pw, static_friction=self.window_static_friction)
        )
        walls_ia = Interaction(restitution=0.5, static_friction=0.3)
        window = dataclasses.replace(DRUM, name="window")
        pairs = _pairs("glass", "drum", pp, pw) + [
            ("glass", "window", pwin),
            ("drum", "window", walls_ia),
            ("window", "window", walls_ia),
        ]
        # facets: sagitta R (1 - cos(pi / n)) <= 0.05 r
        n = math.ceil(math.pi / math.acos(1.0 - 0.05 * r / R))
        cell = min(self.cell, 2 * math.pi * R / n)
        cv, ct_ = geo.frustum(R, R, -W / 2, W / 2, cell)
        # square end walls, a cell wider than the drum: a disc's central fan would put every one of its n
        # triangles under a particle at the centre
        side = 2 * R + 2 * cell
        front_v, front_t = geo.grid_plate(side, side, cell, z=-W / 2, up=True)
        back_v, back_t = geo.grid_plate(side, side, cell, z=W / 2, up=False)
        v_mean = 4.0 / 3.0 * math.pi * r**3 * (1 + 3 * self.radius_spread**2)
        count = int(self.fill_fraction * math.pi * R**2 * W * 0.6 / v_mean)
        # pour region: a box between the bed's level (plus a diameter) and 0.8 R, inside the circle and clear of
        # the end walls by a largest particle
        margin = max(1.45, _bound_ratio(shape)) * r * (1 + 2 * self.radius_spread)
        z_lo, z_hi = _segment_level(self.fill_fraction) * R + 2 * r, 0.8 * R
        half = math.sqrt(R**2 - z_hi**2) - margin
        region = ("box", (-half, -W / 2 + margin, z_lo), (half, W / 2 - margin, z_hi))
        rate = _pour_rate(
            2 * half * (W - 2 * margin) * (z_hi - z_lo), v_mean, _bound3(shape), z_hi - z_lo, self.pour_speed
        )
        fac = _pour(
            "pour",
            region,
            "glass",
            shape.name,
            r,
            self.radius_spread,
            count=count,
            rate=rate,
            seed=self.seed,
            initial_velocity=(0.0, 0.0, -self.pour_speed),
        )
        omega = 2 * math.pi * self.rpm / 60.0
        t_turn = count / rate + self.settle_time
        t_avg = t_turn + self.steady_after * 2 * math.pi / omega
        end = t_avg + self.measure_revolutions * 2 * math.pi / omega
        # slerped keyframes: 45 deg apart, each segment turns at exactly omega about the axis (the pose's pivot)
        step = math.radians(45.0) / omega
        times = np.unique(np.r_[0.0, np.arange(t_turn, end, step), end])
        times, tr, rot = _pose_samples(times, lambda t: (_rot_y(omega * max(t - t_turn, 0.0)), np.zeros(3)))
        walls = [
            WallSpec("Drum", _drum_y(cv), ct_, "drum", times, tr, rot),
            WallSpec("FrontWall", _drum_y(front_v), front_t, "window", times, tr, rot),
            WallSpec("BackWall", _drum_y(back_v), back_t, "window", times, tr, rot),
        ]
        box = R + 4 * margin
        return SceneSpec(
            rig="rotating_drum",
            materials=[GLASS, DRUM, window],
            pairs=pairs,
            shapes=[shape],
            walls=walls,
            factories=[fac],
            run=RunSpec(duration=float(end), dt_fraction=self.dt_fraction, output_interval=self.frame_interval),
            measure=MeasureSpec(
                "drum", drum_center=(0.0, 0.0, 0.0), drum_axis=(0.0, 1.0, 0.0), drum_radius=R, average_from=t_avg
            ),
            # what leaks past the end walls' seams is removed, not left falling
            domain=((-box, -W / 2 - 4 * margin, -box), (box, W / 2 + 4 * margin, box)),
        )


RIGS = {
    "funnel": Funnel,
    "lifting_cylinder": LiftingCylinder,
    "die_press": DiePress,
    "truck_tipper": TruckTipper,
    "rotating_drum": RotatingDrum,
}

SMOKE = {
    "funnel": {
        "particle": "sphere",
        "material": "feed",
        "particle_radius": 0.002,
        "count": 300,
        "rate": 1500.0,
        "top_diameter": 0.07,
        "outlet_diameter": 0.02,
        "stem_length": 0.01,
        "outlet_height": 0.025,
        "plate_size": 0.16,
        "cell": 0.01,
        "duration": 1.6,
    },
    "lifting_cylinder": {
        "particle": "sphere",
        "particle_radius": 0.0025,
        "mass": 0.0,
        "count": 450,
        "inner_diameter": 0.06,
        "height": 0.06,
        "lift_speed": 0.1,
        "base_size": 0.16,
        "pour_height": 0.04,
        "settle_time": 0.25,
        "after_lift": 0.6,
        "cell": 0.01,
        "surface_energy": 0.0,
        "pull_off_force": 0.0,
        "packing_margin": 1.0,
    },
    "die_press": {
        "particle_radius": 0.0005,
        "die_diameter": 0.006,
        "fill_height": 0.01,
        "inlet_diameter": 0.01,
        "inlet_height": 0.003,
        "piston_speed": 0.2,
        "gap": 0.002,
        "force_limit": 10.0,
        "settle_time": 0.1,
        "cell": 0.002,
    },
    "truck_tipper": {
        "particle": "sphere",
        "particle_radius": 0.012,
        "body_length": 0.6,
        "body_width": 0.34,
        "body_height": 0.2,
        "bucket_width": 0.24,
        "bucket_depth": 0.14,
        "bucket_height": 0.1,
        "bucket_x": 0.08,
        "lip_height": 0.16,
        "pour_height": 0.1,
        "dump_duration": 0.5,
        "load_settle": 0.5,
        "tilt_duration": 1.0,
        "after_tilt": 0.5,
        "chassis_height": 0.2,
        "cell": 0.05,
    },
    "rotating_drum": {
        "particle_radius": 0.0015,
        "inner_diameter": 0.06,
        "width": 0.009,
        "rpm": 30.0,
        "pour_speed": 1.0,
        "settle_time": 0.2,
        "steady_after": 0.25,
        "measure_revolutions": 0.25,
        "frame_interval": 0.05,
        "cell": 0.01,
    },
}
"""Overrides that make each rig a CPU smoke test with a few hundred particles."""

BEVERLOO_SMOKE = {
    # seed 000's pellet contacts on spheres: cohesionless, mu_s 0.55, constant-torque mu_r 0.05 -- free-flowing,
    # as Beverloo's law needs (the feed's EPSD mu_r 0.21 makes spheres roll like angular grains)
    "particle": "sphere",
    "material": "pellet",
    "particle_radius": 0.002,
    # 1500 spheres fill the 60 deg cone about 10 diameters (1.3 outlet diameters) deep: a head-independent rate
    "count": 1500,
    "rate": 5000.0,
    "top_diameter": 0.1,
    # 7.5 diameters, above the law's lower limit of about 6; no stem: the outlet is the cone's own edge
    "outlet_diameter": 0.03,
    "stem_length": 0.0,
    # the pile (about 22 mm high) stays clear of the outlet, so nothing throttles the stream
    "outlet_height": 0.04,
    "plate_size": 0.2,
    # the plate catches the stream (nothing rolls out of the domain, so the discharged mass is conserved);
    # the flow through the outlet never touches it
    "plate_rolling_friction": 0.3,
    "cell": 0.01,
    # the pour ends at 0.3 s; the fill has settled by 0.6 s
    "gate_time": 0.6,
    "duration": 2.0,
    # about 30 samples in the steady part of a 0.5 s discharge
    "output_interval": 0.01,
}
"""Funnel overrides (over the full-size defaults) of a CPU-sized Beverloo check, about 20 s on one core: a gated
hopper of free-flowing spheres, filled and settled before its 7.5-diameter outlet opens (README, Discharge
rate)."""


def params(rig: str, values: dict | None = None):
    """The rig's parameter dataclass with ``values`` (strings are parsed: numbers, true/false)."""
    if rig not in RIGS:
        raise StageError(f"rig = {rig!r} is not allowed; expected one of {', '.join(RIGS)}")
    cls = RIGS[rig]
    names = {f.name: f for f in dataclasses.fields(cls)}
    kw = {}
    for k, v in (values or {}).items():
        if k not in names:
            raise StageError(f"{rig}: parameter {k!r} is not defined; parameters: {', '.join(names)}")
        default = names[k].default
        if isinstance(v, str):
            if isinstance(default, bool):
                if v.lower() not in ("true", "false", "1", "0"):
                    raise StageError(f"{rig}: {k} = {v!r} is not allowed; expected true or false")
                v = v.lower() in ("true", "1")
            elif isinstance(default, (int, float)):
                try:
                    v = json.loads(v)
                except ValueError:
                    pass  # typed_number refuses the word
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            # no coercion: true is not a count, 1.5 is not a whole number
            v = typed_number(rig, k, v, type(default), error=StageError)
        kw[k] = v
    try:
        return cls(**kw)
    except ValueError as e:
        raise StageError(str(e)) from None


def spec(rig: str, values: dict | None = None, smoke: bool = False) -> SceneSpec:
    """SceneSpec of ``rig`` from parameter ``values`` (over the SMOKE set when ``smoke``)."""
    merged = dict(SMOKE[rig]) if smoke else {}
    merged.update(values or {})
    p = params(rig, merged)
    s = p.spec()
    s.authoring = {k: getattr(p, k) for k in merged}
    return s


def new(rig: str, path, values: dict | None = None, smoke: bool = False):
    """Write the stage of ``rig`` with parameter ``values`` to ``path``; returns the stage."""
    from .stage import write_stage

    return write_stage(spec(rig, values, smoke), path)


def load(path, overrides: dict | None = None) -> SceneSpec:
    """Read a stage and apply ``--set`` overrides. A rig parameter among them regenerates the scene from
    the parameters recorded in the stage (``warpdem:authoring``) before the other overrides apply."""
    from .stage import apply_overrides, read_stage

    spec_ = read_stage(path)
    overrides = dict(overrides or {})
    rig_keys = {k: v for k, v in overrides.items() if is_rig_key(k)}
    if rig_keys:
        values = dict(spec_.authoring)
        values.update(rig_keys)
        spec_ = spec(spec_.rig, values)
    return apply_overrides(spec_, {k: v for k, v in overrides.items() if k not in rig_keys})
