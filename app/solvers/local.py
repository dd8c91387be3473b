"""Small systems on a rank-local mesh (a 1D cross-section, a row of surface points): a residual form and its
matrix form assembled into NumPy arrays for SciPy's banded and sparse solvers."""

from __future__ import annotations

import numpy as np
from dolfinx.fem import petsc as fem_petsc

from app import fem_utils


class LocalSystem:
    """``assemble()``: the residual as an array and the matrix in CSR (indptr, indices, values) at the forms'
    current coefficients; the matrix's pattern is created once and kept."""

    def __init__(self, residual, matrix):
        self.residual, self.matrix = residual, matrix
        self._A = None

    def assemble(self) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        b = fem_utils.assemble_vector(self.residual)
        r = b.array.copy()
        b.destroy()
        if self._A is None:
            self._A = fem_petsc.create_matrix(self.matrix)
        fem_utils.assemble_matrix_into(self._A, self.matrix, [])
        return r, self._A.getValuesCSR()

    @property
    def shape(self) -> tuple[int, int]:
        return self._A.getSize()
