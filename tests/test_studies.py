"""Studies and sweeps: resumable, failures isolated, rank groups give the same answers, and the
paper's robust trends on coarse meshes."""

import csv
import json

import pytest
from cases import SMALL_TUBE, SWELLING
from mpi4py import MPI

from app import cli
from app.workflows import studies


def _sweep(outdir, comm, param, values, base=SWELLING, overrides=(), ranks_per_case=1, force=False):
    cases = studies.build_cases(base, param, values, outdir, list(overrides))
    return studies.run_study(cases, outdir, comm, "test", param, ranks_per_case, force), cases


def _g(rows):
    return [r["g_c_um"] for r in rows]


def test_sweep_is_resumable_and_writes_tables(shared_tmp, comm, log_lines):
    out = shared_tmp / "sweep"
    rows, cases = _sweep(out, comm, "material.film.modulus_ratio", [6.0, 12.0])
    assert [r["status"] for r in rows] == ["buckled", "buckled"]
    if comm.rank == 0:  # the progress a user waits with: cases done of the total, the time left
        counts = [line.split(";")[0] for line in log_lines if " cases done" in line]
        # 2 ranks: one case per group; rank 0's line counts the other group's case if it ended first
        assert counts == (["study: 1/2 cases done", "study: 2/2 cases done"] if comm.size == 1
                          else [counts[0]]) and counts[0] in ("study: 1/2 cases done", "study: 2/2 cases done")
        assert log_lines[0] == f"study: 2 cases on {comm.size} group(s) of 1 rank(s)"
        if comm.size == 1:
            first = next(line for line in log_lines if "1/2 cases done" in line)
            assert "left (" in first and "a case)" in first
            assert log_lines[-1].endswith("2/2 cases done; none left")
        log_lines.clear()
    stamps = [(c.outdir / "summary.json").stat().st_mtime_ns for c in cases]
    rows2, _ = _sweep(out, comm, "material.film.modulus_ratio", [6.0, 12.0])
    if comm.rank == 0:
        assert log_lines[0] == f"study: 2 cases on {comm.size} group(s) of 1 rank(s); 2 complete already"
    assert [(c.outdir / "summary.json").stat().st_mtime_ns for c in cases] == stamps  # skipped
    assert _g(rows2) == _g(rows)
    with open(out / "study.csv") as f:
        table = list(csv.DictReader(f))
    assert [float(r["value"]) for r in table] == [6.0, 12.0]
    assert all((out / name).stat().st_size > 0 for name in ("study.png", "modes.png", "study.json"))
    # a changed config is not "complete": the case reruns
    rows3, _ = _sweep(out, comm, "material.film.modulus_ratio", [6.0], overrides=["stability.tolerance=5e-4"])
    assert rows3[0]["status"] == "buckled"
    assert (cases[0].outdir / "summary.json").stat().st_mtime_ns != stamps[0]


def test_failed_case_is_reported_and_the_others_run(shared_tmp, comm):
    out = shared_tmp / "fail"
    rows, _ = _sweep(out, comm, "solver.max_it", [1, 25], overrides=["time.dt_min=0.001", "time.end=0.5"])
    assert [r["status"] for r in rows] == ["failed", "stable"]


def test_cli_study_rejects_bad_input(shared_tmp, capsys):
    assert cli.main(["study", "no-such-study", "-o", str(shared_tmp / "x")]) == 2
    assert cli.main(["study", "tube-aspect-ratio", "--values", "1.2,1.9", "-o", str(shared_tmp / "x")]) == 2
    assert "aspect_ratio <= 1.5465" in capsys.readouterr().err or MPI.COMM_WORLD.rank != 0
    assert not (shared_tmp / "x").exists()
    assert cli.main(["sweep", "nope.toml", "--param", "a.b", "--values", "1"]) == 2
    if MPI.COMM_WORLD.rank == 0:  # the line names the file once
        assert capsys.readouterr().err.strip().splitlines() == ["hydrobuckle: error: config file 'nope.toml' does not exist"]


