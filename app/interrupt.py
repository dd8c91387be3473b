"""SIGINT / SIGTERM during a run (Ctrl-C, a cluster's wall-time limit): the handler only records the
signal; the run loop asks :meth:`Watch.requested` after every step, collectively (an allreduce), so all
ranks leave the loop after the same step and none waits in a collective the others have left. A second
signal of the same kind while the first is handled acts as without hydrobuckle (ends the process at once).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}  # 128 + signal number, as a shell reports it

_received = 0  # the signal this process received and has not yet agreed on (0: none)
agreed = 0  # the signal the ranks agreed on in the last check that found one (0: none); read by the CLI


def reset() -> None:
    """Forget a signal already handled: a process that goes on after an interrupted run (a Python script or
    a notebook calling :mod:`app.api` again) starts its next run without it."""
    global _received, agreed
    _received = agreed = 0


def _handler(signum, frame) -> None:
    global _received
    _received = max(_received, signum)
    signal.signal(signum, signal.SIG_DFL)  # a second signal ends the process as usual
    if "OMPI_COMM_WORLD_SIZE" in os.environ:
        # Under mpirun the signal means the job is being torn down: Open MPI no longer reads the ranks'
        # output, and a rank blocked writing a progress line (the write this signal interrupted is
        # retried) would hold the others in the next collective until all are killed. The output goes
        # to /dev/null from here on; summary.json says what happened.
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os.close(null)


class Watch:
    """Context manager: installs the handlers (main thread only) and restores the previous ones."""

    def __init__(self, comm):
        self.comm = comm
        self._old = {}

    def __enter__(self) -> Watch:
        return self.arm()

    def arm(self) -> Watch:
        """(Re)install the handlers: gmsh.initialize/finalize reset SIGINT's, so a run re-arms after meshing."""
        if threading.current_thread() is threading.main_thread():
            for sig in EXIT_CODES:
                old = signal.signal(sig, _handler)
                self._old.setdefault(sig, old)
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()

    def requested(self) -> int:
        """Collective: the signal any rank received (SIGTERM before SIGINT), or 0."""
        return pending(self.comm)


def pending(comm) -> int:
    """Collective over ``comm``: the signal any of its ranks received (SIGTERM before SIGINT), or 0. A
    signal stays received after the run it stopped, so ``study``/``sweep`` ask before each case."""
    global agreed
    sig = comm.allreduce(_received, op=_max())
    if sig:
        agreed = sig
    return sig


def _max():
    from mpi4py import MPI

    return MPI.MAX


def name(sig: int) -> str:
    return signal.Signals(sig).name


def exit_code() -> int | None:
    """The exit code of an interrupted command (130 SIGINT, 143 SIGTERM), or None."""
    return EXIT_CODES.get(agreed) if agreed else None


# How long rank 0 waits, once the ranks agreed on a non-zero code, before it ends with it; and how long a
# rank waits for the others to reach the end before it ends as it would have without them.
LEAVE_DELAY = 0.5
LEAVE_TIMEOUT = 60.0
job_code = None  # the job's code from leave(): the agreed one, else (serial, no agreement) this process's


def leave(code: int) -> int:
    """The exit code this process ends with, in a job of several ranks: every command's last step.

    Open MPI 5's launcher (Debian 13) tears the job down as soon as one process exits with a non-zero
    code, killing ranks that are still writing (measured under load: a bad config on 2 ranks printed
    ``PMIX ERROR: PMIX_ERR_UNREACH`` from a rank killed inside MPI_Finalize in 5 of 6 runs). So the ranks
    first agree on the job's code (the largest of their codes, by a non-blocking allreduce: nobody ends
    before everybody has finished writing); if it is non-zero, all finalize PETSc and MPI together, the
    other ranks end 0 and rank 0 ends with it LEAVE_DELAY after MPI_Finalize, so theirs are not the first
    non-zero exit (:func:`_end_finalized`; a process holding abandoned HDF5 files ends in
    :func:`end_process` instead). ``mpirun`` reports the first non-zero code, ``srun`` the largest. A
    rank that does not hear from all others within LEAVE_TIMEOUT (another rank died, or is stuck in a
    collective this one left) ends with its own code, as without this step. Serial runs are unchanged."""
    global job_code
    job_code = code
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is None or not mpi.Is_initialized() or mpi.Is_finalized():
        return code
    comm = mpi.COMM_WORLD
    if comm.size == 1:
        return code
    _flush()
    import numpy as np

    mine, job = np.array([code], dtype=np.int64), np.zeros(1, dtype=np.int64)
    request = comm.Iallreduce(mine, job, op=mpi.MAX)
    deadline = time.monotonic() + LEAVE_TIMEOUT
    while not request.Test():
        if time.monotonic() > deadline:
            return code
        time.sleep(0.005)
    worst = job_code = int(job[0])
    if worst == 0:
        return 0
    if _files_held_open:
        return 0 if comm.rank else worst  # end_process ends the process without MPI_Finalize
    _end_finalized(worst if comm.rank == 0 else 0, delay=LEAVE_DELAY if comm.rank == 0 else 0.0)


def _end_finalized(code: int, delay: float) -> None:
    """End this process with ``code``: PETSc and MPI finalized here (MPI_Finalize is collective: every rank
    calls this at the same point), then ``delay`` seconds, then exit at once (no destructor may call PETSc
    or MPI after their finalize). Only a wait after MPI_Finalize orders the exits: a wait before it is
    spent in MPI_Finalize's own fence by the others, which then leave with rank 0 (measured on Open MPI 5
    with 3 busy processes on 2 cores, a 2-rank job whose rank 0 ends 143 0.5 s after rank 1 ends 0: PMIx
    error in 4 of 50 runs with the wait before MPI_Finalize, 0 of 50 with it after)."""
    _flush()
    petsc = sys.modules.get("petsc4py.PETSc")
    if petsc is not None:
        petsc._finalize()
    from mpi4py import MPI

    if not MPI.Is_finalized():  # PetscFinalize finalizes MPI too when PETSc initialized it
        MPI.Finalize()
    time.sleep(delay)
    os._exit(code)


def _flush() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass


_files_held_open = False  # an HDF5 file that must never be closed (app.io.hdf5.abandon): end_process


def hold_files_open() -> None:
    global _files_held_open
    _files_held_open = True


def finish(code: int, process: bool) -> int:
    """A command's exit code: 130 / 143 after SIGINT / SIGTERM, else ``code``. ``process``: the command runs
    as the process itself, so the ranks agree on the code (:func:`leave`) and a process that holds an HDF5
    file open for good ends here (:func:`end_process`)."""
    code = exit_code() or code
    if process:
        code = leave(code)
        if _files_held_open:
            end_process(job_code)
    return code


def end_process(code: int) -> None:
    """End a process that holds abandoned HDF5 files with the job's (non-zero) ``code``, agreed by the ranks
    (:func:`leave`): output flushed, then exit at once. Neither destructors nor MPI_Finalize run:
    HDF5 closes its open files when MPI is finalized, and that close hung (measured: 1 of 3 attempts on
    2 ranks). Rank 0 ends first and the launcher then ends the others: Open MPI 5 reports a rank that
    ends 0 without MPI_Finalize as an improper exit (code 1), and two ranks ending non-zero at once made
    it print a PMIx error; the other ranks end by themselves only if nothing ends them within 10 s."""
    from mpi4py import MPI

    _flush()
    if MPI.Is_initialized() and not MPI.Is_finalized() and MPI.COMM_WORLD.rank != 0:
        time.sleep(10.0)
    os._exit(code)
