"""`tid-jax frf` and `tid-jax retune` on a [structure] config: files, JSON, and one-line
errors that name the key."""

import json
import math

import numpy as np
import pytest

import tid_jax as tj
from tests.cli.test_main import FRF_ARRAYS, run
from tests.reference import building_linear
from tid_jax._runtime._outcomes import outcome_code, outcome_message

CONFIG = """
inertance = 275.0
friction_force = 135.0
amplitudes = ["0.1g", 2.0]
n_frequencies = 7

[structure]
storey_masses = [2000.0, 2000.0, 1500.0]
storey_stiffnesses = [1.5e6, 1.25e6, 1.0e6]
damping_ratio = 0.02

[tid]
spring_floor = 1
inerter_floor = 0

[load]
on = "ground"

[response]
kind = "drift"
floor = 1
"""


def _config(tmp_path, text=CONFIG):
    path = tmp_path / "building.toml"
    path.write_text(text)
    return path


def test_frf_of_a_building_writes_its_files_and_json(tmp_path):
    out = tmp_path / "out"
    status, stdout, stderr = run(["frf", "--config", _config(tmp_path), "--out", out, "--json",
                                  "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    for name in ("frf.csv", "frf.json", "frf.png", "frf_config.toml"):
        assert (out / name).stat().st_size > 0
    response = np.asarray(data["response_max"])
    assert response.shape == (2, 7) and len(data["frequencies_hz"]) == 7
    assert np.all(data["converged"]) and np.asarray(data["y_max_m"]).shape == (2, 7)
    assert data["response"] == {"kind": "drift", "floor": 1, "unit": "m",
                                "describes": "storey 1 drift"}
    assert data["amplitudes"][0] == pytest.approx(0.980665)
    assert data["amplitude_unit"] == "m/s2" and data["response_unit"] == "m"
    # the arrays the paper's host writes too (`test_main`)
    assert FRF_ARRAYS <= data.keys()
    # its rows: the same values, the unit of each, stroke and status
    rows = data["results"]
    assert len(rows) == 14 and {r["amplitude_unit"] for r in rows} == {"m/s2"}
    assert [r["peak"] for r in rows] == np.asarray(data["response_max"]).ravel().tolist()
    assert [r["stroke_m"] for r in rows] == np.asarray(data["y_max_m"]).ravel().tolist()
    assert all(r["status"].startswith("ok") and r["x_over_A_K"] is None for r in rows)
    # the TID lowers the peak over the band below the bare structure's
    assert np.all(response.max(axis=1) < 0.9 * np.asarray(data["uncontrolled"]).max(axis=1))
    # the band's default is around the first mode
    M, K = building_linear.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6])
    first = building_linear.natural_frequencies(M, K)[0][0] / (2 * np.pi)
    assert data["frequencies_hz"][0] == pytest.approx(0.5 * first)
    # the config written reruns the same case
    status, again, _ = run(["frf", "--config", out / "frf_config.toml", "--out",
                            tmp_path / "again", "--json", "--quiet"])
    assert status == 0 and json.loads(again)["response_max"] == data["response_max"]


def test_frf_of_a_building_with_a_compliant_device_is_the_library_s(tmp_path):
    import tid_jax as tj

    device = "terminal_mass = 20.0\nseries_stiffness = 2e6\nbacklash = 1e-4\n"
    text = device + CONFIG.replace("n_frequencies = 7", "n_frequencies = 5")
    status, stdout, stderr = run(["frf", "--config", _config(tmp_path, text), "--out",
                                  tmp_path / "out", "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    assert data["tid"]["series_stiffness_N_per_m"] == 2e6 and data["tid"]["backlash_m"] == 1e-4
    system = tj.BuildingTID(
        tj.Structure.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6],
                                    damping_ratio=0.02),
        275.0, 135.0, 1.0, 0.0, None, load="ground",
        terminal_mass=20.0, series_stiffness=2e6, backlash=1e-4)
    k, c = tj.first_mode_tunings(system)["den_hartog"]  # the command's default tuning
    system = system.replace(tid_stiffness=k, tid_damping=c)
    mine = tj.frequency_response(system, 2 * np.pi * np.asarray(data["frequencies_hz"]),
                                 data["amplitudes"], quantity=tj.Quantity("drift", 1))
    ok = np.asarray(data["converged"])
    assert ok.sum() >= 8 and np.array_equal(ok, mine.converged)
    np.testing.assert_allclose(np.asarray(data["response_max"], float)[ok],
                               mine.x_max[ok], rtol=1e-9)


