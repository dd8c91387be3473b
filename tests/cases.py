"""Small configs shared by several test modules (test modules never import each other)."""

from __future__ import annotations

from app import config

# A 0.3 mm wide bilayer strip that buckles within a second of swelling.
SWELLING = {
    "geometry": {"length": 0.3, "substrate_thickness": 0.15, "film_thickness": 0.01},
    "mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
    "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
    "output": {"fields": False, "plot": False},
    "reduced": {"beside_2d": False},  # tests/test_reduction.py tests the 1D counterpart
}


def swelling_case(*overrides) -> dict:
    return config.resolve(SWELLING, list(overrides))


# A small bilayered tube (R = 0.3 mm) that buckles within a second of swelling.
SMALL_TUBE = {
    "geometry": {"kind": "tube", "outer_radius": 0.3, "substrate_thickness": 0.06, "film_thickness": 0.01},
    "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.3},
    "material": {"film": {"modulus_ratio": 10.0}},
    "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
    "output": {"fields": False, "plot": False},
    "reduced": {"beside_2d": False},
}


def tube_case(*overrides, kind="tube"):
    user = {**SMALL_TUBE, "geometry": {**SMALL_TUBE["geometry"], "kind": kind}}
    return config.resolve(user, list(overrides))


# A tiny bilayer (modulus ratio 1) under a ramp with a kink at t = 2 s: about 580 steps, buckling near the
# end (about 3 s serially); a checkpoint every 10 steps. The runs the signal and write-error tests stop.
LONG = """
[geometry]
length = 0.1
substrate_thickness = 0.05
film_thickness = 0.01
[mesh]
element_size = 0.01
film_layers = 2
[time]
end = 3.0
dt_initial = 0.001
dt_max = 0.005
[material.film]
modulus_ratio = 1.0
[loading]
ramp_time = 2.0
[stability]
error_estimate = false
[output]
fields = false
plot = false
checkpoint_every = 10
[reduced]
beside_2d = false
"""


# The geometry and mesh of a 0.15 mm wide bilayer (15 x 2 film elements), as TOML: tests append their own tables.
TINY_BILAYER_TOML = """
[geometry]
length = 0.15
substrate_thickness = 0.15
film_thickness = 0.01
[mesh]
element_size = 0.01
film_layers = 2
substrate_grading = 1.25
[reduced]
beside_2d = false
"""


# A 0.3 mm wide bilayer strip that buckles within seconds (60 x 2 film elements), as TOML: tests append their
# own tables.
BUCKLING_STRIP_TOML = """
[geometry]
length = 0.3
substrate_thickness = 0.15
[mesh]
element_size = 0.005
film_layers = 2
substrate_grading = 1.25
"""


# conftest.small_bilayer's geometry and mesh as a file, with the error estimate and a coarse 1D counterpart
# beside it (tests/test_api.py compares the API with the CLI on it, not the answer's accuracy).
API_BILAYER_TOML = """
[geometry]
length = 0.1
substrate_thickness = 0.05
film_thickness = 0.01
[mesh]
element_size = 0.01
film_layers = 2
substrate_grading = 1.3
[material.film]
modulus_ratio = 8.0
[time]
end = 2.0
dt_initial = 0.01
dt_max = 0.1
[stability]
error_estimate = true
[reduced]   # a coarse 1D reduction: these tests compare the API with the CLI, not the answer's accuracy
beside_2d = true
degree = 2
film_cells = 4
grid = 16
max_wavenumber = 5
"""
