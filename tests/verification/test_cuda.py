"""The same verification table on CUDA (skipped cleanly without a GPU)."""

import pytest

from warpdem import verify

from ..conftest import requires_cuda


@requires_cuda
@pytest.mark.parametrize("name", list(verify.CASES))
def test_case_cuda(name):
    """Each analytic case passes on the first CUDA device with the CPU tolerances."""
    recs = verify.CASES[name]("cuda:0")
    bad = [f"{r.case}: {r.name} = {r.value:.6g} vs {r.expected:.6g}" for r in recs if not r.passed]
    assert not bad, "\n".join(bad)
