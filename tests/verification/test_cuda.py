"""The same verification table on CUDA (skipped cleanly without a GPU)."""

import dataclasses

import pytest

from tests.conftest import RunKilled, kill_past, requires_cuda
from tests.verification.test_analytic import _assert_records
from warpdem.verify import cases as verify


@requires_cuda
@pytest.mark.parametrize("name", list(verify.CASES))
def test_case_cuda(name):
    """Each analytic case produces records and passes on the first CUDA device with the CPU tolerances."""
    _assert_records(verify.CASES[name]("cuda:0"))


@requires_cuda
def test_graph_blocks_match_host_reads():
    """Blocks of captured steps with the rebuild as a conditional node give bit-identical states to the
    fallback that reads the rebuild flag on the host every step (a tiny skin forces many rebuilds)."""
    import numpy as np

    import warpdem as wd

    rng = np.random.default_rng(3)
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", restitution=0.5, static_friction=0.5)
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    pts = [(i * 0.011, j * 0.011, 0.006 + k * 0.011) for i in range(4) for j in range(4) for k in range(4)]
    b.add_spheres(np.asarray(pts) + rng.uniform(-5e-4, 5e-4, (len(pts), 3)), 0.005, "a")
    out = []
    for block in (32, 0):
        m = b.finalize("cuda:0")
        s = wd.Solver(m, wd.SolverOptions(skin=2e-5))
        s.cuda_graph_steps = block
        st = s.run(m.state(), s.contacts(), 501)
        assert s.cuda_graph_steps == block, "the conditional capture fell back to host reads"
        out.append((st.sphere_x.numpy(), st.sphere_v.numpy()))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
    assert out[0][0][:, 2].min() < 0.0055, "the spheres never reached the plane"


@requires_cuda
def test_clump_integration_one_thread_or_a_block_per_clump():
    """8-sphere clumps integrated by one thread each, or by a block of lanes each (the path of large clumps), take
    the same step from the same state: the two differ only in the order of a clump's force sum, so the velocities
    agree to float32 rounding (a dropped sphere or torque term would change them by its whole share)."""
    import numpy as np

    import warpdem as wd
    from tests.engine.test_features import _bed

    out = []
    for large in (False, True):
        m = _bed("clumps", device="cuda:0")
        s = wd.Solver(m, wd.SolverOptions(dt=2e-5))
        assert not s.features.large_clumps
        c = s.contacts()
        st = s.run(m.state(), c, 300)  # the clumps land: contacts with the floor, the patch and each other
        s.features = dataclasses.replace(s.features, large_clumps=large)
        st = s.run(st, c, 1)
        out.append((st.sphere_v.numpy(), st.clump_w.numpy()))
    speed = np.abs(out[0][0]).max()
    assert speed > 1e-3, "the clumps should be moving"
    assert np.abs(out[0][0] - out[1][0]).max() <= 1e-5 * speed
    assert np.abs(out[0][1] - out[1][1]).max() <= 1e-5 * np.abs(out[0][1]).max()


@requires_cuda
def test_checkpoint_resumes_on_another_cuda_device(tmp_path):
    """A run stopped on cuda:0 resumes from its checkpoint when the next call names another CUDA device (the
    last one, or "cuda"), and ends where the uninterrupted run on cuda:0 ends."""
    import numpy as np
    import warp as wp

    from warpdem.scene import rigs, runner

    spec = rigs.spec("funnel", {"count": 60, "duration": 0.2}, smoke=True)
    a = runner.run_scene(spec, "cuda:0", out_dir=tmp_path / "a", frames=False, checkpoint_every=1e-9)

    with pytest.raises(RunKilled):
        runner.run_scene(
            spec, "cuda:0", out_dir=tmp_path / "b", frames=False, checkpoint_every=1e-9, progress=kill_past(0.5)
        )
    other = f"cuda:{wp.get_cuda_device_count() - 1}" if wp.get_cuda_device_count() > 1 else "cuda"
    b = runner.run_scene(spec, other, out_dir=tmp_path / "b", frames=False, checkpoint_every=1e-9)
    assert b.info["resumed_from_s"] is not None and 0.05 < b.info["resumed_from_s"] < 0.2
    assert b.info["steps"] == a.info["steps"]
    xa = np.load(tmp_path / "a" / "final.npz")["sphere_x"]
    xb = np.load(tmp_path / "b" / "final.npz")["sphere_x"]
    # the same kind of GPU runs the same kernels: the resumed run ends bit-identical
    assert np.array_equal(xa, xb)
