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


def run_to_end(cfg: dict, comm):
    """Integrate a config to time.end without the stability test: (problem, stepper, records)."""
    from app.problem import Problem
    from app.stepping import TimeStepper

    p = Problem(cfg, comm)
    st = TimeStepper(p, cfg)
    rows = [st.initial_record()]
    while not st.done():
        rows.append(st.advance())
    st.solver.destroy()
    return p, st, rows
