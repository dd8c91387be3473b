"""Rank-0 logging for hydrobuckle; silences the JIT compiler's INFO chatter."""

from __future__ import annotations

import logging
import sys

LOGGER_NAME = "hydrobuckle"


def setup(comm, level: int = logging.INFO, root: bool = True) -> logging.Logger:
    """hydrobuckle's logger: its lines on rank 0 at ``level``, nothing on the other ranks. ``root``: also
    take over the root logger (the command line); the Python API leaves the caller's logging as it is."""
    if root:
        # The JIT's build step (setuptools) lowers the root logger's level to INFO and would call
        # basicConfig; a root handler of our own, filtering at WARNING, keeps its chatter out.
        root_logger = logging.getLogger()
        root_logger.setLevel(logging.WARNING)
        handler = logging.StreamHandler(sys.stderr)
        handler.setLevel(logging.WARNING)
        handler.setFormatter(logging.Formatter("%(levelname)s:%(name)s: %(message)s"))
        root_logger.handlers = [handler]
    for noisy in ("FFCx", "UFL", "ffcx", "dolfinx"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    log = logging.getLogger(LOGGER_NAME)
    log.handlers.clear()
    log.propagate = False
    if comm.rank == 0:
        handler = logging.StreamHandler(sys.stdout)
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
        log.setLevel(level)
    else:
        log.addHandler(logging.NullHandler())
        log.setLevel(logging.CRITICAL + 1)
    return log


def get() -> logging.Logger:
    return logging.getLogger(LOGGER_NAME)
