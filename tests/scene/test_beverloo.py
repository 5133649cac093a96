"""The funnel's discharge rate against Beverloo's law: a gated hopper of free-flowing spheres
(``rigs.BEVERLOO_SMOKE``), filled and settled before its outlet opens, run once on the CPU."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpdem.scene import measure, rigs, runner

pytest.importorskip("pxr.Usd")


@pytest.fixture(scope="module")
def gated(tmp_path_factory):
    """The Beverloo smoke funnel written as a stage, read back and run (no frames)."""
    path = tmp_path_factory.mktemp("beverloo") / "funnel.usda"
    rigs.new("funnel", path, rigs.BEVERLOO_SMOKE)
    spec = rigs.load(path)
    result = runner.run_scene(spec, device="cpu", out_dir=path.parent / "out", frames=False)
    return {"spec": spec, "result": result, "params": rigs.params("funnel", rigs.BEVERLOO_SMOKE)}


def test_discharge_rate_within_the_beverloo_band(gated):
    """The steady discharge rate lies inside Beverloo's band over the literature's spread (C 0.55-0.65, k
    1.3-2.9; Nedderman 1992), with the fill's own bulk density (measured in the funnel just before the gate
    opens) and Rose and Tanaka's factor for the 60 deg cone (half angle 30 deg, steeper than the flat-bottom
    limit 90 - phi_d = 45 deg). A jammed outlet (no rate) or a funnel that passes a slower feed falls below
    the band; the ungated smoke funnel lies above its own (test_rigs)."""
    m, p = gated["result"].metrics[0], gated["params"]
    assert "discharge_error" not in m and "packing_error" not in m, m
    band = measure.beverloo_band(
        p.outlet_diameter,
        2 * p.particle_radius,
        m["bulk_density_kg_m3"],
        cone_half_angle=p.cone_angle / 2,
    )
    assert band["low_kg_s"] < m["discharge_rate_kg_s"] < band["high_kg_s"], (m["discharge_rate_kg_s"], band)


def test_fill_and_discharge(gated):
    """The fill packs as poured spheres do (random loose 0.55 to random close 0.64), nothing leaves before the
    gate opens, and everything leaves after (mass conservation: all 1500 spheres' mass to 2 %, the radius
    spread's third moment; none removed from the domain). The steady part follows the opening."""
    m, p, spec = gated["result"].metrics[0], gated["params"], gated["spec"]
    assert 0.55 < m["packing_fraction"] < 0.64
    rho = spec.material("grain").density
    volume = 4 / 3 * math.pi * p.particle_radius**3 * (1 + 3 * p.radius_spread**2)
    assert m["discharged_kg"] == pytest.approx(p.count * rho * volume, rel=0.02)
    assert m["removed"] == 0
    series = gated["result"].series
    t = np.asarray(series["time"])
    discharged = np.asarray(series["discharged_kg"])[:, 0]
    assert np.all(discharged[t <= p.gate_time + 1e-9] == 0)
    assert p.gate_time < m["steady_from_s"] < m["steady_to_s"]


def test_gate_holds_the_fill_then_stays_clear(gated):
    """The gate carries the settled fill's weight (the funnel's walls carry part of it) and, once it has opened,
    feels no force at all: it drops faster than the grains fall and leaves the outlet's shadow before they
    reach it, so the stream is never disturbed. The fill had settled when it opened (kinetic energy per
    particle below the run's settling threshold)."""
    p, spec, series = gated["params"], gated["spec"], gated["result"].series
    t = np.asarray(series["time"])
    gate = len(np.asarray(series["wall_force"])[0]) - 1  # the last surface: walls follow planes, Gate last
    assert [w.name for w in spec.walls][-1] == "Gate"
    force = np.asarray(series["wall_force"])[:, gate]
    weight = spec.material("grain").density * 9.81 * p.count * 4 / 3 * math.pi * p.particle_radius**3
    at_gate = int(np.argmin(np.abs(t - p.gate_time)))  # the runner ends a tick there (the packing time)
    assert t[at_gate] == pytest.approx(p.gate_time, abs=1e-4)
    assert 0 < -force[at_gate] < weight
    # from the second output after the opening on (the first still holds the instant the fill lets go)
    assert np.all(force[t > p.gate_time + 1.5 * p.output_interval] == 0)
    assert np.asarray(series["kinetic_energy"])[at_gate, 0] < spec.run.settle_energy
