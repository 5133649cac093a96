"""Results writers: time-sampled USD with changing particle counts, the VTK series, clump expansion, pictures."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from warpdem.scene.export import (
    ResultWriter,
    ShapeGeometry,
    WallGeometry,
    expand_clumps,
    save_figure,
    side_view_png,
)

# usd-core may be missing: skip the module rather than fail at import
Sdf = pytest.importorskip("pxr.Sdf")
Usd = pytest.importorskip("pxr.Usd")
UsdGeom = pytest.importorskip("pxr.UsdGeom")

SPHERES = (3, 7, 7)  # loose spheres per frame
CLUMPS = (0, 5, 12)  # clumps per frame: the count grows, starting from none
TIMES = (0.0, 0.01, 0.025)  # uneven spacing: time codes are frame indices regardless
WALL_SHIFT = np.array([0.0, 0.002, -0.03])  # wall translation per frame [m]


def _plate():
    """A 2-triangle square plate, 0.1 m across, in its own frame."""
    v = np.array([[-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0], [-0.05, 0.05, 0.0]])
    return WallGeometry("floor plate-1", v, np.array([[0, 1, 2], [0, 2, 3]]))


def _shapes():
    """Two clump shapes: a 2-sphere dumbbell and a 3-sphere triangle."""
    return [
        ShapeGeometry("dumbbell", [[-1e-3, 0, 0], [1e-3, 0, 0]], [1.5e-3, 1.5e-3]),
        ShapeGeometry("tri", [[0, 0, 0], [2e-3, 0, 0], [0, 2e-3, 0]], [1e-3, 1.2e-3, 0.8e-3]),
    ]


def _frames():
    """Three frames whose sphere and clump counts grow; random but reproducible."""
    rng = np.random.default_rng(7)
    frames = []
    for f, (n, k) in enumerate(zip(SPHERES, CLUMPS)):
        q = rng.normal(size=(k, 4))
        frames.append(
            dict(
                sphere_x=rng.uniform(-0.04, 0.04, (n, 3)),
                sphere_r=rng.uniform(1e-3, 2e-3, n),
                sphere_id=np.arange(n) + 100,
                sphere_v=rng.normal(size=(n, 3)),
                clump_x=rng.uniform(-0.04, 0.04, (k, 3)),
                clump_q=q / np.linalg.norm(q, axis=1, keepdims=True),
                clump_shape=rng.integers(0, 2, k),
                clump_scale=rng.uniform(0.8, 1.2, k),
                clump_id=np.arange(k),
                clump_v=rng.normal(size=(k, 3)),
                wall_pose=np.array([[*(f * WALL_SHIFT), 0.0, 0.0, 0.0, 1.0]]),
                face_impacts=[np.array([f, 2 * f])],
                face_energy=[np.array([0.5 * f, 1e-3])],
            )
        )
    return frames


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The three frames written once (USD + VTK); returns (summary, frames, out_dir)."""
    out = tmp_path_factory.mktemp("result")
    frames = _frames()
    writer = ResultWriter(out, [_plate()], _shapes())
    for t, frame in zip(TIMES, frames):
        writer.add_frame(t, **frame)
    info = writer.close()
    return info, frames, out


@pytest.fixture(scope="module")
def stage(written):
    """The stage reopened from disk after close()."""
    info = written[0]
    # close() dropped every handle, so this reads the file rather than a layer still in memory.
    assert Sdf.Layer.Find(info["usd"]) is None
    return Usd.Stage.Open(info["usd"])


def test_close_summary(written):
    """close() reports the stage, the .pvd and the frame count; a second close() returns the same."""
    info, _, out = written
    assert info == {"usd": str(out / "result.usdc"), "vtk_series": str(out / "result.pvd"), "frames": 3}


def test_usd_prims_have_expected_types(stage):
    """/World (default prim), Points, PointInstancer with its prototypes, and the wall Mesh exist."""
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    assert stage.GetPrimAtPath("/World/Spheres").GetTypeName() == "Points"
    assert stage.GetPrimAtPath("/World/Clumps").GetTypeName() == "PointInstancer"
    wall = stage.GetPrimAtPath("/World/Walls/floor_plate_1")  # name sanitised to a USD identifier
    assert wall.GetTypeName() == "Mesh"
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Clumps"))
    targets = inst.GetPrototypesRel().GetTargets()
    assert targets == [Sdf.Path("/World/Clumps/Prototypes/dumbbell"), Sdf.Path("/World/Clumps/Prototypes/tri")]
    tri = stage.GetPrimAtPath(targets[1])
    assert tri.GetTypeName() == "Xform"
    spheres = [UsdGeom.Sphere(c) for c in tri.GetAllChildren()]  # not GetChildren: under an "over"
    assert [s.GetRadiusAttr().Get() for s in spheres] == pytest.approx([1e-3, 1.2e-3, 0.8e-3])
    assert spheres[1].GetPrim().GetAttribute("xformOp:translate").Get() == pytest.approx((2e-3, 0, 0))


