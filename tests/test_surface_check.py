"""The 2D run's check of the permeable surface's short-wave limit (app/onset/surface_check.py).

- the surface state in equilibrium with the bath against the closed-form laterally constrained layer;
- a 2D bilayer whose surface becomes unstable at short waves before it wrinkles (the paper's w = 0.05 mm
  film on a narrow strip): the surface onset at the instant the bath's chemical potential reaches that
  of the film's homogeneous critical stretch (theory: lateral stretch 1 at the surface), and at the 1D
  reduction's short-wave onset;
- a homogeneous tube (ratio 1): the 2D surface onset against the 1D reduction's (the passage is
  compressed around by the swelling, so the local state is not the flat one).
- 3D (the same check on each quadrilateral facet, the wave in every direction of the surface): the surface
  state and half-space against the 2D ones where the state lies in a plane, a state unstable only across the
  2D plane, and the 3D slab and the 3D tube one element long against the 2D runs' surface onsets.
"""

from __future__ import annotations

import numpy as np
import pytest

from app import config
from app.model import theory
from app.model.material import chemical_potential, first_piola
from app.factory import layer_materials
from app.onset.surface_check import SurfaceState
from app.workflows import reduction
from app.workflows.run import simulate


def _critical_time(cfg) -> float:
    """When the ramp brings the bath to the chemical potential of the film's critical constrained state."""
    film = layer_materials(cfg)["film"]
    lc = theory.surface_critical_stretch(film, drained=True)
    mu_c = chemical_potential(film, ((1.0, 0.0), (0.0, lc)), theory.constrained_layer_fluid(film, lc))
    lo = cfg["loading"]
    return lo["ramp_time"] * (mu_c - film.mu0) / (lo["chemical_potential"] - film.mu0)


def test_surface_state_is_the_constrained_layer_in_equilibrium_with_the_bath():
    """Tangential column (1, 0): the normal stretch and s of a laterally constrained layer at mu_bar
    (closed form, app.model.theory); a sheared, stretched column: P e_n = 0 and mu = mu_bar by the law's
    float evaluation. Measured 1e-12."""
    cfg = config.load("configs/bilayer.toml")
    film = layer_materials(cfg)["film"]
    st = SurfaceState([film, film, film])
    cols = np.array([[1.0, 0.0], [0.97, 0.0], [1.02, 0.08]])
    for mu_bar in (-5.0, -0.5, 0.0):
        F, s = st.solve(cols, mu_bar)
        lam = theory.constrained_layer_stretch(film, mu_bar)
        assert F[0, 1, 1] == pytest.approx(lam, rel=1e-10) and F[0, 0, 1] == pytest.approx(0.0, abs=1e-12)
        assert s[0] == pytest.approx(theory.constrained_layer_fluid(film, lam), rel=1e-10)
        for i in (1, 2):
            P = first_piola(film, F[i], s[i])
            assert np.abs(P[:, 1]).max() < 1e-10
            assert chemical_potential(film, F[i], s[i]) == pytest.approx(mu_bar, abs=1e-10)


W05 = ["geometry.film_thickness=0.05", "geometry.length=0.3", "mesh.element_size=0.01", "mesh.film_layers=4",
       "stability.error_estimate=false", "reduced.beside_2d=false", "output.fields=false", "output.plot=false"]


def test_2d_bilayer_reports_the_surface_onset_at_the_bath_potential_of_the_critical_state(shared_tmp, comm):
    """w = 0.05 mm on a 0.3 mm strip: the surface onset within 1e-4 s of the closed-form instant (measured
    4e-5: the quadratic between steps), before the 2D wrinkling onset, and within 2e-4 s of the 1D
    reduction's converged short-wave onset."""
    cfg = config.load("configs/bilayer.toml", W05)
    s = simulate(cfg, shared_tmp / "w05", comm, progress=False)
    so = s["surface_onset"]
    t_c = _critical_time(cfg)
    assert so["kind"] == "surface" and so["criterion"] == "drained"
    assert so["time"] == pytest.approx(t_c, abs=1e-4)
    assert so["bracket"][0] <= so["time"] <= so["bracket"][1]
    assert so["before_critical"] and s["critical"]["time"] > so["time"]
    assert so["where"][1] == pytest.approx(0.55)  # on the film's surface
    red = reduction.compute(cfg) if comm.rank == 0 else None
    red = comm.bcast({k: v for k, v in red.items() if k != "_estimate"} if red else None, root=0)
    assert red["kind"] == "surface"
    assert red["time"] == pytest.approx(so["time"], abs=2e-4)


