#!/usr/bin/env bash
# Prove the test suite bites: apply deliberate breakages one at a time to a scratch copy of the
# working tree and run the tests that should notice; each must fail. Prints a Markdown table
# (docs/testing.md keeps the last one). Not part of .ci/run (several minutes).
#   bash scripts/mutation-check.sh [--ranks N] [NAME ...]   (default: serially, every mutation)
# --ranks 2 runs the tests under `mpirun -n 2` (scripts/pytest-rank.sh), so the 2-rank-only tests take part;
# a mutation whose tests are all skipped there (serial-only tests) is reported "n/a".
# Exit code 1 if the unmutated tests fail or any mutation survives (or no longer applies).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
[ -x "$here/.venv/bin/python" ] || bash "$here/scripts/install.sh"
source "$here/scripts/mpi-env.sh"
exec "$here/.venv/bin/python" - "$here" "$@" <<'PY'
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

here = Path(sys.argv[1])
args = sys.argv[2:]
ranks = 1
if args[:1] == ["--ranks"]:
    ranks, args = int(args[1]), args[2:]
only = set(args)

# (name, file, regex, replacement, tests that must fail)
MUTATIONS = [
    ("minimizer: a solve that ran out of iterations descending from a saddle is cut back (no snap rounds)",
     "app/solvers/minimizer.py", r"\nSNAP_ROUNDS = 4", "\nSNAP_ROUNDS = 1",
     ["tests/test_barrier.py::test_a_crease_in_barrier_contact_is_the_same_on_1_and_2_ranks"]),
    ("barrier: a quadrilateral's centre passes nothing back to its nodes (gradient and Hessian of the 3D barrier)",
     "app/model/barrier.py", r"np\.add\.at\(out, self\.centres\.reshape\(-1\), ", "(lambda *a: None)(out, self.centres.reshape(-1), ",
     ["tests/test_barrier.py::test_the_barrier_has_its_finite_difference_derivatives"]),
    ("3D surface check: the wave along the frame's first axis only (no other directions of the surface)",
     "app/reduced/halfspace.py", r"if F\.shape == \(2, 2\):", "if True:",
     ["tests/test_surface_check.py::test_the_3d_half_space_is_the_plane_strain_one_for_a_wave_in_a_plane_of_the_state"]),
    ("clamped base: the 1D modes held as on rollers (u_y only)", "app/reduced/onset.py",
     r'sec\.shape == "planar" and not sec\.clamped', 'sec.shape == "planar"',
     ["tests/test_clamped_base.py::test_the_clamped_and_the_rollered_base_each_meet_their_1d_answer"]),
    ("3D user mesh: a node inside another cell's face not looked for (hanging nodes pass)", "meshes/msh.py",
     r"hit = \(dist < near\)", "hit = (dist < -1.0)",
     ["tests/test_msh3d.py::test_a_malformed_hexahedral_file_exits_2_naming_the_cell_or_group"]),
    ("3D user mesh: a passage's growth as the mean normal displacement (not the rings' radial mean)",
     "app/geometry/msh.py", r'growth="mean_radial" if shape == "cylinder"', 'growth="mean_normal" if shape == "cylinder"',
     ["tests/test_msh3d.py::test_the_3d_tube_read_back_from_its_msh_file_is_the_3d_tube"]),
    ("penalty at 2x2 Gauss points again (volumetric locking)", "app/model/potential.py",
     r"constraint \* \(dx_coupling or dx\)", "constraint * dx",
     ["tests/test_stability.py::test_compression_wrinkling_matches_stiff_film_theory"]),
    ("plate lattice with the length for the width (a square's lattice on every rectangle)", "app/reduced/section.py",
     r"L, W = self\.length, self\.width", "L, W = self.length, self.length",
     ["tests/test_three_d.py::test_a_rectangular_plate_lattice_weighs_each_side_by_its_length"]),
    ("3D tube's growth: the rings' mean radial displacement outward instead of inward", "app/model/growth.py",
     r"means\.append\(-np\.sum", "means.append(np.sum",
     ["tests/test_three_d.py::test_a_tube_one_element_long_is_the_plane_strain_tube"]),
    ("cylinder modes: the sin part of each n around dropped (cos only)", "app/model/shapes3d.py",
     r"e = np\.exp\(-1j \* np\.outer\(n, th\)\)", "e = np.cos(np.outer(n, th))",
     ["tests/test_three_d.py::test_the_wave_vector_of_an_analytic_field_on_a_cylinder"]),
    ("plane strain's out-of-plane stretch dropped from I1 (a constant in 2D's energy, none in 3D's)",
     "app/model/hydrogel.py", r"FF = ufl\.inner\(F, F\) \+ \(3 - ufl\.shape\(F\)\[0\]\)", "FF = ufl.inner(F, F)",
     ["tests/test_three_d.py::test_a_plate_one_element_wide_is_the_plane_strain_bilayer"]),
    ("dissipation term's factor off by 2", "app/model/hydrogel.py",
     r"/ \(2 \* tau \* J0", "/ (4 * tau * J0",
     ["tests/test_physics.py", "tests/test_loading.py"]),
    ("inertia count off by one", "app/solvers/stability.py",
     r"return int\(nneg\) \+ self", "return int(nneg) + 1 + self",
     ["tests/test_stability.py", "tests/test_screening.py"]),
    ("drained test without the elimination of the fluid content (S = K_uu: undrained)", "app/solvers/stability.py",
     r'P = B\.matTransposeMult\(sub\["uc"\]\)', 'P = B.matTransposeMult(sub["uc"]); P.scale(0.0)',
     ["tests/test_surface_instability.py", "tests/test_screening.py::test_criteria_are_ordered_and_rate_tends_to_the_limits"]),
    ("stiff-film formula's exponent changed", "app/model/theory.py",
     r"\(3 \* Es / Ef\) \*\* \(2 / 3\)", "(3 * Es / Ef) ** (1 / 2)",
     ["tests/test_stability.py::test_compression_wrinkling_matches_stiff_film_theory"]),
    ("surface potential at t_n instead of t_(n+1)", "app/solvers/stepping.py",
     r"self\.system\.set_time\(self\.t \+ dt, dt\)", "self.system.set_time(self.t, dt)",
     ["tests/test_loading.py", "tests/test_physics.py"]),
    ("stop_at_onset ignored", "app/onset/policy.py",
     r"return self\.after is AfterCrossing\.STOP or ", "return ",
     ["tests/test_stability.py::test_summary_reports_modes_and_writes_mode_files"]),
    ("console script removed from pyproject.toml", "pyproject.toml",
     r'\nhydrobuckle = "app\.cli:main"\n', "\n",
     ["tests/test_console.py::test_install_into_fresh_venv_creates_console_script"]),
    ("install check fooled by the current directory", "scripts/install.sh",
     r'installed\(\) \{.*?\n\}\n',
     'installed() {\n  "$venv/bin/python" - "$here" >/dev/null 2>&1 <<\'PYCHECK\'\nimport sys, pathlib, app\n'
     'assert pathlib.Path(app.__file__).resolve().parent == pathlib.Path(sys.argv[1]).resolve() / "app"\n'
     'PYCHECK\n}\n',
     ["tests/test_console.py::test_install_into_fresh_venv_creates_console_script"]),
    ("accumulated flux not accumulated (Q_n = dQ)", "app/model/problem.py",
     r"state\[self\.q_dofs\] \+= w\[self\.q_dofs\]", "state[self.q_dofs] = w[self.q_dofs]",
     ["tests/test_physics.py"]),
    ("bench keeps a repeated --sizes entry", "app/workflows/bench.py",
     r"if twice:", "if False:",
     ["tests/test_bench.py::test_bench_rejects_bad_sizes"]),
    ("a history row that did not fit is left in part (not cut back off)", "app/io/writes.py",
     r"os\.ftruncate\(self\.fd, start\)", "pass",
     ["tests/test_write_errors.py::test_a_row_that_does_not_fit_is_cut_back_off"]),
    ("surface self-contact never found", "app/onset/contact.py",
     r"pair = _segments_cross\(x, shape\.closed\)", "pair = None",
     ["tests/test_postbuckling.py::test_inversion_check_on_a_computed_creased_state"]),
    ("closed passage ordered along x for the contact check", "app/model/shapes.py",
     r"return np\.argsort\(np\.arctan2\(rel\[:, 1\], rel\[:, 0\]\)\)", "return np.argsort(rel[:, 0])",
     ["tests/test_postbuckling.py::test_a_tube_branch_is_followed_around_its_closed_passage"]),
    ("inverted cells never reported", "app/onset/contact.py",
     r"if jmin > 0:", "if True:",
     ["tests/test_postbuckling.py::test_inversion_check_on_a_computed_creased_state"]),
    ("a new crossing on a branch not detected (the count only falls there)", "app/onset/tracker.py",
     r"if nneg > self\.count:", "if nneg > self.count and not self.stepper.minimizing:",
     ["tests/test_postbuckling.py::test_branch_crossings_on_a_branch_are_detected"]),
    ("after a switch the perturbed state's count alone is the reference (the same instability a new crossing)",
     "app/onset/tracker.py", r"self\.count = max\(self\.screen\.start\(\), nneg\)",
     "self.count = self.screen.start()",
     ["tests/test_postbuckling.py::"
      "test_a_switch_that_lowers_the_count_does_not_make_the_same_instability_a_new_crossing"]),
    ("drained branch switch with its fluid content of the wrong sign (phase)", "app/solvers/stability.py",
     r"b\.scale\(-1\.0\)", "b.scale(1.0)",
     ["tests/test_postbuckling.py::test_drained_switch_leaves_the_chemical_potential_unperturbed"]),
    ("a minimizing step that ends uphill accepted", "app/solvers/stepping.py",
     r"if not energy_decreased\(self\.solver\.last\):", "if False:",
     ["tests/test_postbuckling.py::test_a_minimizing_step_that_ends_uphill_is_rejected"]),
    ("the branch state not carried by a checkpoint (resumed on the fundamental path)", "app/solvers/stepping.py",
     r'"minimizing": self\.minimizing,', '"minimizing": False,',
     ["tests/test_checkpoint.py::test_resume_continues_like_an_uninterrupted_run"]),
    ("the trial crease stops halfway to the symmetry line", "app/onset/creases.py",
     r"\(s \+ step\) \* \(self\.line - X\)", "(s + step) * (self.line - 0.5 * X)",
     ["tests/test_creases.py::test_the_crease_onset_of_a_compressed_layer_is_hong_zhao_suos_before_biots"]),
    ("the contact penalty's Hessian drops g times the gap's curvature", "app/model/polyline_penalty.py",
     r"k\[p\] \* \(np\.outer\(dg, dg\) \+ g \* d2g\)", "k[p] * np.outer(dg, dg)",
     ["tests/test_contact.py::test_the_gap_and_the_penalty_have_their_finite_difference_derivatives"]),
    ("the contact's candidate search misses the pairs up to the reach", "app/model/polyline_penalty.py",
     r"0\.5 \* L \+ self\.reach \* self\.seg_length", "0.5 * L",
     ["tests/test_contact.py::test_the_pairs_near_enough_to_touch_are_those_of_a_check_of_every_pair"]),
    ("contact pairs a node with what lies behind a corner", "app/model/polyline_penalty.py",
     r"self\.partners = ~own & \(facing >= -1e-9 \* L\[None, :\]\)", "self.partners = ~own",
     ["tests/test_contact.py::test_a_bodys_own_corner_is_not_contact"]),
    ("contact by the nodes alone (the segments' midpoints weightless)", "app/model/polyline_penalty.py",
     r"self\.weight = np\.concatenate\(\[count / 6\.0, np\.full\(m, 2\.0 / 3\.0\)\]\)",
     "self.weight = np.concatenate([count / 2.0, np.zeros(m)])",
     ["tests/test_contact.py::test_a_slit_pressed_onto_itself_is_its_half_with_a_symmetry_line"]),
    ("the drained criterion leaves out the contact's Hessian", "app/solvers/stability.py",
     r'self\.A = fem_petsc\.create_matrix\(hessian\.form\)\n        self\.contact = getattr\(hessian, "contact", None\)',
     'self.A = fem_petsc.create_matrix(hessian.form)\n        self.contact = None',
     ["tests/test_contact.py::test_a_tube_passage_folds_all_around_and_is_followed_in_contact"]),
    ("the swelling crease's grand potential without the bath's work", "app/model/equilibrium.py",
     r"G = \(bulk - self\.mu_bar \* c\) \* p\.dx", "G = bulk * p.dx",
     ["tests/test_creases_swelling.py::test_the_flat_state_in_equilibrium_with_the_bath_is_the_constrained_layers_closed_form"]),
    ("the undrained creased state lets its fluid follow (drained)", "app/model/equilibrium.py",
     r"            self\.kept = \[bc\]\n", "",
     ["tests/test_creases_swelling.py::test_the_drained_crease_costs_less_than_the_undrained_one_and_comes_first"]),
    ("a crease level counts a failed flat state as past the onset", "app/onset/maxwell.py",
     r"        except FlatFailed:  # no flat state, no comparison: the level cannot be completed\n            raise\n", "",
     ["tests/test_creases.py::test_a_flat_state_that_cannot_be_solved_ends_the_level_instead_of_counting_as_past_the_onset"]),
    ("a crease bracket that snaps is taken for a sign change", "app/onset/maxwell.py",
     r'return "failed" in tb or \(not grows and tb\["depth_mm"\] > SNAP_DEPTH_RATIO \* ta\["depth_mm"\]\)', "return False",
     ["tests/test_creases.py::test_a_bracket_that_ends_in_a_snap_bounds_the_onset_from_above"]),
    ("a .msh mesh's mesh companion asks for an element size again", "app/workflows/error_estimate.py",
     r"        return refined_configs\(cfg, study, 2\)\[1\]\[2\], \"refined\"", "        raise",
     ["tests/test_own_geometry.py::test_msh_run_with_default_settings_reports_an_error_bar",
      "tests/test_own_geometry.py::test_readme_own_geometry_example_as_written"]),
    ("time companion with its step bounds unchanged (dt_max holds the slow phase)", "app/workflows/convergence.py",
     r'changes\.update\(\{"time\.dt_initial": dt0, "time\.dt_max": max\(t\["dt_max"\] / r, dt0\),',
     'changes.update({"time.dt_initial": t["dt_initial"], "time.dt_max": t["dt_max"],',
     ["tests/test_error_estimate.py"]),
    ("result directory not locked (two runs into one directory)", "app/io/lock.py",
     r"    problem = comm\.bcast\(problem, root=0\)\n    if problem:", "    problem = None\n    if problem:",
     ["tests/test_result_lock.py"]),
    ("1D reduction: drained modes without the elimination of s (undrained)", "app/reduced/modes.py",
     r"a = a - ufl\.derivative\(e_s, p, v\) \* ufl\.derivative\(e_s, p, dv\) / e_ss \* weight \* dx", "a = a",
     ["tests/test_reduction.py::test_mode_operator_of_a_homogeneous_layer_at_short_waves_is_the_surface_condition"]),
    ("1D reduction: the short-wave half-space without the elimination of s", "app/reduced/halfspace.py",
     r"a = a - ufl\.derivative\(e_s, p, v\) \* ufl\.derivative\(e_s, p, dv\) / e_ss \* dx", "a = a",
     ["tests/test_reduction.py::test_short_wave_limit_is_the_homogeneous_layers_surface_condition"]),
    ("1D reduction: the sin part of the mode's gradient with the wrong sign", "app/reduced/modes.py",
     r"\[-k \* V, V\.dx\(0\)\]", "[k * V, V.dx(0)]",
     ["tests/test_reduction.py::test_stiff_film_in_compression_wrinkles_at_the_film_on_substrate_strain"]),
    ("2D surface check: the surface state not in equilibrium with the bath", "app/onset/surface_check.py",
     r"\(mu - self\.mu_bar\) \* v\[dim\]", "(mu - 0.0) * v[dim]",
     ["tests/test_surface_check.py"]),
    ("a solve failed with a kept factor is not repeated with plain Newton", "app/solvers/newton.py",
     r"if reason <= 0 and self\._kept:", "if False:",
     ["tests/test_reuse.py::test_a_failed_reuse_is_repeated_with_plain_newton"]),
    ("the repeat of a failed reuse starts from the failed iterate", "app/solvers/newton.py",
     r"            start\.copy\(self\.x\)\n", "",
     ["tests/test_reuse.py::test_a_failed_reuse_is_repeated_with_plain_newton"]),
    ("the contact objective lets a node tunnel beyond the penalty's reach", "app/model/polyline_penalty.py",
     r"return math\.inf if len\(self\.tunnelled_crossings\(u\)\) else self\.energy\(u\)", "return self.energy(u)",
     ["tests/test_contact.py::test_a_node_pushed_through_beyond_the_penalty_reach_is_outside_the_domain"]),
    ("the minimizer's negative-curvature step goes uphill", "app/solvers/minimizer.py",
     r"            if w\.dot\(v\) > 0\.0:", "            if w.dot(v) < 0.0:",
     ["tests/test_postbuckling.py::test_a_stalled_line_search_at_a_saddle_is_left_along_negative_curvature"]),
    ("a branch step starts from an extrapolated guess outside the energy's domain", "app/solvers/stepping.py",
     r"if self\.minimizing and not self\.solver\.admissible\(self\.system\.state\.x\.array\):", "if False:",
     ["tests/test_postbuckling.py::test_a_branch_step_whose_extrapolated_start_inverts_a_cell_starts_from_the_last_state"]),
    ("a stalled minimizer never leaves the saddle", "app/solvers/minimizer.py",
     r"and self\.last\.escapes < ESCAPES and self\._escape\(\)\)", "and False)",
     ["tests/test_postbuckling.py::test_a_stalled_line_search_at_a_saddle_is_left_along_negative_curvature"]),
    ("a growing crease's mirror holds nothing", "app/model/equilibrium.py",
     r"return 0\.5 \* stiffness \*", "return 0.5e-9 * stiffness *",
     ["tests/test_creases.py::test_a_growing_crease_on_a_homogeneous_layer_has_the_held_creases_onset"]),
    ("a growing crease is closed from the flat state at every load, never followed down", "app/onset/creases.py",
     r"above = \[tk for tk in self\._creased if tk > t\]", "above = []",
     ["tests/test_creases.py::test_a_growing_crease_in_a_bilayer_takes_a_size_of_its_own"]),
    ("a transient's content taken at the cells' first Gauss point, not their mean", "app/model/equilibrium.py",
     r"\(self\.content\(t, self\._y\) \* self\._w\)\.sum\(axis=1\)", "self.content(t, self._y)[:, 0]",
     ["tests/test_creases_swelling.py::"
      "test_a_trial_on_the_runs_transient_holds_its_uniform_content_and_quasi_statically_is_the_undrained_one"]),
    ("a transient's content profile from the flux, not its derivative", "app/reduced/content.py",
     r"coefficients\[m, i\] = -np\.polyder\(np\.polyfit\(xi, Q\[i \* d:i \* d \+ d \+ 1\], d\)\) / h",
     "coefficients[m, i] = -np.polyfit(xi, Q[i * d:i * d + d + 1], d)[1:] / h",
     ["tests/test_creases_swelling.py::"
      "test_a_trial_on_the_runs_transient_holds_its_uniform_content_and_quasi_statically_is_the_undrained_one"]),
    ("an overrun contact penalty is never raised", "app/onset/contact.py",
     r"elif self\.p\.contact\.stiffen\(t\):", "elif False:",
     ["tests/test_contact.py::test_a_soft_penalty_is_raised_until_it_holds_the_contact_and_a_resume_keeps_it"]),
    ("a resumed run forgets the raised contact penalty", "app/io/checkpoint.py",
     r'    if meta\.get\("contact"\) and problem\.contact is not None:',
     '    if False:',
     ["tests/test_contact.py::test_a_soft_penalty_is_raised_until_it_holds_the_contact_and_a_resume_keeps_it"]),
]