def test_study_tables_print_each_studys_results_and_its_1d_reduction(shared_tmp, capsys):
    """``study --tables DIR``: one markdown table per study from DIR/<study>/study.csv, with every value of a
    row in its column's format ("-" where the case has none), and the 1D reduction's table from
    DIR/<study>-reduced/study.csv where that was run; a study not run says so. A DIR that does not exist is
    bad input: exit 2, one line naming it."""
    root, study = shared_tmp / "tables", "bilayer-modulus-ratio"
    rows = {study: [{"series": "", "value": 2.0, "status": "wrinkled", "g_c_um": 12.34567, "N_c": 3.5,
                               "t_c": 0.123456, "mu_c": -1.2345, "wall_time_s": 42.4},
                              {"series": "", "value": 5.0, "status": "failed"}],
            f"{study}-reduced": [{"series": "", "value": 2.0, "status": "done", "onset": "wrinkles",
                                       "g_c_um": 12.3, "g_c_error_um": 0.0004, "N_c": 3.5, "t_c": 0.1,
                                       "mu_c": -1.2, "wall_time_s": 1.26}]}
    if MPI.COMM_WORLD.rank == 0:
        for name, table in rows.items():
            (root / name).mkdir(parents=True)
            with open(root / name / "study.csv", "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=studies.COLUMNS)
                w.writeheader()
                w.writerows({k: r.get(k, "") for k in studies.COLUMNS} for r in table)
    MPI.COMM_WORLD.barrier()
    capsys.readouterr()
    assert cli.main(["study", "--tables", str(root)]) == 0
    out = capsys.readouterr().out
    assert "| - | 2.0 | wrinkled | 12.346 | 3.5 | 0.1235 | -1.23 | 42 |" in out
    assert "| - | 5.0 | failed | - | - | - | - | - |" in out
    assert f"### {study} (1D reduction)" in out
    assert "| - | 2.0 | wrinkles | 12.300 | 0.000 | 3.5 | 0.1000 | -1.20 | 1.3 |" in out
    for name in studies.STUDIES:  # every study has its section, run or not
        assert f"### {name}\n" in out
    assert out.count("(not run)") == len(studies.STUDIES) - 1
    assert cli.main(["study", "--tables", str(root / "nope")]) == 2
    if MPI.COMM_WORLD.rank == 0:
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "nope: no such directory" in err[0]


def test_the_crease_study_tabulates_both_verdicts_and_interpolates_the_crossovers(shared_tmp, capsys):
    """``study bilayer-creases``: each case's row carries its crease onset, the film's own onset and both
    verdicts from summary.json; ``study --tables`` prints them and the crossovers, where the crease's onset
    (the run's; the film's own) equals the wrinkling onset, interpolated linearly between the rows that
    change sign. Onsets linear in the ratio r: crease 0.5 - 0.05 r, film's own 0.59 (a constant), wrinkle
    0.8 - 0.15 r cross at r = 3 and r = 1.4 exactly."""
    spec, cases = studies.study_cases("bilayer-creases", shared_tmp / "creases", "1,2,4", [])
    assert spec.creases and all(c.cfg["stability"]["creases"] for c in cases)
    assert cases[1].cfg["material"]["film"]["modulus_ratio"] == 2
    for case in cases:
        r = case.value
        t = {"crease": 0.5 - 0.05 * r, "film": 0.59, "wrinkle": 0.8 - 0.15 * r}
        first = {"least_energy": "crease" if t["crease"] < t["wrinkle"] else "wrinkle",
                 "nucleation": "crease" if t["film"] < t["wrinkle"] else "wrinkle"}
        summary = {"status": "buckled", "critical": {"time": t["wrinkle"], "applied_strain": 0.6 * t["wrinkle"],
                                                     "first_mode_wrinkle_count": 1.0, "growth_um": 400.0},
                   "reduced": {"time": t["wrinkle"] - 1e-3},
                   "creases": {"onset": {"time": t["crease"], "time_error": 1e-4, "applied_strain": 0.6 * t["crease"],
                                         "applied_strain_error": 6e-5},
                               "levels": [{"depth_mm": 0.09}, {"depth_mm": 0.1}],
                               "film_onset": {"onset": {"time": t["film"], "time_error": 2e-4}}, "first": first}}
        if MPI.COMM_WORLD.rank == 0:
            case.outdir.mkdir(parents=True)
            (case.outdir / "summary.json").write_text(json.dumps(summary))
    MPI.COMM_WORLD.barrier()
    rows = studies.collect(cases, spec.param)
    assert [(r["first_least_energy"], r["first_nucleation"]) for r in rows] == \
        [("crease", "crease"), ("crease", "wrinkle"), ("wrinkle", "wrinkle")]
    assert rows[2]["crease_strain"] == pytest.approx(0.18) and rows[0]["crease_depth_mm"] == 0.1
    assert rows[0]["film_crease_t"] == 0.59 and rows[0]["t_reduced"] == pytest.approx(0.649)
    found = studies.crossovers(rows)
    assert found["least_energy"] == pytest.approx(3.0) and found["nucleation"] == pytest.approx(1.4)
    if MPI.COMM_WORLD.rank == 0:
        studies.write_tables(rows, shared_tmp / "creases", "test", spec.param)
        (shared_tmp / "tables-creases").mkdir()
        (shared_tmp / "creases").rename(shared_tmp / "tables-creases" / "bilayer-creases")
    MPI.COMM_WORLD.barrier()
    capsys.readouterr()
    assert cli.main(["study", "--tables", str(shared_tmp / "tables-creases")]) == 0
    out = capsys.readouterr().out
    assert "| - | 2 | buckled | 0.3000 | 0.5000 | 0.4990 | 0.2400 | 0.0001 | 0.100 | 0.4000 | 0.5900 | 0.0002 | " \
        "crease | wrinkle | - |" in out
    assert "Crossover by least energy (" in out and "modulus_ratio = 3\n" in out and "modulus_ratio = 1.4\n" in out


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size < 2, reason="groups of ranks need several ranks")
def test_rank_groups_give_the_same_results_as_one_by_one(shared_tmp):
    """Cases on 2-rank groups (each case distributed) against the same cases run side by side on one
    rank each: the same g_c (distributed and serial arithmetic agree to ~1e-9) and N_c."""
    world = MPI.COMM_WORLD
    grouped, _ = _sweep(shared_tmp / "groups2", world, "material.film.modulus_ratio", [5.0, 9.0], ranks_per_case=2)
    alone, cases = _sweep(shared_tmp / "groups1", world, "material.film.modulus_ratio", [5.0, 9.0])
    assert [r["status"] for r in grouped] == [r["status"] for r in alone] == ["buckled", "buckled"]
    assert [json.loads((c.outdir / "summary.json").read_text())["ranks"] for c in cases] == [1, 1]
    assert [json.loads((shared_tmp / "groups2" / r["directory"] / "summary.json").read_text())["ranks"]
            for r in grouped] == [2, 2]
    assert _g(grouped) == pytest.approx(_g(alone), rel=1e-6)
    assert [r["N_c"] for r in grouped] == [r["N_c"] for r in alone]