def test_prototypes_are_skipped_by_default_traversal(stage):
    """The prototypes sit under an "over", so generic traversals (and renderers) do not draw them alone."""
    assert stage.GetPrimAtPath("/World/Clumps/Prototypes").GetSpecifier() == Sdf.SpecifierOver
    traversed = {str(p.GetPath()) for p in stage.Traverse()}
    assert not any(p.startswith("/World/Clumps/Prototypes") for p in traversed)
    assert "/World/Clumps" in traversed


def test_usd_stage_metadata(stage):
    """upAxis Z, metersPerUnit 1, time codes 0..2 (frame index), mean simulated frame rate."""
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 2.0)
    assert stage.GetTimeCodesPerSecond() == pytest.approx(2 / TIMES[-1])
    times = stage.GetPrimAtPath("/World").GetAttribute("warpdem:time")
    assert [times.Get(f) for f in range(3)] == pytest.approx(TIMES)


def test_usd_one_time_sample_per_frame(stage):
    """points, positions, protoIndices and the wall transform each have exactly 3 time samples."""
    for path in (
        "/World/Spheres.points",
        "/World/Spheres.widths",
        "/World/Spheres.ids",
        "/World/Clumps.positions",
        "/World/Clumps.orientations",
        "/World/Clumps.scales",
        "/World/Clumps.protoIndices",
        "/World/Clumps.ids",
        "/World/Walls/floor_plate_1.xformOp:translate",
        "/World/Walls/floor_plate_1.xformOp:orient",
    ):
        assert stage.GetAttributeAtPath(path).GetNumTimeSamples() == 3, path


def test_usd_counts_follow_each_frame(stage, written):
    """Array lengths at each time code equal that frame's sphere / clump count, including zero."""
    frames = written[1]
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Clumps"))
    pts = UsdGeom.Points(stage.GetPrimAtPath("/World/Spheres"))
    for f, (n, k) in enumerate(zip(SPHERES, CLUMPS)):
        for attr in (
            inst.GetPositionsAttr(),
            inst.GetOrientationsAttr(),
            inst.GetScalesAttr(),
            inst.GetProtoIndicesAttr(),
            inst.GetIdsAttr(),
            inst.GetVelocitiesAttr(),
        ):
            assert len(attr.Get(f)) == k, (attr.GetName(), f)
        for attr in (pts.GetPointsAttr(), pts.GetWidthsAttr(), pts.GetIdsAttr(), pts.GetVelocitiesAttr()):
            assert len(attr.Get(f)) == n, (attr.GetName(), f)
        np.testing.assert_allclose(np.array(pts.GetPointsAttr().Get(f)), frames[f]["sphere_x"], rtol=1e-6)
        np.testing.assert_allclose(np.array(pts.GetWidthsAttr().Get(f)), 2 * frames[f]["sphere_r"], rtol=1e-6)
        assert list(pts.GetIdsAttr().Get(f)) == list(frames[f]["sphere_id"])


def test_usd_proto_indices_and_scales_last_frame(stage, written):
    """protoIndices at the last frame equal the input; scales are uniform (s, s, s)."""
    last = written[1][-1]
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Clumps"))
    assert list(inst.GetProtoIndicesAttr().Get(2)) == list(last["clump_shape"])
    scales = np.array(inst.GetScalesAttr().Get(2))
    np.testing.assert_allclose(scales, np.repeat(last["clump_scale"][:, None], 3, axis=1), rtol=1e-6)


def test_usd_orientations_round_trip(stage, written):
    """(x, y, z, w) -> USD quath (real, imaginary) -> (x, y, z, w) within half precision (1e-3)."""
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Clumps"))
    for f in (1, 2):
        back = np.array([[*q.GetImaginary(), q.GetReal()] for q in inst.GetOrientationsAttr().Get(f)])
        np.testing.assert_allclose(back, written[1][f]["clump_q"], atol=1e-3)