def scratch_copy() -> Path:
    dst = Path(tempfile.mkdtemp(prefix="hb-mutant-"))
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=here, check=True,
                           capture_output=True, text=True).stdout.split("\n")
    for f in filter(None, files):
        src = here / f
        if src.is_file():
            (dst / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst / f)
    return dst


def pytest(root: Path, tests) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    if ranks == 1:
        cmd = [str(here / ".venv/bin/python"), "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--color=no", *tests]
    else:  # the scratch copy's scripts/pytest-rank.sh runs its .venv (a link to this checkout's) from the copy
        if not (root / ".venv").exists():
            (root / ".venv").symlink_to(here / ".venv")
        cmd = ["mpirun", "-n", str(ranks), *os.environ.get("HB_MPIRUN_FLAGS", "").split(), "bash",
               str(root / "scripts" / "pytest-rank.sh"), "-x", *tests]
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    pytest.output = proc.stdout[-4000:]
    lines = [line for line in proc.stdout.splitlines() if re.search(r"(passed|failed|skipped|error)", line)
             and " in " in line] or [line for line in proc.stdout.splitlines() if line.strip()][-1:] or [""]
    return proc.returncode, time.perf_counter() - t0, lines[-1]


def all_skipped(last: str) -> bool:
    return "skipped" in last and not re.search(r"\d+ (passed|failed|error)", last)


