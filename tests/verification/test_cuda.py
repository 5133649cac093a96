"""The same verification table on CUDA (skipped cleanly without a GPU)."""

import pytest

from tests.conftest import requires_cuda
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