@pytest.mark.parametrize("change, message", [
    (("storey_stiffnesses = [1.5e6, 1.25e6, 1.0e6]", "storey_stiffnesses = [1.5e6, 1.0e6]"),
     "storey_stiffnesses"),
    (("storey_stiffnesses = [1.5e6, 1.25e6, 1.0e6]", "storey_stiffnesses = [1.5e6, -1, 1.0e6]"),
     "storey_stiffnesses"),
    (("spring_floor = 1", "spring_floor = 5"), "spring_floor"),
    (("kind = \"drift\"\nfloor = 1", "kind = \"drift\"\nfloor = 7"), "response floor"),
    (("kind = \"drift\"", "kind = \"velocity\""), "response kind"),
    (("on = \"ground\"", "on = \"wind\""), "load"),
    (("damping_ratio = 0.02", "damping = 0.02"), "damping"),
    (("damping_ratio = 0.02", "mass_matrix = [[1.0, 2.0], [0.0, 1.0]]\nstiffness_matrix = "
      "[[1.0, 0.0], [0.0, 1.0]]\ndamping_matrix = [[0.0, 0.0], [0.0, 0.0]]"), "symmetric"),
    (("amplitudes = [\"0.1g\", 2.0]", "amplitudes = [\"much\"]"), "amplitudes"),
    (("inertance = 275.0", "inertance = 275.0\nseries_stiffness = 2e6"), "terminal_mass"),
    (("inertance = 275.0", "inertance = 275.0\nhost_stiffness = 2e6"), "host_stiffness"),
])
def test_bad_building_configs_get_one_line_naming_the_key(tmp_path, change, message):
    path = _config(tmp_path, CONFIG.replace(*change))
    status, stdout, stderr = run(["frf", "--config", path, "--out", tmp_path / "out"])
    assert status == 2 and stdout == ""
    assert len(stderr.strip().splitlines()) == 1 and message in stderr
    assert not (tmp_path / "out" / "frf.json").exists()


def test_rtds_of_a_building_is_the_library_s_test(tmp_path):
    import tid_jax as tj

    text = CONFIG.replace('amplitudes = ["0.1g", 2.0]', 'amplitudes = ["0.1g"]')
    out = tmp_path / "out"
    status, stdout, stderr = run(["rtds", "--config", _config(tmp_path, text), "--out", out,
                                  "--frequency-hz", "2.0", "--delay-ms", "5", "--periods",
                                  "20", "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    system = tj.BuildingTID(
        tj.Structure.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6],
                                    damping_ratio=0.02),
        275.0, 135.0, 1.0, 0.0, None, load="ground")
    k, c = tj.first_mode_tunings(system)["den_hartog"]  # the command's default tuning
    mine = tj.simulate_substructuring(system.replace(tid_stiffness=k, tid_damping=c),
                                      2 * np.pi * 2.0, 0.980665, quantity=tj.Quantity("drift", 1),
                                      delay=0.005, periods=20)
    assert data["response_test"] == pytest.approx([float(mine.x_max)], rel=1e-9)
    assert data["stroke_whole_m"] == pytest.approx([float(mine.reference_y_max)], rel=1e-9)
    assert data["stable"] == [True] and data["response"]["describes"] == "storey 1 drift"
    assert data["test"]["amplitude"] == pytest.approx(0.980665)
    for name in ("rtds.csv", "rtds.json", "rtds.png", "rtds_config.toml"):
        assert (out / name).stat().st_size > 0
    # a building needs its amplitude: the ground motion's has no default
    status, _, stderr = run(["rtds", "--config", _config(tmp_path, text.replace(
        'amplitudes = ["0.1g"]\n', "")), "--out", tmp_path / "other"])
    assert status == 2 and "amplitude" in stderr and len(stderr.strip().splitlines()) == 1


