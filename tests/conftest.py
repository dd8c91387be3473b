"""MPI-aware pytest fixtures: one shared tmp dir per test across ranks, collective clean-up."""

from __future__ import annotations

import gc
import logging
from pathlib import Path

import pytest
from mpi4py import MPI

from app import config, logging_setup


@pytest.fixture(autouse=True)
def _collective_cleanup():
    """Keep collective destructors of PETSc/dolfinx objects in step across ranks."""
    yield
    gc.collect()
    MPI.COMM_WORLD.barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD


@pytest.fixture
def shared_tmp(tmp_path_factory) -> Path:
    """A temporary directory that is the same path on every rank."""
    comm = MPI.COMM_WORLD
    path = str(tmp_path_factory.mktemp("hb")) if comm.rank == 0 else None
    return Path(comm.bcast(path, root=0))


@pytest.fixture(scope="session", autouse=True)
def _quiet_logging():
    logging_setup.setup(MPI.COMM_WORLD, logging.WARNING)


def small_bilayer(**overrides) -> dict:
    """A small, fast bilayer config (0.1 mm wide, 0.05 mm substrate); dotted-key overrides."""
    user = {
        "geometry": {"length": 0.1, "substrate_thickness": 0.05, "film_thickness": 0.01},
        "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.3},
        "time": {"end": 0.3, "dt_initial": 0.01, "dt_max": 0.1},
        "output": {"fields": False, "plot": False},
    }
    return config.resolve(user, [f"{k}={v}" for k, v in overrides.items()])


def time_stepper(problem, cfg: dict):
    """A TimeStepper with the [time] and [solver] settings of a resolved config."""
    from app.solvers.stepping import TimeStepper
    from app.workflows.run import RunSettings

    settings = RunSettings.from_config(cfg)
    return TimeStepper(problem, settings.time, settings.solver)


def run_to_end(cfg: dict, comm):
    """Integrate a config to time.end without the stability test: (problem, stepper, records)."""
    from app.model.problem import Problem

    p = Problem.from_config(cfg, comm)
    st = time_stepper(p, cfg)
    rows = [st.initial_record()]
    while not st.done():
        rows.append(st.advance())
    st.destroy()
    return p, st, rows


REPO = Path(__file__).resolve().parents[1]


def child_env() -> dict:
    """The environment for a child process that starts its own MPI job (mpirun or a singleton):
    the parent's Open MPI/PMIx variables removed, so a test running under ``mpirun -n 2`` can
    launch one too."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_", "PRTE_"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    return env


def on_rank0(fn, *args, **kwargs):
    """Call ``fn`` on rank 0 only and return its result on every rank (its exception is re-raised
    on every rank). The other ranks wait without spinning, so a child MPI job started by ``fn``
    gets the cores."""
    import time

    comm = MPI.COMM_WORLD
    if comm.size == 1:
        return fn(*args, **kwargs)
    if comm.rank == 0:
        try:
            payload = (True, fn(*args, **kwargs))
        except BaseException as err:  # noqa: B036 - handed to the other ranks, then re-raised
            payload = (False, err)
        for r in range(1, comm.size):
            comm.send(payload, dest=r, tag=77)
    else:
        while not comm.iprobe(source=0, tag=77):  # wait without spinning in MPI
            time.sleep(0.05)
        payload = comm.recv(source=0, tag=77)  # any size (irecv's default buffer is 32 kB)
    ok, value = payload
    if not ok:
        raise value
    return value
