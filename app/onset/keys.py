"""The [stability] keys of the onset tracker (app.onset.tracker.StabilitySettings); ``criterion`` and each
criterion's parameters come from the registry (app.onset.criteria.CRITERIA) and are put in by app.config."""

from __future__ import annotations

from app.schema import Key, ge, in_closed, in_open, key, matches, one_of

STABILITY: dict[str, Key] = {
    "enabled": key(bool, True, None, "test K for positive definiteness after every step"),
    "tolerance": key(float, 1.0e-3, in_open(0.0, 0.5), "relative bracket width of the onset time"),
    "stop_at_onset": key(bool, True, None, "false: continue on the unbuckled path and record later crossings "
                         "(the same as after_onset = \"fundamental\")"),
    "after_onset": key(str, None, one_of("stop", "fundamental", "branch"),
                       "what follows the onset: stop; continue on the unbuckled (fundamental) path; or follow "
                       "the buckled branch (docs/postbuckling.md). Unset: from stop_at_onset", optional=True),
    "imperfection": key(float, 0.01, in_closed(-1.0, 1.0),
                        "after_onset = branch: the mode's peak surface normal displacement added at the onset, "
                        "as a fraction of geometry.film_thickness (or mesh.element_size, or a .msh mesh's "
                        "sqrt(area/cells)); sign = direction, not 0"),
    "branch_modes": key(str, "1", matches(r"1|\d+:\d+(\+\d+:\d+)*",
                                          "matching '1' or wave vectors 'i:j' joined by '+' (e.g. '2:0+0:2'; "
                                          "3D kinds)"),
                        "after_onset = branch, 3D: what the switch adds at the onset: '1' the first eigenmode as "
                        "computed (at a multiple onset any mix of the modes crossing together), or the pure shape "
                        "of wave vector (i, j) within the modes crossing together ('2:0': stripes; '2:0+0:2' "
                        "both, squares), to follow the competing branches of a multiple onset (docs/three-d.md)"),
    "modes": key(int, 3, in_closed(1, 50), "eigenpairs reported at the onset"),
    "eigen_every": key(int, 0, ge(0), "also compute lambda_min every n steps (0 = only at the onset)"),
    "surface_check": key(bool, True, None,
                         "check the permeable surface's short-wave limit every step from the local state: "
                         "reports where and when it becomes unstable at waves below the mesh "
                         "(summary.json surface_onset, docs/reduction.md)"),
    "screening": key(str, "newton", one_of("newton", "exact"),
                     "per-step test: inertia of the Newton factor (confirmed exactly) or exact K"),
    "max_crossings": key(int, 20, ge(1), "with stop_at_onset = false: stop after this many"),
    "creases": key(bool, False, None, "also find the energetic crease onset (docs/creases.md)"),
    "crease_size": key(float, 0.05, in_open(0.0, 0.5), "the trial crease's length / the body's thickness"),
    "crease_resolution": key(int, 32, in_closed(8, 256), "elements along the trial crease (finest of 3 meshes)"),
    "crease_growth": key(bool, True, None,
                         "the free surface beyond the trial crease may fold onto the symmetry line (contact with "
                         "its mirror image, stiffness contact_stiffness) and the crease grow to its size of least "
                         "energy, followed down in load to its onset; false: held at its size (docs/creases.md)"),
    "crease_fluid": key(str, "drained", one_of("drained", "undrained", "transient"),
                        "under swelling: the creased state's fluid follows the bath (drained) or keeps the flat "
                        "state's content (undrained), both states in equilibrium with the bath; or both states hold "
                        "the run's own transient content at each time (transient: a bilayer, from its exact 1D "
                        "transient); without fluid motion it has no effect"),
    "contact": key(bool, False, None, "self-contact of the traction-free surface as a term of the energy: a followed "
                   "branch goes on past the fold into creases (docs/creases.md)"),
    "contact_energy": key(str, "auto", one_of("auto", "penalty", "barrier"),
                          "self-contact's energy: the penalty (2D) or the smooth barrier of incremental potential "
                          "contact (2D and 3D; no state or iterate passes through the surface); auto: the penalty "
                          "in 2D, the barrier in 3D (docs/creases.md)"),
    "contact_stiffness": key(float, 1000.0, in_closed(10.0, 1.0e6),
                             "self-contact's kappa (and a growing trial crease's mirror's): the penalty's interface "
                             "stiffness kappa mu / h (penetration ~ p / (kappa mu) of an element), or the barrier's "
                             "stiffness kappa mu"),
    "error_estimate": key(bool, True, None,
                          "estimate g_c's discretization error with two coarsened companion runs"),
}
