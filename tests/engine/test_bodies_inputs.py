"""Bad input for clumps, moving walls, factories and the cohesive laws is refused with a clear message."""

import numpy as np
import pytest

import warpdem as wd


def test_cohesive_interaction_fields_are_validated():
    """Negative surface energy, a repulsive pull-off force and a plasticity ratio of 1 are refused by name."""
    with pytest.raises(ValueError, match="surface_energy = -0.1"):
        wd.Interaction(law="JKR", surface_energy=-0.1)
    with pytest.raises(ValueError, match="pull_off_force = 0.001"):
        wd.Interaction(law="EEPA", pull_off_force=1e-3)
    with pytest.raises(ValueError, match="plasticity_ratio = 1.0"):
        wd.Interaction(law="EEPA", plasticity_ratio=1.0)
    with pytest.raises(ValueError, match="law = 'DMT'"):
        wd.Interaction(law="DMT")
    assert wd.Interaction(law="hertz-mindlin-jkr").law == wd.ContactLaw.JKR


def test_wall_motion_is_validated():
    """Overlapping segments, a segment ending before it starts and non-unit keyframe rotations are refused."""
    with pytest.raises(ValueError, match="end = 0.5"):
        wd.Segment(1.0, 0.5)
    with pytest.raises(ValueError, match="segments\\[1\\].start"):
        wd.WallMotion.schedule([wd.Segment(0.0, 1.0), wd.Segment(0.5, 2.0)])
    with pytest.raises(ValueError, match="unit quaternions"):
        wd.WallMotion.keyframes([0.0, 1.0], [(0, 0, 0), (1, 0, 0)], [(0, 0, 0, 2), (0, 0, 0, 1)])
    b = wd.ModelBuilder()
    b.add_material(wd.Material("m", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    with pytest.raises(ValueError, match="motion = 'up'"):
        b.add_wall_mesh([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], "m", motion="up")


def test_wall_motion_host_pose_is_rigid_kinematics():
    """A constant velocity then a quarter turn about z through (1, 0, 0): poses follow the formulas."""
    m = wd.WallMotion.schedule(
        [
            wd.Segment(0.0, 1.0, velocity=(0.5, 0, 0)),
            wd.Segment(2.0, 3.0, angular_velocity=(0, 0, np.pi / 2), pivot=(1.0, 0, 0)),
        ]
    )
    pos, q = m.pose(1.5)
    assert np.allclose(pos, (0.5, 0, 0)) and np.allclose(q, (0, 0, 0, 1))
    pos, q = m.pose(5.0)
    # the origin, at (0.5, 0, 0) after the slide, turns 90 deg about (1, 0, 0): to (1, -0.5, 0)
    assert np.allclose(pos, (1.0, -0.5, 0.0), atol=1e-12)
    assert np.allclose(q, (0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)))


def test_clumps_need_a_template_and_unit_orientations():
    """add_clumps refuses an object that is not a template, a zero quaternion and a negative scale."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("m", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    with pytest.raises(TypeError, match="expected a ClumpTemplate"):
        b.add_clumps(object(), [(0, 0, 0)], "m")
    tpl = wd.ClumpTemplate.from_spheres("pair", [(-1e-3, 0, 0), (1e-3, 0, 0)], [1.5e-3, 1.5e-3])
    with pytest.raises(ValueError, match="zero quaternion"):
        b.add_clumps(tpl, [(0, 0, 0)], "m", orientations=[(0, 0, 0, 0)])
    with pytest.raises(ValueError, match="scale = -1"):
        b.add_clumps(tpl, [(0, 0, 0)], "m", scale=-1.0)


def test_clump_and_sphere_mix_and_union_mass_is_used():
    """A clump and a free sphere in one scene: the clump falls as one rigid body (distances between its
    spheres unchanged) and the model's clump volume is the union's, not the sum of its spheres."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("m", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_plane((0, 0, 0), (0, 0, 1), "m")
    tpl = wd.ClumpTemplate.from_spheres("pair", [(-1e-3, 0, 0), (1e-3, 0, 0)], [1.5e-3, 1.5e-3])
    b.add_clump(tpl, (0, 0, 0.01), "m", orientation=(0, np.sin(0.3), 0, np.cos(0.3)))
    b.add_sphere((0.01, 0, 0.005), 1e-3, "m")
    model = b.finalize("cpu")
    assert model.clump_volume.numpy()[0] == pytest.approx(tpl.volume, rel=1e-6)
    h = 1.5e-3 - 1e-3  # two caps of height r - d/2 make the lens counted twice by a plain sum
    lens = 2 * np.pi * h * h * (3 * 1.5e-3 - h) / 3
    assert tpl.volume == pytest.approx(2 * 4 / 3 * np.pi * 1.5e-3**3 - lens, rel=2e-3)
    solver = wd.Solver(model)
    state = solver.run(model.state(), solver.contacts(), int(0.4 / solver.dt))
    x = state.sphere_x.numpy()
    assert np.linalg.norm(x[0] - x[1]) == pytest.approx(2e-3, rel=1e-5)
    assert x[2, 2] == pytest.approx(1e-3, abs=1e-4)  # the sphere rests on the floor
    assert x[:2, 2].min() > 1.4e-3  # the clump landed on the floor too, not through it


def test_clump_factory_needs_the_template_bounding_ratio():
    """A dynamic factory of clumps must keep them apart by their bounding radius, or add_factory refuses it."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("m", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    grain = wd.phosphate_template()
    fac = wd.DynamicFactory(wd.Box((0, 0, 0), (0.01, 0.01, 0.01)), wd.FixedSize(1e-3), rate=100, count=5, seed=1)
    with pytest.raises(ValueError, match="bounding_ratio = 1.0"):
        b.add_factory(fac, "m", template=grain)


def test_control_assign_moves_a_wall_by_the_new_table_in_place():
    """A wall keyframed along +x is switched to -z after 0.1 s: at 0.2 s its pose is the new motion's, (0, 0,
    -0.2) m, to float32, through the same device arrays; a table of another segment count is refused."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("m", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_wall_mesh(
        [(0, 0, 0), (1, 0, 0), (0, 1, 0)],
        [(0, 1, 2)],
        "m",
        motion=wd.WallMotion.keyframes([0.0, 1.0], [(0, 0, 0), (1, 0, 0)]),
    )
    b.add_spheres([(5.0, 5.0, 5.0)], 0.1, "m")
    m = b.finalize("cpu")
    s = wd.Solver(m, wd.SolverOptions(dt=1e-3))
    c = s.contacts()
    st = s.run(m.state(), c, 100)
    assert st.wall_pose.numpy()[0, :3] == pytest.approx([0.1, 0.0, 0.0], abs=1e-6)
    arrays = [s.control.segment_t0, s.control.segment_v]
    table = wd.MotionTable.build([wd.WallMotion.keyframes([0.0, 1.0], [(0, 0, 0), (0, 0, -1)])])
    s.control.assign(table)
    assert [s.control.segment_t0, s.control.segment_v] == arrays
    st = s.run(st, c, 100)
    assert st.wall_pose.numpy()[0, :3] == pytest.approx([0.0, 0.0, -0.2], abs=1e-6)
    with pytest.raises(ValueError, match="segments per wall"):
        s.control.assign(wd.MotionTable.build([wd.WallMotion.keyframes([0.0, 1.0, 2.0], [(0, 0, 0)] * 3)]))
