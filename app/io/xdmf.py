"""One XDMF dataset per result file: every field of an output time on one grid.

dolfinx 0.5's XDMFFile writes each function as its own temporal collection beside the mesh, which
ParaView opens as a multiblock of overlapping blocks (one per function, plus the bare mesh). The
heavy data it writes to the ``.h5`` file is fine; only the XML is rearranged here: after every write
(rank 0, written to a temporary file and renamed, so a reader never sees half a file) the ``.xdmf``
becomes a single temporal collection whose grid at each time carries the mesh and every attribute
written at that time, all pointing into the same ``.h5`` datasets.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from dolfinx.io import XDMFFile

from app.io import hdf5, writes


def rearrange(path: str | Path, name: str) -> int:
    """Rewrite the dolfinx XDMF file ``path`` as one temporal collection named ``name``; returns the
    number of time steps. Idempotent: a file already rearranged is rewritten unchanged."""
    path = Path(path)
    root = ET.parse(path).getroot()
    domain = root.find("Domain")
    mesh = next((g for g in domain.findall("Grid") if g.get("GridType") == "Uniform"), None)
    collections = [g for g in domain.findall("Grid") if g.get("GridType") == "Collection"]
    steps: dict[str, list] = {}  # time value -> attributes, in writing order
    shared = {}
    for coll in collections:
        for grid in coll.findall("Grid"):
            time = grid.find("Time")
            key = time.get("Value") if time is not None else "0"
            steps.setdefault(key, []).extend(grid.findall("Attribute"))
            for tag in ("Topology", "Geometry"):  # present in an already rearranged file
                if grid.find(tag) is not None:
                    shared.setdefault(tag, grid.find(tag))
    if mesh is not None:
        shared = {tag: mesh.find(tag) for tag in ("Topology", "Geometry")}
    out = ET.Element("Xdmf", {"Version": "3.0"})
    dom = ET.SubElement(out, "Domain")
    series = ET.SubElement(dom, "Grid", {"Name": name, "GridType": "Collection", "CollectionType": "Temporal"})
    for value, attributes in steps.items():
        grid = ET.SubElement(series, "Grid", {"Name": name, "GridType": "Uniform"})
        for tag in ("Topology", "Geometry"):
            grid.append(shared[tag])
        ET.SubElement(grid, "Time", {"Value": value})
        seen = set()
        for a in attributes:
            if a.get("Name") not in seen:
                seen.add(a.get("Name"))
                grid.append(a)
    ET.indent(out, "  ")
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(b'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
            ET.ElementTree(out).write(f, encoding="utf-8", xml_declaration=False)
            f.write(b"\n")
        writes.commit(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)  # the file as it was (a full disk: no partial copy left)
        raise
    return len(steps)


def mesh_bytes(domain) -> int:
    """About the bytes XDMFFile.write_mesh puts into the .h5: node coordinates (3 x float64) and the
    cells' node lists (int64)."""
    nodes = domain.geometry.index_map().size_global
    tdim = domain.topology.dim
    cells = domain.topology.index_map(tdim).size_global
    return 8 * (3 * nodes + domain.ufl_cell().num_vertices() * cells)


def function_bytes(f) -> int:
    """About the bytes XDMFFile.write_function puts into the .h5 for ``f``: its global values as float64,
    a 2D vector padded to 3 components."""
    im = f.function_space.dofmap.index_map
    bs = f.function_space.dofmap.index_map_bs
    return 8 * im.size_global * (3 if bs == 2 else bs)


def ballast_path(path: str | Path) -> Path:
    """The hidden file that keeps space aside for the close of the XDMF file ``path`` while it is open."""
    path = Path(path)
    return path.with_name(f".{path.name}.reserve")


