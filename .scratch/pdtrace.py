import sys
from pathlib import Path
from mpi4py import MPI
from app import config
from app.solvers import minimizer as mz
from app.workflows.run import simulate
PERIOD_DOUBLING = ["stability.after_onset=branch", "stability.error_estimate=false", "mesh.element_size=0.008",
                   "mesh.film_layers=4", "time.end=1.6", "output.fields=false", "output.plot=false", "time.max_steps=45"]
oj, oc, oo = mz.MinimizingNewton._jacobian, mz.MinimizingNewton._converged, mz.MinimizingNewton._objective
def jac(self, snes, x, J, P):
    oj(self, snes, x, J, P); print(f"   J: neg {self.last.negatives} sigma {self.sigma:.3e}", flush=True)
def conv(self, snes, it, norms):
    r = oc(self, snes, it, norms); print(f"   it {it} xnorm {norms[0]:.12e} dx {norms[1]:.6e} f {norms[2]:.12e} -> {r}", flush=True); return r
def obj(self, snes, x):
    e = oo(self, snes, x); print(f"   obj {e:.15e}", flush=True); return e
mz.MinimizingNewton._jacobian, mz.MinimizingNewton._converged, mz.MinimizingNewton._objective = jac, conv, obj
cfg = config.load("configs/bilayer.toml", PERIOD_DOUBLING)
simulate(cfg, Path(sys.argv[1]), MPI.COMM_SELF, progress=True)
