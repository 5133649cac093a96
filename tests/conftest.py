import pytest
import warp as wp

wp.config.quiet = True
wp.init()


def cuda_available() -> bool:
    return wp.get_cuda_device_count() > 0


requires_cuda = pytest.mark.skipif(not cuda_available(), reason="no CUDA device (CI has none)")