def test_2d_homogeneous_tube_surface_onset_equals_the_reduction(shared_tmp, comm):
    """A tube of one gel (ratio 1): its passage is unstable at short waves before any finite wave (1D:
    t = 0.98757 s, no wavelength of its own). The 2D check on a coarse mesh (the state it needs is the
    passage's hoop stretch, which the mesh resolves) agrees with the 1D onset to 1e-3 s."""
    cfg = config.load("configs/tube.toml", [
        "material.film.modulus_ratio=1", "mesh.element_size=0.04", "mesh.film_layers=2",
        "stability.error_estimate=false", "reduced.beside_2d=false", "output.fields=false", "output.plot=false",
        "time.end=1.0"])
    s = simulate(cfg, shared_tmp / "tube1", comm, progress=False)
    so = s["surface_onset"]
    red = reduction.compute(cfg) if comm.rank == 0 else None
    red = comm.bcast({k: v for k, v in red.items() if k != "_estimate"} if red else None, root=0)
    assert red["kind"] == "surface"
    assert so["time"] == pytest.approx(red["time"], abs=1e-3)
    # the passage's hoop stretch is below 1 there: the local state is not the flat surface's
    assert so["time"] != pytest.approx(_critical_time(cfg), abs=1e-4)
    r = np.hypot(*so["where"])
    assert r == pytest.approx(cfg["geometry"]["outer_radius"] - 0.2 - 0.02, rel=1e-3)


def test_a_resumed_run_keeps_the_surface_onset_found_before_its_checkpoint(shared_tmp, comm):
    """The w = 0.05 mm strip stopped (as an interrupt stops it) three steps after its surface onset and
    resumed: summary.json reports the surface onset the stopped run found (the checkpoint carries it; the
    check does not look again), which is the uninterrupted run's."""
    from app.io import checkpoint

    cfg = config.load("configs/bilayer.toml", W05 + ["output.checkpoint_every=1"])
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    so = full["surface_onset"]
    assert so["before_critical"]
    rows = np.genfromtxt(shared_tmp / "full" / "history.csv", delimiter=",", names=True)
    stop = int(rows["step"][rows["time"] >= so["time"]][0]) + 3
    assert stop + 3 < full["steps"]
    part = shared_tmp / "part"
    stopped = simulate(cfg, part, comm, progress=False, stop_after=stop)
    assert stopped["status"] == "interrupted" and stopped["surface_onset"] is not None
    resumed = simulate(cfg, part, comm, progress=False, resume=checkpoint.check(part, cfg, comm))
    # the resumed run reports the onset its checkpoint carries, exactly
    assert resumed["surface_onset"] == stopped["surface_onset"]
    # and the uninterrupted run's: bit for bit serially; on 2 ranks MUMPS' roundoff (measured 5e-16), and the
    # place only serially: the strip's surface state is uniform along it, so on 2 ranks which facet of that tie
    # is reported changes from run to run (measured: x = 0.005 and 0.165 mm)
    got = resumed["surface_onset"]
    assert got.keys() == so.keys()
    for k, v in so.items():
        if k == "where" and comm.size > 1:
            assert got[k][1] == pytest.approx(v[1], rel=1e-12)  # on the surface: y alone
            continue
        numeric = isinstance(v, float) or (isinstance(v, list) and all(isinstance(x, float) for x in v))
        assert got[k] == (pytest.approx(v, rel=1e-12) if numeric else v), k
    assert resumed["critical"]["time"] == pytest.approx(full["critical"]["time"], rel=1e-10)


# --- 3D (docs/three-d.md, "The short-wave surface check in 3D") ---------------------------------------------

def _film():
    return layer_materials(config.load("configs/bilayer.toml"))["film"]


def test_the_3d_surface_state_is_the_2d_one_with_the_third_stretch_and_in_equilibrium():
    """Tangential columns (1, 0, 0), (0, 1, 0): the laterally constrained layer of the closed form, as in 2D;
    a sheared, stretched pair: P e_n = 0 and mu = mu_bar by the law's float evaluation. Measured 1e-12."""
    film = _film()
    st = SurfaceState([film, film], dim=3)
    cols = np.array([[[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]], [[0.97, 0.05], [0.02, 1.03], [0.06, -0.04]]])
    for mu_bar in (-5.0, -0.5, 0.0):
        F, s = st.solve(cols, mu_bar)
        lam = theory.constrained_layer_stretch(film, mu_bar)
        assert F[0, 2, 2] == pytest.approx(lam, rel=1e-10) and np.abs(F[0, :2, 2]).max() < 1e-12
        assert s[0] == pytest.approx(theory.constrained_layer_fluid(film, lam), rel=1e-10)
        P = first_piola(film, F[1], s[1])
        assert np.abs(np.asarray(P)[:, 2]).max() < 1e-10
        assert chemical_potential(film, F[1], s[1]) == pytest.approx(mu_bar, abs=1e-10)


