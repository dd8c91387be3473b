#!/usr/bin/env bash
# Open a run's fields.xdmf and mode.xdmf in the real ParaView (pvbatch under xvfb) as a user would,
# check that each is ONE dataset with every field, color by fluid content, warp by displacement (and
# the mode by a visible scale factor) and save screenshots. Optional, not in .ci/run.
#   bash scripts/paraview-check.sh [RESULT_DIR] [OUT_DIR]
# RESULT_DIR defaults to results/bilayer (run `bash scripts/demo.sh` first, or it runs it);
# screenshots go to OUT_DIR (default RESULT_DIR): paraview-fields.png, paraview-mode.png.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
results="${1:-$here/results/bilayer}"
outdir="${2:-$results}"
if ! command -v pvbatch >/dev/null || ! command -v xvfb-run >/dev/null; then
  echo "paraview-check: apt-get installing paraview, python3-paraview, xvfb"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends paraview python3-paraview xvfb xauth
fi
if [ ! -f "$results/summary.json" ]; then
  bash "$here/scripts/demo.sh" -o "$results"
fi
mkdir -p "$outdir"
script="$(mktemp --suffix=.py)"
trap 'rm -f "$script"' EXIT
cat >"$script" <<'PY'
import json
import sys

from paraview import servermanager
from paraview.simple import (ColorBy, CreateView, GetAnimationScene, GetColorTransferFunction, Render,
                             SaveScreenshot, Show, WarpByVector, XDMFReader)

results, outdir = sys.argv[1], sys.argv[2]
summary = json.load(open(f"{results}/summary.json"))
crit = summary.get("critical") or {}
cfg = summary["config"]
film = cfg["geometry"].get("film_thickness") or 0.01


def open_one(path, arrays):
    reader = XDMFReader(FileNames=[path])
    reader.UpdatePipelineInformation()
    times = list(reader.TimestepValues) if hasattr(reader.TimestepValues, "__len__") else [reader.TimestepValues]
    reader.UpdatePipeline(times[-1])
    data = servermanager.Fetch(reader)
    kind = data.GetClassName()
    if kind != "vtkUnstructuredGrid":
        sys.exit(f"paraview-check: FAIL {path} opens as {kind}, not one dataset")
    names = {data.GetPointData().GetArrayName(i) for i in range(data.GetPointData().GetNumberOfArrays())}
    names |= {data.GetCellData().GetArrayName(i) for i in range(data.GetCellData().GetNumberOfArrays())}
    missing = [a for a in arrays if a not in names]
    if missing:
        sys.exit(f"paraview-check: FAIL {path} lacks {missing} (has {sorted(names)})")
    print(f"paraview-check: {path}: one {kind}, {data.GetNumberOfCells()} cells, {len(times)} time step(s), "
          f"arrays {sorted(names)}")
    return reader, times, data


def film_camera(view, data, band):
    """Look at the film region: the left end of the top band, 5 band heights wide; a 3D body from above and
    aside (an isometric view of the whole of it)."""
    x0, x1, y0, y1, z0, z1 = data.GetBounds()
    if z1 - z0 > 1e-12:
        Render(view)
        cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
        size = max(x1 - x0, y1 - y0, z1 - z0)
        view.CameraPosition = [cx + 1.6 * size, cy + 1.4 * size, cz + 2.0 * size]
        view.CameraFocalPoint = [cx, cy, cz]
        view.CameraViewUp = [0, 1, 0]
        view.CameraParallelProjection = 0
        view.ResetCamera()
        Render(view)
        return
    width = min(x1 - x0, 5 * band)
    cx, cy = x0 + width / 2, y1 - band / 2
    Render(view)  # the first render resets the camera: place it afterwards
    view.CameraPosition = [cx, cy, 10 * width]
    view.CameraFocalPoint = [cx, cy, 0]
    view.CameraViewUp = [0, 1, 0]
    view.CameraParallelProjection = 1
    view.CameraParallelScale = 0.5 * width * 500 / 1400
    Render(view)


def new_view():
    view = CreateView("RenderView")
    view.ViewSize = [1400, 500]
    view.OrientationAxesVisibility = 0
    return view


fields = ["displacement", "fluid_content", "chemical_potential", "J", "flux", "stress_xx", "stress_min_principal"]
reader, times, data = open_one(f"{results}/fields.xdmf", fields)
scene = GetAnimationScene()
scene.UpdateAnimationUsingDataTimeSteps()
scene.AnimationTime = times[-1]
view = new_view()
warp = WarpByVector(Input=reader, Vectors=["POINTS", "displacement"], ScaleFactor=1.0)
display = Show(warp, view)
ColorBy(display, ("CELLS", "fluid_content"))
lut = GetColorTransferFunction("fluid_content")
lo, hi = warp.CellData["fluid_content"].GetRange()
if not (hi > lo):
    sys.exit("paraview-check: FAIL fluid_content has no range")
lut.RescaleTransferFunction(lo, hi)
display.SetScalarBarVisibility(view, True)
film_camera(view, data, 8 * film)
SaveScreenshot(f"{outdir}/paraview-fields.png", view, ImageResolution=[1400, 500])
print(f"paraview-check: fields at t = {times[-1]:.6g} s, fluid_content {lo:.4g}..{hi:.4g} -> {outdir}/paraview-fields.png")

reader2, _, data2 = open_one(f"{results}/mode.xdmf", ["critical_displacement", "mode"])
view2 = new_view()
base = WarpByVector(Input=reader2, Vectors=["POINTS", "critical_displacement"], ScaleFactor=1.0)
scale = 0.5 * film  # the mode is normalized to max |u| = 1 mm: wrinkles of half a film thickness
wrinkled = WarpByVector(Input=base, Vectors=["POINTS", "mode"], ScaleFactor=scale)
d2 = Show(wrinkled, view2)
ColorBy(d2, ("POINTS", "mode", "Magnitude"))
d2.SetScalarBarVisibility(view2, True)
film_camera(view2, data2, 8 * film)
SaveScreenshot(f"{outdir}/paraview-mode.png", view2, ImageResolution=[1400, 500])
print(f"paraview-check: mode at t_c = {crit.get('time', float('nan')):.6g} s (N_c = {crit.get('wrinkle_count')}), "
      f"warped x {scale:g} -> {outdir}/paraview-mode.png")
PY
xvfb-run -a pvbatch "$script" "$results" "$outdir"