selected = [m for m in MUTATIONS if not only or any(o in m[0] for o in only)]
tests_all = sorted({t for m in selected for t in m[4]})
base = scratch_copy()
check = subprocess.run([str(here / ".venv/bin/python"), "-c", "import app; print(app.__file__)"], cwd=base,
                       capture_output=True, text=True).stdout.strip()
assert check.startswith(str(base)), f"the scratch copy's app is not the one imported: {check}"
rc, secs, last = pytest(base, tests_all)
print(f"unmutated: {last} ({secs:.0f} s)", flush=True)
if rc != 0:
    print(pytest.output)
    print("mutation-check: the unmutated tests fail; fix them first")
    sys.exit(1)
shutil.rmtree(base)

rows, survived = [], 0
for name, path, pattern, repl, tests in selected:
    root = scratch_copy()
    text = (root / path).read_text()
    new, n = re.subn(pattern, lambda _m: repl, text, count=1, flags=re.S)
    if n != 1:
        rows.append((name, path, "NOT APPLIED (pattern not found)", "", ""))
        survived += 1
        shutil.rmtree(root)
        continue
    (root / path).write_text(new)
    rc, secs, last = pytest(root, tests)
    caught = rc != 0
    verdict = "caught" if caught else ("n/a (every test skipped)" if all_skipped(last) else "SURVIVED")
    survived += verdict == "SURVIVED"
    rows.append((name, path, verdict, f"{secs:.0f}", last))
    print(f"{verdict:8s} {name}: {last} ({secs:.0f} s)", flush=True)
    shutil.rmtree(root)

print()
print("| mutation | file | result | tests [s] | pytest's last line |")
print("|---|---|---|---|---|")
for r in rows:
    print("| " + " | ".join(r) + " |")
na = sum(r[2].startswith("n/a") for r in rows)
print(f"\n{len(rows) - survived - na}/{len(rows) - na} mutations caught on {ranks} rank(s)"
      + (f" ({na} n/a: their tests run serially only)" if na else ""))
sys.exit(1 if survived else 0)
PY
