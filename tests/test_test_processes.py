"""The test processes themselves: one BLAS/OpenMP thread each (tests/conftest.py), as the 2 pytest-xdist workers
fill the 2 cores."""
import threadpoolctl


def test_every_thread_pool_of_a_test_process_has_one_thread():
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS, loaded after conftest)
    import numpy as np

    np.ones((64, 64)) @ np.ones((64, 64))
    pools = threadpoolctl.threadpool_info()
    assert pools, "no BLAS or OpenMP library found loaded"
    assert {(pool["filepath"], pool["num_threads"]) for pool in pools} == {(pool["filepath"], 1) for pool in pools}