def test_sensitivity_of_a_building_names_every_floor_and_storey(tmp_path):
    import jax.numpy as jnp

    import tid_jax as tj

    out = tmp_path / "out"
    text = CONFIG.replace('amplitudes = ["0.1g", 2.0]', "amplitudes = [2.0]").replace(
        "n_frequencies = 7", "n_frequencies = 31")
    status, stdout, stderr = run(["sensitivity", "--config", _config(tmp_path, text),
                                  "--out", out, "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    records = {r["parameter"]: r for r in data["results"]}
    names = {"tid_stiffness", "tid_damping", "inertance", "friction_force", "amplitude"}
    names |= {f"floor_mass_{i}" for i in (1, 2, 3)}
    names |= {f"storey_stiffness_{i}" for i in (1, 2, 3)}
    assert names <= set(records) and all(r["converged"] for r in records.values())
    assert records["storey_stiffness_2"]["value"] == pytest.approx(1.25e6)
    assert records["floor_mass_3"]["unit"] == "kg" and records["amplitude"]["unit"] == "m/s2"
    # the library's elasticities, at the tuning the command reports
    system = tj.BuildingTID(
        tj.Structure.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6],
                                    damping_ratio=0.02),
        275.0, 135.0, data["tid_stiffness_N_per_m"], data["tid_damping_N_s_per_m"],
        load="ground")
    (mine,) = tj.amplitude_sensitivities(system, [2.0], quantity=tj.Quantity("drift", 1),
                                         optimum=False)
    for j, name in enumerate(mine.parameters):
        assert records[name]["elasticity"] == pytest.approx(
            float(jnp.asarray(mine.host_elasticity)[j]), rel=1e-6, abs=1e-9)
        record = records[name]
        if record["value"]:
            assert record["derivative_per_unit"] == pytest.approx(
                record["elasticity"] * record["peak"] / record["value"])
    # and at the retuned optimum, which does not depend on the given tuning
    optimum = records["amplitude"]
    assert optimum["optimum_converged"] and optimum["optimum_peak"] < optimum["peak"]
    assert records["tid_stiffness"]["optimum_elasticity"] == 0.0
    assert all(math.isfinite(r["optimum_stiffness_elasticity"]) for r in records.values())
    for name in ("sensitivity.csv", "sensitivity.json", "sensitivity.png",
                 "sensitivity_config.toml"):
        assert (out / name).exists()


