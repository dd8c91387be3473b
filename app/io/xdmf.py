"""One XDMF dataset per result file: every field of an output time on one grid.

dolfinx 0.5's XDMFFile writes each function as its own temporal collection beside the mesh, which
ParaView opens as a multiblock of overlapping blocks (one per function, plus the bare mesh). The
heavy data it writes to the ``.h5`` file is fine; only the XML is rearranged here: after every write
(rank 0, written to a temporary file and renamed, so a reader never sees half a file) the ``.xdmf``
becomes a single temporal collection whose grid at each time carries the mesh and every attribute
written at that time, all pointing into the same ``.h5`` datasets.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path


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
    with open(tmp, "wb") as f:
        f.write(b'<?xml version="1.0"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
        ET.ElementTree(out).write(f, encoding="utf-8", xml_declaration=False)
        f.write(b"\n")
    os.replace(tmp, path)
    return len(steps)


class FieldSeries:
    """A temporal series of several functions on one mesh, written through dolfinx's XDMFFile and
    kept rearranged into one dataset after each output time (see :func:`rearrange`)."""

    def __init__(self, comm, path: str | Path, domain, name: str):
        from app import compat

        self.comm, self.path, self.name = comm, Path(path), name
        self._file = compat.xdmf_writer(comm, str(self.path))
        self._file.write_mesh(domain)

    def write(self, functions, t: float) -> None:
        for f in functions:
            self._file.write_function(f, t)
        self._rearrange()

    def _rearrange(self) -> None:
        if self.comm.rank == 0:
            rearrange(self.path, self.name)
        self.comm.barrier()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
            self._rearrange()  # in case closing rewrote dolfinx's own layout

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
