import sys
from pathlib import Path
from mpi4py import MPI
from app import config
from app.workflows.run import simulate
PERIOD_DOUBLING = ["stability.after_onset=branch", "stability.error_estimate=false", "mesh.element_size=0.008",
                   "mesh.film_layers=4", "time.end=1.6", "output.fields=false", "output.plot=false"]
cfg = config.load("configs/bilayer.toml", PERIOD_DOUBLING + sys.argv[2:])
simulate(cfg, Path(sys.argv[1]), MPI.COMM_SELF, progress=True)
