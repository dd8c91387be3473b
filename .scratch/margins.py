import numpy as np
from app import config
from app.workflows import reduced as wr
from app.reduced import onset as ro
from app.reduced.section import Section
from app.reduced.solve import compute
orig = ro.interpolated_root
calls = []
def spy(ts, m):
    r = orig(ts, m)
    calls.append((list(ts), list(m), r))
    return r
ro.interpolated_root = spy
cfg = config.load("configs/bilayer.toml")
lev = compute(Section.from_config(cfg), wr.settings(cfg))
c = lev.onset()
print("onset", repr(c.time), repr(c.growth), c.n)
for ts, m, r in calls:
    if abs(r - c.time) < 1e-12:
        print([repr(x) for x in ts]); print([repr(x) for x in m]); print(repr(r))