class FieldSeries:
    """A temporal series of several functions on one mesh, written through dolfinx's XDMFFile and
    kept rearranged into one dataset after each output time (see :func:`rearrange`).

    Every write is collective and either succeeds on every rank or raises the same
    :class:`~app.io.writes.ResultWriteError` on every rank (naming the .h5 file, or the .xdmf file for
    its XML): rank 0 first reserves the bytes the write needs (:func:`app.io.writes.reserve`), so a full
    disk stops it before any rank enters HDF5; an HDF5 failure all the same is agreed on by every rank,
    and the file is then abandoned, never closed (:func:`app.io.hdf5.abandon`)."""

    BALLAST = 64 * 1024  # kept aside for the close, which writes HDF5's last metadata (measured: 4 kB)

    def __init__(self, comm, path: str | Path, domain, name: str):
        self.comm, self.path, self.name = comm, Path(path), name
        self.h5 = self.path.with_suffix(".h5")
        self.ballast = ballast_path(self.path)
        self._file = None
        self._grown = 0  # rank 0: the .h5's growth in the last write (a measured size for the next)

        def create():
            self._file = XDMFFile(comm, str(self.path), "w")

        try:
            self._collective([create, lambda: self._file.write_mesh(domain)], mesh_bytes(domain))
        except Exception:

            writes.release(comm, self.ballast)
            raise

    def _need(self, data_bytes: int) -> int | None:
        """Rank 0: the bytes to reserve for a write of ``data_bytes`` of data (None elsewhere): the larger
        of that and the last write's growth, a quarter more (HDF5's object headers), and the XML twice
        (dolfinx rewrites it, then :func:`rearrange` writes it aside)."""
        if self.comm.rank != 0:
            return None
        xml = self.path.stat().st_size if self.path.is_file() else 0
        return int(1.25 * max(data_bytes, self._grown)) + 2 * xml + 8192

    def _collective(self, actions, data_bytes: int | None) -> None:
        """Run the HDF5 ``actions`` on every rank, after reserving their space (unless ``data_bytes`` is
        None), and agree on the outcome of each before the next: a rank that failed must not leave the
        others inside the next one's collectives (measured: a hang when they agreed only after all)."""
        size0 = self.h5.stat().st_size if self.comm.rank == 0 and self.h5.is_file() else 0
        if data_bytes is not None:
            writes.reserve(self.comm, self.path.parent, self._need(data_bytes), self.h5, self.ballast,
                           self.BALLAST)
        for action in actions:
            local = None
            with hdf5.HDF5Errors() as errors:
                try:
                    action()
                except RuntimeError as err:
                    local = (errors.os_reason(), errors.reason(err))
            failures = self.comm.allgather(local)
            if any(failures):
                self._abandon()
                reason = None
                if self.comm.rank == 0:  # the OS's words where HDF5 recorded them, else ask the file system
                    known = [f for f in failures if f]
                    reason = (next((os_reason for os_reason, _ in known if os_reason), None)
                              or writes.space_problem(self.path.parent, self._need(data_bytes or 0))
                              or known[0][1])
                raise writes.ResultWriteError(self.h5, self.comm.bcast(reason, root=0))
        if self.comm.rank == 0 and self.h5.is_file():
            self._grown = max(0, self.h5.stat().st_size - size0)

    def _abandon(self) -> None:
        if self._file is not None:
            hdf5.abandon(self._file)
            self._file = None
        writes.release(self.comm, self.ballast)

    def write(self, functions, t: float) -> None:
        if self._file is None:
            return
        functions = list(functions)
        self._collective([lambda f=f: self._file.write_function(f, t) for f in functions],
                         sum(function_bytes(f) for f in functions))
        self._rearrange()

    def _rearrange(self) -> None:

        writes.on_rank0(self.comm, self.path, rearrange, self.path, self.name)

    def close(self) -> None:

        if self._file is not None:
            writes.release(self.comm, self.ballast)
            self._collective([self._file.close], None)
            self._file = None
            self._rearrange()  # in case closing rewrote dolfinx's own layout

    def __enter__(self):
        return self

    def __exit__(self, *exc):

        try:
            self.close()
        except writes.ResultWriteError:
            if exc[0] is None:
                raise
