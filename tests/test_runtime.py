"""The process runtime's decisions that need no process: BLAS threads per rank."""
from ddsolve.parallel.runtime import blas_threads


def test_blas_threads_share_the_cores_among_the_ranks_of_a_node():
    assert blas_threads(2, {}) == 2  # one process: every core
    assert blas_threads(2, {"OMPI_COMM_WORLD_LOCAL_SIZE": "2"}) == 1  # two ranks on two cores: one each
    assert blas_threads(2, {"OMPI_COMM_WORLD_LOCAL_SIZE": "8"}) == 1  # oversubscribed: never none
    assert blas_threads(16, {"MPI_LOCALNRANKS": "4"}) == 4  # MPICH's variable
    assert blas_threads(16, {"OMPI_COMM_WORLD_LOCAL_SIZE": "junk"}) == 16


def test_the_users_thread_count_is_kept():
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "GOTO_NUM_THREADS"):
        assert blas_threads(2, {name: "2", "OMPI_COMM_WORLD_LOCAL_SIZE": "2"}) is None
