"""A problem's dofs keyed independently of the mesh's partition: displacement dofs by their input node,
flux dofs by their facet's input vertices (with the sign of the facet's canonical normal), so a state stored
from any number of ranks is put back on any other (app.io.checkpoint)."""

from __future__ import annotations

import numpy as np

from app import fem_utils
from app.geometry import dofmaps

KEY_BASE = 1 << 31  # a facet's key: lo * KEY_BASE + hi (input node indices < 2^31)
KEY_BASE_3D = 1 << 21  # in 3D: (a * KEY_BASE_3D + b) * KEY_BASE_3D + c (input node indices < 2^21)


class LayoutMismatch(RuntimeError):
    """Stored keys that the rebuilt mesh does not have (raised on every rank alike)."""


class DofLayout:
    """The keys of a problem's local dofs (owned + ghost) and the moves between its local arrays and the
    stored, key-ordered ones (gathered to rank 0, scattered back)."""

    def __init__(self, problem):
        self.comm = problem.comm
        error = None
        try:
            self._build(problem)
        except RuntimeError as err:  # raised on every rank, so none waits in a collective
            error = str(err)
        errors = [e for e in self.comm.allgather(error) if e]
        if errors:
            raise RuntimeError(f"checkpoint layout: {errors[0]}")

    def _build(self, problem):
        p = problem
        orig = np.asarray(p.domain.geometry.input_global_indices, dtype=np.int64)
        self.dim = p.domain.geometry.dim
        limit = KEY_BASE if self.dim == 2 else KEY_BASE_3D
        if orig.size and orig.max() >= limit:
            raise RuntimeError(f"input node index {orig.max()} >= {limit}: facet keys would overflow")
        X = fem_utils.node_coordinates(p.domain)
        nodes = dofmaps.lagrange1_dof_nodes(p.V_u)  # per local displacement block
        self.u_key, self.u_x = orig[nodes], X[nodes]
        ends = dofmaps.facet_nodes(p.domain)[dofmaps.facet_of_dofs(p.V_q)]  # (n_q, 2 or 4) geometry nodes
        ends = np.take_along_axis(ends, np.argsort(orig[ends], axis=1), axis=1)  # by input index
        if self.dim == 2:
            lo, hi = ends[:, 0], ends[:, 1]
            self.q_key = orig[lo] * KEY_BASE + orig[hi]
            t = X[hi] - X[lo]
            canonical = np.column_stack([t[:, 1], -t[:, 0]])
        else:
            a, b, c = ends[:, 0], ends[:, 1], ends[:, 2]
            self.q_key = (orig[a] * KEY_BASE_3D + orig[b]) * KEY_BASE_3D + orig[c]
            canonical = np.cross(X[b] - X[a], X[c] - X[a])
        n_dof = dofmaps.facet_dof_normals(p.V_q)
        dot = np.einsum("ij,ij->i", n_dof, canonical)
        if (np.abs(dot) < 0.5 * np.linalg.norm(n_dof, axis=1) * np.linalg.norm(canonical, axis=1)).any():
            raise RuntimeError("a flux dof's normal is not along its facet's normal")
        self.q_sign = np.sign(dot)
        self.nu = p.V_u.dofmap.index_map.size_local  # owned displacement blocks (the first ones)
        self.nq = p.V_q.dofmap.index_map.size_local
        self.u_dofs, self.q_dofs = p.u_dofs, p.q_dofs
        self.n_w = p.state.x.array.size
        self._order = None  # rank 0: the permutation of the gathered owned dofs into key order
        self._keys = None  # rank 0: (u_key, x, q_key) in key order, once gathered
        self._gathered = False
        self._where = None  # rank 0: per rank, the stored positions of its local dofs

    # local arrays -> owned canonical parts
    def u_part(self, u_unrolled: np.ndarray) -> np.ndarray:
        return np.asarray(u_unrolled).reshape(-1, self.dim)[: self.nu]

    def q_part(self, q: np.ndarray) -> np.ndarray:
        return (np.asarray(q) * self.q_sign)[: self.nq]

    def mixed_parts(self, w: np.ndarray):
        return self.u_part(w[self.u_dofs]), self.q_part(w[self.q_dofs])

    def mixed(self, u: np.ndarray, q_canonical: np.ndarray) -> np.ndarray:
        """A local mixed-space array from local (owned + ghost) displacement blocks and canonical fluxes."""
        w = np.zeros(self.n_w)
        w[self.u_dofs] = u.ravel()
        w[self.q_dofs] = q_canonical * self.q_sign
        return w

    # gathering (writing)
    def keys(self):
        """Collective (the first time): on rank 0 (u_key, x, q_key) in key order, else None."""
        if not self._gathered:
            self._keys = self._gather_keys()
            self._gathered = True
        return self._keys

    def _gather_keys(self):
        parts = self.comm.gather((self.u_key[: self.nu], self.u_x[: self.nu], self.q_key[: self.nq]), root=0)
        keys, error = None, None
        if self.comm.rank == 0:
            uk = np.concatenate([p[0] for p in parts])
            qk = np.concatenate([p[2] for p in parts])
            ou, oq = np.argsort(uk, kind="stable"), np.argsort(qk, kind="stable")
            for k, o, what in ((uk, ou, "node"), (qk, oq, "facet")):
                if k.size > 1 and not (np.diff(k[o]) > 0).all():
                    error = f"checkpoint layout: two owned dofs with one {what} key"
            self._order = {"u": ou, "q": oq}
            keys = uk[ou], np.concatenate([p[1] for p in parts])[ou], qk[oq]
        error = self.comm.bcast(error, root=0)
        if error:
            raise RuntimeError(error)
        return keys

    def gather(self, kind: str, owned: np.ndarray):
        """Collective: the owned values of every rank in key order on rank 0 (``keys()`` first), else None."""
        parts = self.comm.gather(np.ascontiguousarray(owned), root=0)
        if self.comm.rank != 0:
            return None
        return np.concatenate(parts)[self._order[kind]]

    # scattering (restoring)
    def locate(self, stored) -> None:
        """Collective: match every rank's local dofs with the stored keys ((u_key, x, q_key) on rank 0);
        a :class:`LayoutMismatch` on every rank if the meshes differ."""
        parts = self.comm.gather((self.u_key, self.u_x, self.q_key), root=0)
        problem = None
        if self.comm.rank == 0:
            uk, x, qk = stored
            scale = max(1.0, float(np.abs(x).max(initial=0.0)))
            self._where = []
            for ku, xu, kq in parts:
                pu = np.minimum(np.searchsorted(uk, ku), max(uk.size - 1, 0))
                pq = np.minimum(np.searchsorted(qk, kq), max(qk.size - 1, 0))
                if uk.size == 0 or (uk[pu] != ku).any() or qk.size == 0 or (qk[pq] != kq).any():
                    problem = "its mesh has nodes or facets the rebuilt mesh lacks"
                    break
                dx = float(np.abs(x[pu] - xu).max(initial=0.0))
                if dx > 1e-9 * scale:
                    problem = f"a node of the rebuilt mesh is {dx:.3g} mm away from the checkpoint's"
                    break
                self._where.append({"u": pu, "q": pq})
        problem = self.comm.bcast(problem, root=0)
        if problem:
            raise LayoutMismatch(f"the checkpoint does not fit the mesh this config builds: {problem} "
                                 "(a changed mesh file or gmsh version?)")

    def scatter(self, kind: str, stored) -> np.ndarray:
        """Collective: this rank's local values of a stored array (given on rank 0)."""
        chunks = [stored[w[kind]] for w in self._where] if self.comm.rank == 0 else None
        return self.comm.scatter(chunks, root=0)