def test_trends_film_thickness_and_modulus_ratio(shared_tmp, comm):
    """Paper: g_c rises with the film thickness and falls with the modulus ratio."""
    rows, _ = _sweep(shared_tmp / "w", comm, "geometry.film_thickness", [0.008, 0.016],
                     overrides=["mesh.element_size=0.004"])
    assert rows[0]["g_c_um"] < rows[1]["g_c_um"]
    # the wavelength scales with the film thickness (l_c = 2 pi w (Ef/3Es)^(1/3)): twice the film,
    # about half the wrinkles
    assert rows[0]["N_c"] > rows[1]["N_c"]
    assert 1.5 <= rows[0]["N_c"] / rows[1]["N_c"] <= 2.5
    rows, _ = _sweep(shared_tmp / "ratio", comm, "material.film.modulus_ratio", [4.0, 20.0])
    assert rows[0]["g_c_um"] > rows[1]["g_c_um"]
    # l_c ~ (Ef/Es)^(1/3): a 5x stiffer film wrinkles with a 1.7x longer wavelength, fewer wrinkles
    assert rows[0]["N_c"] > rows[1]["N_c"]


def test_trend_tube_substrate_thickness(shared_tmp, comm):
    """Paper: in tubes g_c falls as the substrate thickness grows."""
    rows, _ = _sweep(shared_tmp / "H", comm, "geometry.substrate_thickness", [0.04, 0.1], base=SMALL_TUBE)
    assert rows[0]["g_c_um"] > rows[1]["g_c_um"]
    assert json.loads((shared_tmp / "H" / rows[0]["directory"] / "summary.json").read_text())["status"] == "buckled"


def test_isomodes_record_later_crossings_in_order(shared_tmp, comm):
    """Each crossing the bisection located must agree with the per-step inertia in history.csv:
    before crossing k's time the count of negative eigenvalues is below k, from the first step after
    it on at least k."""
    import csv

    out = shared_tmp / "iso"
    cases = studies.build_cases(SWELLING, "geometry.film_thickness", [0.008, 0.012], out,
                                ["stability.max_crossings=3"], isomodes=True)
    rows = studies.run_study(cases, out, comm, "test", "geometry.film_thickness")
    for r, case in zip(rows, cases):
        summary = json.loads((case.outdir / "summary.json").read_text())
        crossings = summary["crossings"]
        assert len(crossings) == 3
        times = [c["time"] for c in crossings]
        assert times == sorted(times)
        with open(case.outdir / "history.csv") as f:
            history = [(float(h["time"]), int(h["negative_eigenvalues"])) for h in csv.DictReader(f)]
        for k, c in enumerate(crossings, start=1):
            lo, hi = c["bracket"]
            assert all(n < k for t, n in history if t <= lo)
            assert all(n >= k for t, n in history if t >= hi)
        assert len(r["crossings"].split(";")) == 3
    assert (out / "isomodes.png").stat().st_size > 0