def test_usd_instance_transforms_place_clump_spheres(stage, written):
    """USD's own instance transforms put the prototype spheres where expand_clumps puts them."""
    last = written[1][-1]
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Clumps"))
    xforms = inst.ComputeInstanceTransformsAtTime(Usd.TimeCode(2), Usd.TimeCode(2))
    world, _, body = expand_clumps(
        last["clump_x"], last["clump_q"], last["clump_shape"], last["clump_scale"], _shapes()
    )
    shapes = _shapes()
    first = 0
    for i, m in enumerate(xforms):
        offsets = shapes[last["clump_shape"][i]].sphere_offset
        got = np.array([m.Transform(tuple(o)) for o in offsets])
        np.testing.assert_allclose(got, world[first : first + len(offsets)], atol=2e-6)  # quath: ~5e-4 rad
        assert np.all(body[first : first + len(offsets)] == i)
        first += len(offsets)


def test_usd_wall_translation_and_primvars(stage):
    """The wall's world transform at frame 2 is 2 * shift; impact primvars: one value per face, uniform."""
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Walls/floor_plate_1"))
    m = mesh.ComputeLocalToWorldTransform(Usd.TimeCode(2))
    np.testing.assert_allclose(np.array(m.ExtractTranslation()), 2 * WALL_SHIFT, atol=1e-12)
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3, 3]
    assert list(mesh.GetFaceVertexIndicesAttr().Get()) == [0, 1, 2, 0, 2, 3]
    api = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    count, energy = api.GetPrimvar("impactCount"), api.GetPrimvar("impactEnergy")
    assert count.GetInterpolation() == UsdGeom.Tokens.uniform
    assert energy.GetInterpolation() == UsdGeom.Tokens.uniform
    assert count.GetTypeName() == Sdf.ValueTypeNames.IntArray
    assert list(count.Get(2)) == [2, 4]
    assert list(energy.Get(2)) == pytest.approx([1.0, 1e-3])
    assert count.GetAttr().GetNumTimeSamples() == 3


def test_vtk_collection_lists_three_timesteps(written):
    """result.pvd is a VTK Collection listing particles and walls at each of the 3 frame times."""
    info = written[0]
    root = ET.parse(info["vtk_series"]).getroot()
    assert root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    particles = [d for d in sets if d.get("part") == "0"]
    walls = [d for d in sets if d.get("part") == "1"]
    assert [float(d.get("timestep")) for d in particles] == pytest.approx(TIMES)
    assert [float(d.get("timestep")) for d in walls] == pytest.approx(TIMES)
    assert particles[2].get("file") == "vtk/particles_00002.vtp"


def test_vtk_particles_read_back(written):
    """The last particles file holds loose spheres plus every clump's spheres, with radius, body, speed."""
    pv = pytest.importorskip("pyvista")
    _, frames, out = written
    last = frames[-1]
    world, radius, body = expand_clumps(
        last["clump_x"], last["clump_q"], last["clump_shape"], last["clump_scale"], _shapes()
    )
    cloud = pv.read(out / "vtk" / "particles_00002.vtp")
    assert cloud.n_points == SPHERES[-1] + len(radius)
    np.testing.assert_allclose(cloud.point_data["radius"], np.concatenate([last["sphere_r"], radius]), rtol=1e-6)
    np.testing.assert_allclose(cloud.points, np.concatenate([last["sphere_x"], world]), atol=1e-7)
    assert np.all(cloud.point_data["body"][: SPHERES[-1]] == -1)
    assert np.array_equal(cloud.point_data["body"][SPHERES[-1] :], last["clump_id"][body])
    np.testing.assert_allclose(
        cloud.point_data["speed"][SPHERES[-1] :], np.linalg.norm(last["clump_v"], axis=1)[body], rtol=1e-5
    )
    empty = pv.read(out / "vtk" / "particles_00000.vtp")  # frame 0: loose spheres only
    assert empty.n_points == SPHERES[0]


def test_vtk_walls_in_world(written):
    """The walls file holds the plate translated to its frame-2 pose, with per-face impact data."""
    pv = pytest.importorskip("pyvista")
    mesh = pv.read(written[2] / "vtk" / "walls_00002.vtp")
    np.testing.assert_allclose(mesh.points, _plate().vertices + 2 * WALL_SHIFT, atol=1e-12)
    assert list(mesh.cell_data["impactCount"]) == [2, 4]
    assert list(mesh.cell_data["wall"]) == [0, 0]


