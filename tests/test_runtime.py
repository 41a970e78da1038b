"""The process runtime's decisions that need no rank: BLAS threads per rank, mpiexec's options, the
files PETSc's options name, the phases' CPU account."""
import pytest

from ddsolve.errors import UsageError
from ddsolve.parallel.launch import ALLOCATION_VARIABLES, launcher_options, leader, world_position
from ddsolve.parallel.runtime import blas_threads, check_petsc_files


def test_blas_threads_share_the_cores_among_the_ranks_of_a_node():
    assert blas_threads(2, {}) == 2  # one process: every core
    assert blas_threads(2, {"OMPI_COMM_WORLD_LOCAL_SIZE": "2"}) == 1  # two ranks on two cores: one each
    assert blas_threads(2, {"OMPI_COMM_WORLD_LOCAL_SIZE": "8"}) == 1  # oversubscribed: never none
    assert blas_threads(16, {"MPI_LOCALNRANKS": "4"}) == 4  # MPICH's variable
    assert blas_threads(16, {"OMPI_COMM_WORLD_LOCAL_SIZE": "junk"}) == 16


def test_the_users_thread_count_is_kept():
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "GOTO_NUM_THREADS"):
        assert blas_threads(2, {name: "2", "OMPI_COMM_WORLD_LOCAL_SIZE": "2"}) is None


def test_files_petsc_would_fail_to_read_or_write_are_refused_first(tmp_path):
    """One line naming the option, before PETSc starts (its own error is many lines, and a log it cannot
    write fails only after the result set replaced the old one)."""
    options = tmp_path / "options.txt"
    options.write_text("-ksp_type cg\n")
    check_petsc_files(["-options_file", str(options), "-log_view", f":{tmp_path / 'log.txt'}", "-log_view",
                       "-memory_view", "-ksp_view", "ascii:x.txt"])  # all fine: a value is a path only there
    for given, message in [(["-options_file", str(tmp_path / "none")], "file of -options_file not found"),
                           (["-options_file_yaml", str(tmp_path)], "cannot read file of -options_file_yaml"),
                           (["-log_view", f":{tmp_path / 'no' / 'log.txt'}"], "no writable folder"),
                           (["-log_view", f"ascii:{tmp_path}:ascii_info"], "is a directory")]:
        with pytest.raises(UsageError, match=message) as caught:
            check_petsc_files(given)
        assert caught.value.collective


def _pml(options: list[str]) -> str | None:
    """The pml ``options`` name with ``--mca pml``, or None."""
    return next((options[i + 2] for i in range(len(options) - 2) if options[i:i + 2] == ["--mca", "pml"]), None)


def test_a_one_host_launch_names_the_shared_memory_layer():
    open_mpi = "mpiexec (OpenRTE) 4.1.4"
    assert _pml(launcher_options(open_mpi, {})) == "ob1"
    assert _pml(launcher_options(open_mpi, {"OMPI_MCA_pml": "ucx"})) is None  # the user's choice stands
    for name in ALLOCATION_VARIABLES:  # in a batch allocation the ranks may span hosts: the network decides
        assert _pml(launcher_options(open_mpi, {name: "1"})) is None
    assert launcher_options("HYDRA build details: Version: 4.0", {}) == []  # MPICH's options differ


def test_the_rank_and_the_leaders_are_known_before_mpi_starts():
    assert world_position({}) == (0, 1)
    assert world_position({"OMPI_COMM_WORLD_RANK": "3", "OMPI_COMM_WORLD_SIZE": "8"}) == (3, 8)
    assert world_position({"PMI_RANK": "1", "PMI_SIZE": "2"}) == (1, 2)
    assert [leader(1, size) for size in (1, 2, 4, 8, 12)] == [0, 1, 1, 2, 3]  # u⁺: block 1
    assert [leader(3, size) for size in (1, 2, 4, 8)] == [0, 1, 3, 6]


def test_work_a_child_did_while_the_rank_started_counts_as_start_up():
    from ddsolve.parallel.phases import Phases

    phases = Phases()
    sum(range(200_000))  # some CPU seconds of "meshing"
    phases.end("meshing")
    before = dict(phases.cpu)
    phases.move_cpu(0.5 * before["meshing"], "meshing", "startup")
    assert phases.cpu["meshing"] == pytest.approx(0.5 * before["meshing"])
    assert phases.cpu["startup"] + phases.cpu["meshing"] == pytest.approx(before["startup"] + before["meshing"])
    phases.move_cpu(10.0, "meshing", "startup")  # never more than the phase had
    assert phases.cpu["meshing"] == 0.0