def test_the_3d_half_space_is_the_plane_strain_one_for_a_wave_in_a_plane_of_the_state():
    """A state with F_2D in its (t1, n) block and 1 at t2 (F t2 = t2), the wave along t1, is the plane-strain
    half-space: the
    margins agree to roundoff (measured 1e-13); the margin over the wave's directions does not depend on how
    the frame is turned about the normal (the law is isotropic; to the scaling, below), and a state compressed along t2 only is
    unstable in 3D where the 2D check, which sees waves along t1 only, is not. (The margin is the smallest
    eigenvalue of the Jacobi-scaled operator: its sign is frame-independent, its size to the scaling.)"""
    from app.reduced.halfspace import HalfSpace

    film = _film()
    h2, h3 = HalfSpace(film, "drained"), HalfSpace(film, "drained", dim=3)
    st2, st3 = SurfaceState([film]), SurfaceState([film], dim=3)
    for mu_bar in (-0.5, -0.05, 0.0):
        F2, s2 = st2.solve(np.array([[1.0, 0.0]]), mu_bar)
        F3 = np.eye(3)
        F3[np.ix_([0, 2], [0, 2])] = F2[0]
        margin2 = h2.margin(F2[0], float(s2[0]))
        assert h3.margin_along(F3, float(s2[0])) == pytest.approx(margin2, rel=1e-10, abs=1e-12)
        # isotropic in the plane: every direction the same up to the Jacobi scaling of the turned components
        # (the margin's sign is exact, its size measured 1e-5 apart)
        assert h3.margin(F3, float(s2[0])) == pytest.approx(margin2, rel=1e-4)
        assert h3.definite(F3, float(s2[0])) == h2.definite(F2[0], float(s2[0])) == (margin2 > 0)
    # compressed along t2 (0.9), not along t1, at a bath where the unstrained surface is stable; turned by 0.3 rad
    cols = np.array([[[1.0, 0.0], [0.0, 0.9], [0.0, 0.0]]])
    F, s = st3.solve(cols, -0.5)
    c, sn = np.cos(0.3), np.sin(0.3)
    Q = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    assert h3.margin(F[0] @ Q, float(s[0])) == pytest.approx(h3.margin(F[0], float(s[0])), rel=1e-4)
    assert h3.margin(F[0], float(s[0])) < 0 < h3.margin_along(F[0], float(s[0]))


def test_a_3d_slab_reports_the_2d_surface_onset(shared_tmp, comm):
    """The w = 0.05 mm strip as a plate one element wide: the surface onset of the 3D check at the 2D run's
    (1e-8 s; the states are the same) and at the closed-form instant (1e-4 s, as in 2D), on the film's top."""
    cfg2 = config.load("configs/bilayer.toml", W05)
    cfg3 = config.load("configs/bilayer.toml", W05 + ["geometry.kind=plate", "geometry.width=0.01",
                                                     "geometry.substrate_thickness=0.5"])
    s2 = simulate(cfg2, shared_tmp / "w05-2d", comm, progress=False)["surface_onset"]
    s3 = simulate(cfg3, shared_tmp / "w05-3d", comm, progress=False)["surface_onset"]
    assert s3["time"] == pytest.approx(s2["time"], abs=1e-8)
    assert s3["time"] == pytest.approx(_critical_time(cfg3), abs=1e-4)
    assert len(s3["where"]) == 3 and s3["where"][1] == pytest.approx(0.55)


def test_a_3d_tube_one_element_long_reports_the_2d_tube_surface_onset(shared_tmp, comm):
    """The homogeneous tube above as a 3D tube one element long: the same passage state, and a wave along the
    axis (where the passage keeps its stretch 1) is not the first unstable one, so the 3D check finds the 2D
    check's onset, on the passage. The facets around the polygonal passage differ in their states by the
    discretization (1e-7), and which of them goes first depends on the partition: measured up to 2.3e-7 s apart
    on 2 ranks (equal to the printed digits on 1); a wrong surface state moves the onset by 1e-3 s or more."""
    over = ["material.film.modulus_ratio=1", "mesh.element_size=0.04", "mesh.film_layers=2",
            "stability.error_estimate=false", "reduced.beside_2d=false", "output.fields=false", "output.plot=false",
            "time.end=1.0"]
    s2 = simulate(config.load("configs/tube.toml", over), shared_tmp / "t2", comm, progress=False)["surface_onset"]
    cfg3 = config.load("configs/tube.toml", over + ["geometry.kind=tube-3d", "geometry.length=0.04"])
    s3 = simulate(cfg3, shared_tmp / "t3", comm, progress=False)["surface_onset"]
    assert s3["time"] == pytest.approx(s2["time"], abs=1e-6)
    assert np.hypot(*s3["where"][:2]) == pytest.approx(np.hypot(*s2["where"]), rel=1e-3)  # on the passage