def test_expand_clumps_quarter_turn_about_z():
    """A 90 deg turn about z takes offset (1, 0, 0) to (0, 1, 0), times the scale; radii scale too."""
    shape = ShapeGeometry("pair", [[1.0, 0, 0], [0, 0, 0]], [0.5, 0.25])
    h = math.sqrt(0.5)
    x, r, body = expand_clumps([[10.0, 0, 0], [0, 0, 0]], [[0, 0, h, h], [0, 0, 0, 1]], [0, 0], [2.0, 1.0], [shape])
    np.testing.assert_allclose(x, [[10, 2, 0], [10, 0, 0], [1, 0, 0], [0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(r, [1.0, 0.5, 0.5, 0.25])
    assert list(body) == [0, 0, 1, 1]
    x, r, body = expand_clumps(np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0, int), None, [shape])
    assert x.shape == (0, 3) and r.shape == (0,) and body.shape == (0,)


def test_side_view_png_writes_file(tmp_path):
    """A picture with walls and a colour scale is written and is a non-empty PNG."""
    rng = np.random.default_rng(3)
    x = rng.uniform(-0.02, 0.02, (500, 3))
    plate = _plate()
    path = side_view_png(
        tmp_path / "pile.png",
        x,
        np.full(500, 1e-3),
        [(plate.vertices, plate.triangles)],
        axis="x",
        title="pile",
        colour_by=x[:, 2],
    )
    data = open(path, "rb").read()
    assert len(data) > 1000 and data[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_figure_is_saved_as_a_palette_png_that_looks_the_same(tmp_path):
    """save_figure writes a .png as a 256-colour palette image, smaller than matplotlib's own RGBA file, whose
    pixels are matplotlib's up to the quantizer's rounding where a plot's colours are few; another suffix is
    matplotlib's own format (a PDF stays a PDF)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0, 1, 2], [0, 1, 4], color="tab:red")
    ax.axhline(2.0, color="0.5", ls="--")
    try:
        plain = io.BytesIO()
        fig.savefig(plain, format="png", dpi=80)
        got = save_figure(fig, tmp_path / "plot.png", dpi=80)
        save_figure(fig, tmp_path / "plot.pdf")
    finally:
        plt.close(fig)
    assert got == str(tmp_path / "plot.png")
    data = (tmp_path / "plot.png").read_bytes()
    assert len(data) < len(plain.getvalue())
    with Image.open(tmp_path / "plot.png") as out, Image.open(io.BytesIO(plain.getvalue())) as ref:
        assert out.mode == "P" and out.size == ref.size
        a, b = np.asarray(out.convert("RGBA"), int), np.asarray(ref.convert("RGBA"), int)
    # antialiased edges blend many shades; a palette of 256 keeps nearly every pixel within a few levels
    assert np.mean(np.abs(a - b).max(axis=2) <= 8) > 0.99
    assert (tmp_path / "plot.pdf").read_bytes()[:5] == b"%PDF-"


def test_side_view_true_size_and_near_covers_far(tmp_path):
    """Discs have their true size (the blob spans 35 mm x 20 mm) and the nearer sphere is drawn on top.

    Looking along y from -y: sphere A (x = 0, y = 0) is nearer than B (x = 15 mm, y = 10 mm), both r = 10 mm;
    where they overlap (x = 7.5 mm) the picture must show A's brighter colour, not B's.
    """
    from PIL import Image

    x = np.array([[0.015, 0.010, 0.0], [0.0, 0.0, 0.0]])  # far one first: the order must not matter
    path = side_view_png(tmp_path / "two.png", x, [0.01, 0.01], axis="y", figsize=(4, 4), dpi=100)
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(float) / 255
    sat = (rgb.max(axis=2) - rgb.min(axis=2)) / np.maximum(rgb.max(axis=2), 1e-9)
    rows, cols = np.nonzero(sat > 0.2)  # the sand colour; axes, ticks and text are grey
    width, height = cols.max() - cols.min() + 1, rows.max() - rows.min() + 1
    assert width / height == pytest.approx(35 / 20, rel=0.03)

    def pixel(x_mm):
        c = cols.min() + (x_mm + 10) / 35 * (width - 1)
        return rgb[(rows.min() + rows.max()) // 2, int(round(c))]

    near, overlap, far = pixel(-5.0), pixel(7.5), pixel(20.0)
    np.testing.assert_allclose(overlap, near, atol=0.02)
    assert far.sum() < 0.8 * near.sum()  # depth shading: farther is darker


@pytest.mark.parametrize(
    "bad, name",
    [
        (dict(sphere_r=np.full(4, 1e-3)), "sphere_r"),
        (dict(sphere_id=np.arange(2)), "sphere_id"),
        (dict(sphere_v=np.zeros((5, 2))), "sphere_v"),
        (dict(clump_q=np.zeros((2, 3))), "clump_q"),
        (dict(clump_shape=np.array([0, 5])), "clump_shape"),
        (dict(clump_scale=np.array([1.0, -1.0])), "clump_scale"),
        (dict(clump_id=np.arange(3)), "clump_id"),
        (dict(wall_pose=np.zeros((2, 7))), "wall_pose"),
        (dict(face_impacts=[np.zeros(3, int)]), "face_impacts"),
        (dict(face_energy=[np.zeros(2), np.zeros(2)]), "face_energy"),
        (dict(sphere_x=None), "sphere_x"),
    ],
)
def test_add_frame_rejects_mismatched_shapes(tmp_path, bad, name):
    """A frame with an array of the wrong shape or value raises ValueError naming it; nothing is written."""
    good = dict(
        sphere_x=np.zeros((5, 3)),
        sphere_r=np.full(5, 1e-3),
        sphere_id=np.arange(5),
        clump_x=np.zeros((2, 3)),
        clump_q=np.tile([0, 0, 0, 1.0], (2, 1)),
        clump_shape=np.array([0, 1]),
        clump_scale=np.ones(2),
        clump_id=np.arange(2),
        wall_pose=np.array([[0, 0, 0, 0, 0, 0, 1.0]]),
    )
    writer = ResultWriter(tmp_path, [_plate()], _shapes(), vtk=False)
    try:
        with pytest.raises(ValueError, match=name) as err:
            writer.add_frame(0.0, **{**good, **bad})
        assert "not allowed; expected" in str(err.value)
        assert writer.frame_count == 0
        writer.add_frame(0.0, **good)
        with pytest.raises(ValueError, match="time"):
            writer.add_frame(0.0, **good)  # times must increase
    finally:
        writer.close()


def test_geometry_and_writer_arguments_validated(tmp_path):
    """Bad geometry and writer options raise ValueError naming the argument and the allowed values."""
    with pytest.raises(ValueError, match=r"triangles\[1\].*\[0, 3\)"):
        WallGeometry("w", np.eye(3), [[0, 1, 2], [0, 1, 3]])
    with pytest.raises(ValueError, match="sphere_radius"):
        ShapeGeometry("s", [[0, 0, 0]], [1e-3, 2e-3])
    with pytest.raises(ValueError, match="usd_name"):
        ResultWriter(tmp_path, [], [], usd_name="result.obj")
    with pytest.raises(ValueError, match="up_axis"):
        ResultWriter(tmp_path, [], [], up_axis="X")
    with pytest.raises(ValueError, match="clump_x"):
        expand_clumps(np.zeros((2, 2)), np.zeros((2, 4)), [0, 0], None, _shapes())


def test_flush_makes_a_readable_stage_before_close(tmp_path):
    """With flush_every=2 the file on disk already has 2 frames (ASCII .usda) while the writer is open;
    velocities given only from frame 1 on are blocked at frame 0 rather than held back in time."""
    writer = ResultWriter(
        tmp_path,
        [],
        _shapes(),
        usd_name="run.usda",
        vtk=False,
        flush_every=2,
        meters_per_unit=0.001,
        frames_per_second=30,
    )
    for f in range(3):
        writer.add_frame(
            0.1 * f,
            sphere_x=np.full((f + 1, 3), 0.001 * f),
            sphere_r=np.full(f + 1, 1e-3),
            sphere_id=np.arange(f + 1),
            sphere_v=None if f == 0 else np.ones((f + 1, 3)),
        )
    on_disk = Usd.Stage.Open(Sdf.Layer.OpenAsAnonymous(str(tmp_path / "run.usda")))
    points = on_disk.GetAttributeAtPath("/World/Spheres.points")
    assert points.GetNumTimeSamples() == 2
    assert on_disk.GetTimeCodesPerSecond() == 30
    assert UsdGeom.GetStageMetersPerUnit(on_disk) == 0.001
    assert tuple(points.Get(1)[0]) == pytest.approx((1.0, 1.0, 1.0))  # 1 mm in stage units of mm
    assert on_disk.GetAttributeAtPath("/World/Spheres.velocities").Get(0) is None
    writer.close()
    assert (
        Usd.Stage.Open(str(tmp_path / "run.usda")).GetAttributeAtPath("/World/Spheres.points").GetNumTimeSamples() == 3
    )
