"""Cost of a step in contact against a branch step without contact (docs/performance.md).

Runs a config with self-contact on (``stability.contact = true``, a followed branch) in this process,
times every accepted step (TimeStepper.advance: its attempts, cut-backs and solves, without the stability
work of the tracker), and reads history.csv to sort the steps after the first branch switch into those
whose state touches nowhere and those in contact. Prints the mean and median wall time and Newton
iterations of each and their ratio.

    python scripts/contact_cost.py OUTDIR configs/bilayer.toml --set mesh.element_size=0.008 ...
    mpirun -n 2 python scripts/contact_cost.py OUTDIR ...      (the same, on 2 ranks)
"""

import csv
import statistics
import sys
import time
from pathlib import Path

from mpi4py import MPI

from app import config
from app.solvers.stepping import TimeStepper
from app.workflows.run import simulate

AFTER_SWITCH = 3  # steps after a branch switch that leave its saddle (docs/performance.md, a branch step)


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    outdir, path, rest = Path(argv[0]), argv[1], argv[2:]
    overrides = [rest[i + 1] for i in range(len(rest)) if rest[i] == "--set"]
    cfg = config.load(path, overrides + ["stability.contact=true", "stability.after_onset=branch"])
    walls: dict[int, float] = {}
    advance = TimeStepper.advance

    def timed(self, *args, **kwargs):
        t0 = time.perf_counter()
        rec = advance(self, *args, **kwargs)
        walls[rec.step] = time.perf_counter() - t0
        return rec

    TimeStepper.advance = timed
    summary = simulate(cfg, outdir, MPI.COMM_WORLD, progress=False)
    if MPI.COMM_WORLD.rank:
        return 0
    with open(outdir / "history.csv") as f:
        rows = list(csv.DictReader(f))
    switches = summary.get("postbuckling", {}).get("switches", [])
    if not switches:
        print("contact_cost: the run never switched onto a branch", file=sys.stderr)
        return 1
    t_switch = switches[0]["time"]
    free, touching = [], []
    for r in rows:
        step = int(r["step"])
        if float(r["time"]) <= t_switch or step not in walls:
            continue
        (touching if float(r["contact_length_mm"]) > 0 else free).append((walls[step], int(r["newton_its"])))
    print(f"status {summary['status']}: {summary['message'][:160]}")
    if not free or not touching:
        print(f"contact_cost: {len(free)} branch steps without contact, {len(touching)} in contact: nothing to "
              "compare", file=sys.stderr)
        return 1
    for name, part in (("branch steps without contact", free), ("steps in contact", touching)):
        w = [x for x, _ in part]
        print(f"{name}: {len(part)}, wall mean {statistics.mean(w):.3f} s, median {statistics.median(w):.3f} s, "
              f"Newton iterations mean {statistics.mean(n for _, n in part):.1f}")
    ratio_mean = statistics.mean(x for x, _ in touching) / statistics.mean(x for x, _ in free)
    ratio_median = statistics.median(x for x, _ in touching) / statistics.median(x for x, _ in free)
    print(f"ratio in contact / without: mean {ratio_mean:.2f}, median {ratio_median:.2f}")
    # the same without the AFTER_SWITCH steps after each branch switch (a fold in contact is an instability of
    # its own: its snap is a switch's cost, not the contact term's, as for the branch steps' own ratio)
    times = sorted(sw["time"] for sw in switches)
    after: set[int] = set()
    for ts in times:
        later = [int(r["step"]) for r in rows if float(r["time"]) > ts]
        after.update(later[:AFTER_SWITCH])
    calm = {name: [walls[int(r["step"])] for r in rows if float(r["time"]) > t_switch and int(r["step"]) in walls
                   and int(r["step"]) not in after and (float(r["contact_length_mm"]) > 0) == touch]
            for name, touch in (("free", False), ("touching", True))}
    if calm["free"] and calm["touching"]:
        print(f"without the {AFTER_SWITCH} steps after each of the {len(times)} switches: "
              f"{len(calm['free'])} without contact, {len(calm['touching'])} in contact, ratio mean "
              f"{statistics.mean(calm['touching']) / statistics.mean(calm['free']):.2f}, median "
              f"{statistics.median(calm['touching']) / statistics.median(calm['free']):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