def test_retune_of_a_frictionless_building_keeps_k_and_c_in_json(tmp_path):
    text = CONFIG.replace("friction_force = 135.0", "friction_force = 0.0")
    out = tmp_path / "out"
    status, stdout, stderr = run(["retune", "--config", _config(tmp_path, text), "--out", out,
                                  "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    results = data["results"]
    assert len(results) == 2 and all(r["converged"] for r in results)
    # the first mode's H-infinity tuning, over the same band
    system = tj.BuildingTID(tj.Structure.shear_building(
        [2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6], damping_ratio=0.02), 275.0, 0.0,
        1.0, 0.0, load="ground")
    k, c = tj.first_mode_tunings(system)["h_infinity"]
    h_infinity_peaks = tj.peaks(system.replace(tid_stiffness=k, tid_damping=c),
                                2 * np.pi * np.asarray(data["frequencies_hz"]),
                                [r["amplitude"] for r in results],
                                quantity=tj.Quantity("drift", 1)).x_peak
    for r, h_infinity in zip(results, np.asarray(h_infinity_peaks), strict=True):
        assert r["k_N_per_m"] > 0 and r["c_N_s_per_m"] > 0 and r["status"].startswith("ok")
        assert r["peak_after"] <= h_infinity * (1 + 1e-6)
        assert r["peak_after"] <= r["peak_before"] * (1 + 1e-9)  # below Den Hartog's
        assert r["peak_before"] == pytest.approx(r["peak_after"] / r["peak_after_over_before"])
        assert r["stroke_after_m"] > 0 and r["amplitude_unit"] == "m/s2"
    # frictionless: the tuning does not depend on the amplitude, the peak and the stroke
    # are proportional
    assert results[0]["k_N_per_m"] == pytest.approx(results[1]["k_N_per_m"], rel=1e-3)
    assert results[1]["peak_after"] / results[0]["peak_after"] == pytest.approx(
        2.0 / 0.980665, rel=1e-6)
    assert results[1]["stroke_after_m"] / results[0]["stroke_after_m"] == pytest.approx(
        2.0 / 0.980665, rel=1e-3)
    for name in ("retune.csv", "retune.json", "retune_summary.png",
                 "retune_frequency_response.png", "retune_config.toml"):
        assert (out / name).stat().st_size > 0


def test_robust_tuning_of_a_building_holds_for_stiffer_and_softer_structures(tmp_path):
    out = tmp_path / "out"
    text = CONFIG.replace('amplitudes = ["0.1g", 2.0]', "amplitudes = [2.0]")
    status, stdout, stderr = run(["robust", "--config", _config(tmp_path, text), "--out", out,
                                  "--host-frequency-tolerance", "0.05", "--json", "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    robust, records = data["robust"], data["results"]
    # the default 0.07 m limit is active at 2 m/s2 and every scenario's stroke keeps it
    # (aimed 0.5% inside it)
    assert robust["converged"] and robust["stroke_limit_m"] == 0.07
    assert robust["max_stroke_m"] == pytest.approx(0.07, rel=1e-2)
    assert robust["max_stroke_m"] <= 0.07
    assert all(r["stroke_after_m"] <= robust["max_stroke_m"] for r in records)
    assert [r["frequency_scale"] for r in records] == pytest.approx([0.95, 1.0, 1.05])
    ratios = [r["peak_after_over_best"] for r in records]
    assert min(ratios) >= 1 - 1e-6 and robust["worst_ratio"] == pytest.approx(max(ratios))
    # (the given tuning's strokes are not limited: its worst ratio, 1.44, is no bound on
    # the limited design's, 2.59)
    assert robust["worst_ratio"] > 1.0
    for r in records:
        assert r["peak_after"] == pytest.approx(r["peak_after_over_best"] * r["peak_best"])
        assert r["stroke_after_m"] > 0 and r["status"].startswith("ok")
    for name in ("robust.csv", "robust.json", "robust.png", "robust_config.toml"):
        assert (out / name).exists()


def test_building_rows_say_the_result_s_outcome_as_host_rows_do(tmp_path):
    # frictionless, a band below the first mode (2 Hz): the retuned peak at its upper end,
    # which an ever stiffer spring lowers (no optimum); a stroke limit of 0.1 mm
    text = CONFIG.replace("friction_force = 135.0", "friction_force = 0.0").replace(
        'amplitudes = ["0.1g", 2.0]', "amplitudes = [2.0]")
    edge = outcome_message(tj.Outcome, outcome_code(tj.Outcome.not_stationary))
    status, stdout, stderr = run(["retune", "--config", _config(
        tmp_path, text.replace("n_frequencies = 7", "n_frequencies = 7\nband_hz = [1.0, 1.5]")),
        "--out", tmp_path / "retune", "--json", "--quiet"])
    assert status == 0, stderr
    (record,) = json.loads(stdout)["results"]
    assert not record["converged"] and record["status"].split("; ")[0] == edge
    assert record["peak_frequency_after_Hz"] == pytest.approx(1.5)
    over = outcome_message(tj.Outcome, outcome_code(tj.Outcome.stroke_over_limit))
    status, stdout, stderr = run(["robust", "--config", _config(
        tmp_path, "stroke_limit = 1e-4\n" + text), "--out", tmp_path / "robust", "--json",
        "--quiet"])
    assert status == 0, stderr
    data = json.loads(stdout)
    # only a TID that braces the structure keeps it: the search ends without a stationary
    # point (or with the stroke over the limit); every row says the design's outcome
    stalled = outcome_message(tj.Outcome, outcome_code(tj.Outcome.not_stationary))
    robust = data["robust"]
    assert not robust["converged"] and robust["status"] in (over, stalled)
    assert all(not r["converged"] and r["status"].split("; ")[0] == robust["status"]
               for r in data["results"])
