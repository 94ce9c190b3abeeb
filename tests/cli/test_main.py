"""The `tid-jax` command line, run for real on small grids: `main(argv)` in-process (so the
compiled solvers are shared between tests) and the installed console script once."""

import contextlib
import csv
import io
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest

import tid_jax as tj
from tid_jax._runtime import _io
from tid_jax.cli import main
from tid_jax.cli.frf import FRF_COLUMNS
from tid_jax.cli.retune import RETUNE_COLUMNS

FRF_ARGS = ["frf", "--amplitudes", "200", "600", "--band-hz", "3", "5", "--n-frequencies", "5"]
FRF_FILES = ("frf.csv", "frf.json", "frf.png", "frf_config.toml")
RETUNE_FILES = (
    "retune.csv",
    "retune.json",
    "retune_config.toml",
    "retune_frequency_response.png",
    "retune_summary.png",
)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

FRF_ARRAYS = {"amplitudes", "amplitude_unit", "response_unit", "response_max", "uncontrolled",
              "y_max_m", "converged", "stable", "stick_fraction", "transitions"}


def run(argv):
    """`main(argv)` with stdout and stderr captured: `(exit status, stdout, stderr)`."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([str(arg) for arg in argv])
    return status, out.getvalue(), err.getvalue()


def read_csv(path):
    with open(path, newline="") as file:
        rows = list(csv.reader(file))
    return rows[0], rows[1:]


def leftovers(folder):
    """Temporary files of interrupted atomic writes."""
    return sorted(p.name for p in pathlib.Path(folder).iterdir() if p.name.endswith(".tmp"))


@pytest.fixture(scope="module")
def frf_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("frf")
    status, stdout, stderr = run([*FRF_ARGS, "--out", out, "--json"])
    return status, stdout, stderr, out


@pytest.fixture(scope="module")
def retune_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("retune")
    config = folder / "system.toml"
    config.write_text(
        "# the paper's device on a 2000 kg host\n"
        "host_mass = 2000.0\nhost_frequency_hz = 4.0\nhost_damping_ratio = 0.02\n"
        "inertance = 100.0\nfriction_force = 20.0\n"
        "amplitudes = [200.0, 600.0]\nband_hz = [3.2, 4.8]\nn_frequencies = 21\n"
        "stroke_limit = 0.005\n"
    )
    out = folder / "out"
    status, stdout, stderr = run(["retune", "--config", config, "--out", out])
    return status, stdout, stderr, out


# --- frf ------------------------------------------------------------------------------------


def test_frf_writes_parsable_files(frf_run):
    status, _, _, out = frf_run
    assert status == 0
    for name in FRF_FILES:
        assert (out / name).stat().st_size > 0
    assert (out / "frf.png").read_bytes()[:8] == PNG_SIGNATURE
    header, rows = read_csv(out / "frf.csv")
    assert tuple(header) == FRF_COLUMNS
    assert len(rows) == 2 * 5
    table = {
        name: np.array([float(row[i]) for row in rows])
        for i, name in enumerate(header)
        if name not in ("converged", "stable", "amplitude_unit", "peak_unit", "status")
    }
    assert set(table["amplitude"]) == {200.0, 600.0}
    np.testing.assert_allclose(np.unique(table["frequency_Hz"]), np.linspace(3, 5, 5))
    stiffness = tj.paper_system().host_stiffness
    np.testing.assert_allclose(
        table["x_over_A_K"], table["peak"] / (table["amplitude"] / stiffness)
    )
    np.testing.assert_allclose(table["stroke_m"], table["y_over_A_K"] * table["amplitude"]
                               / stiffness)
    assert all(row[header.index("converged")] == "True" for row in rows)
    assert {row[header.index("amplitude_unit")] for row in rows} == {"N"}
    assert all(row[header.index("status")] == "ok" for row in rows)
    assert leftovers(out) == []


# In a fresh process: the command `argv`, then the library on the same system, band and
# amplitude, with the default settings and with those of the command's JSON record; prints
# the command's exit status, that record's settings and the compilation events of JAX
# (`jax.monitoring`: tracing for jit, lowering, compiling) of the library calls.
LIBRARY_AFTER_COMMAND = """
import json, pathlib, sys

from tid_jax.cli import main

status = main(sys.argv[1:])

import jax
import numpy as np
import tid_jax as tj

solver = json.loads((pathlib.Path(sys.argv[-1]) / "frf.json").read_text())["solver"]
compiled = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kwargs: compiled.append(event)
    if event.startswith("/jax/core/compile/") else None)
for settings in (tj.SolverSettings(), tj.SolverSettings(**solver)):
    tj.frequency_response(tj.paper_system(), 2 * np.pi * np.linspace(3, 5, 5), [200.0],
                          settings=settings)
print(json.dumps({"status": status, "solver": solver, "compiled": compiled}))
"""


def test_commands_compile_the_programs_of_library_calls(tmp_path):
    # The settings reach the compiled programs as a library call with the same settings
    # passes them, fitted to the system's model as the JSON records them: in a process
    # that holds no program yet (this session's cache on disk), a library call after the
    # command, with the settings as given or as recorded, traces and compiles nothing.
    argv = ["frf", "--amplitudes", "200", "--band-hz", "3", "5", "--n-frequencies", "5",
            "--quiet", "--out", tmp_path]
    done = subprocess.run([sys.executable, "-c", LIBRARY_AFTER_COMMAND, *map(str, argv)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    record = json.loads(done.stdout.splitlines()[-1])
    assert record["status"] == 0
    assert record["solver"] == tj.SolverSettings().for_system(tj.paper_system()).to_dict()
    assert record["compiled"] == []


def test_frf_json_on_stdout_is_the_saved_json_and_rebuilds_the_system(frf_run):
    status, stdout, _, out = frf_run
    printed = json.loads(stdout)
    assert printed == json.loads((out / "frf.json").read_text())
    assert printed["version"] == tj.__version__
    assert printed["solver"] == tj.SolverSettings().for_system(tj.paper_system()).to_dict()
    system = tj.TIDSystem(**printed["system"])
    assert system.to_dict() == tj.paper_system().to_dict()
    assert printed["system"] == tj.paper_system().to_dict()
    # the saved peaks are the library's, for the saved system and frequencies
    omegas = 2 * np.pi * np.asarray(printed["frequencies_hz"])
    expected = tj.frequency_response(system, omegas, 600.0)
    np.testing.assert_allclose(printed["response_max"][1], expected.x_max, rtol=1e-10)
    assert FRF_ARRAYS <= printed.keys() and printed["response_unit"] == "m"
    np.testing.assert_allclose(printed["y_max_m"][1], expected.y_max, rtol=1e-10)


def test_frf_linear_columns_are_the_linear_receptance(frf_run):
    _, stdout, _, _ = frf_run
    data = json.loads(stdout)
    system = tj.paper_system()
    receptance = tj.linear_receptance(system, 2 * np.pi * np.asarray(data["frequencies_hz"]))
    stiffness = float(system.host_stiffness)
    np.testing.assert_allclose(data["x_linear_over_A_K"], np.abs(receptance.host) * stiffness)
    np.testing.assert_allclose(data["y_linear_over_A_K"], np.abs(receptance.inerter) * stiffness)


def test_frf_reports_progress_and_where_results_went(frf_run):
    _, _, stderr, out = frf_run
    assert "amplitude 1/2 (A = 200 N)" in stderr
    assert "amplitude 2/2 (A = 600 N)" in stderr
    assert f"results in {out}/" in stderr


def test_frf_reports_the_breakaway_amplitude(frf_run):
    _, stdout, _, _ = frf_run
    data = json.loads(stdout)
    system = tj.paper_system()
    omegas = 2 * np.pi * np.asarray(data["frequencies_hz"])
    expected = tj.breakaway_amplitude(system, omegas)
    np.testing.assert_allclose(data["breakaway_amplitude_N"], expected.amplitude, rtol=1e-12)
    assert data["breakaway_minimum_N"] == pytest.approx(float(expected.minimum), rel=1e-12)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize("quiet", [False, True])
def test_frf_progress_bar_on_a_terminal(tmp_path, quiet):
    out, err = io.StringIO(), _Terminal()
    argv = [*FRF_ARGS, "--out", tmp_path, *(["--quiet"] if quiet else [])]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main([str(arg) for arg in argv]) == 0
    stderr = err.getvalue()
    # The table ends with the breakaway amplitude.
    breakaway = tj.breakaway_amplitude(tj.paper_system(), 2 * np.pi * np.linspace(3, 5, 5))
    assert (f"Breakaway amplitude over the band: {float(breakaway.minimum):.4g} N"
            in out.getvalue())
    if quiet:
        assert stderr == ""
    else:
        # The bar at each step (one per amplitude), the messages above it.
        assert "1/2 [" in stderr and "2/2 [" in stderr
        assert "amplitude 2/2 (A = 600 N)" in stderr


def test_saved_config_reproduces_the_run(frf_run, tmp_path):
    _, stdout, _, out = frf_run
    config = tomllib.loads((out / "frf_config.toml").read_text())
    assert config["amplitudes"] == [200.0, 600.0]
    # the device in its own table
    assert config["inerter"] == {"inertance": 75.0, "friction_force": 20.0}
    assert config["band_hz"] == [3.0, 5.0]
    status, again, _ = run(
        ["frf", "--config", out / "frf_config.toml", "--out", tmp_path, "--json", "--quiet"]
    )
    assert status == 0
    first, second = json.loads(stdout), json.loads(again)
    for key in ("system", "solver", "frequencies_hz", "response_max", "y_max_m", "summary"):
        assert second[key] == first[key]


def test_flags_override_config_and_table_is_printed(frf_run, tmp_path):
    config = tmp_path / "mine.toml"
    config.write_text(
        "host_mass = 1000.0\nhost_frequency_hz = 3.0\nfriction_force = 5.0\n"
        "tid_damping = 400.0\namplitudes = [100.0, 200.0]\nband_hz = [3.0, 5.0]\n"
        "n_frequencies = 5\n"
    )
    stiffness = 9.0e5
    status, stdout, stderr = run(
        [
            "frf",
            "--config",
            config,
            "--host-mass",
            1500,
            "--host-stiffness",
            stiffness,
            "--amplitudes",
            300,
            700,
            "--out",
            tmp_path / "out",
            "--quiet",
        ]
    )
    assert status == 0
    assert stderr == ""
    lines = stdout.splitlines()
    assert lines[1].split()[:2] == ["A", "unit"] and lines[3].split()[:2] == ["300", "N"]
    assert [line.split()[0] for line in lines[3:-1]] == ["300", "700"]
    assert lines[-1].startswith("Breakaway amplitude over the band:")
    data = json.loads((tmp_path / "out" / "frf.json").read_text())
    k_dh, _ = tj.den_hartog_tuning(1500.0, stiffness, tj.paper_system().inertance)
    assert data["system"]["host_mass"] == 1500.0  # flag beats config
    assert data["system"]["host_stiffness"] == stiffness  # flag replaces host_frequency_hz
    assert data["system"]["friction_force"] == 5.0  # config beats default
    assert data["system"]["tid_damping"] == 400.0
    assert data["system"]["tid_stiffness"] == pytest.approx(float(k_dh))  # default
    assert data["amplitudes"] == [300.0, 700.0] and data["amplitude_unit"] == "N"
    assert "host_frequency_hz" not in data["inputs"]


# --- retune ---------------------------------------------------------------------------------


def test_retune_prints_the_table_and_writes_every_file(retune_run):
    status, stdout, stderr, out = retune_run
    assert status == 0
    for name in RETUNE_FILES:
        assert (out / name).stat().st_size > 0
    for name in RETUNE_FILES[3:]:
        assert (out / name).read_bytes()[:8] == PNG_SIGNATURE
    assert leftovers(out) == []
    lines = stdout.splitlines()
    assert "k/k_DH" in lines[1] and "c/c_DH" in lines[1] and "stroke [cm] (limit 0.5)" in lines[1]
    assert [line.split()[0] for line in lines[3:-1]] == ["200", "600"]
    assert lines[-1].startswith("With the initial tuning: Breakaway amplitude over the band:")
    assert "retune stage" in stderr and f"results in {out}/" in stderr


def test_retune_csv_and_json_agree_with_the_system(retune_run):
    _, stdout, _, out = retune_run
    header, rows = read_csv(out / "retune.csv")
    assert tuple(header) == RETUNE_COLUMNS
    data = json.loads((out / "retune.json").read_text())
    assert data["version"] == tj.__version__
    assert data["solver"] == tj.SolverSettings().for_system(tj.paper_system()).to_dict()
    assert data["inputs"]["host_mass"] == 2000.0
    system = tj.TIDSystem(**data["system"])
    assert system.host_mass == 2000.0 and system.inertance == 100.0
    assert float(system.host_frequency) == pytest.approx(2 * np.pi * 4.0)
    k_dh, c_dh = (float(v) for v in tj.den_hartog_tuning(2000.0, system.host_stiffness, 100.0))
    assert data["den_hartog"] == pytest.approx({"tid_stiffness": k_dh, "tid_damping": c_dh})
    assert len(data["results"]) == len(rows) == 2
    for record, row in zip(data["results"], rows, strict=True):
        assert [str(record[key]) for key in RETUNE_COLUMNS] == row
        assert record["k_over_k_den_hartog"] == pytest.approx(record["k_N_per_m"] / k_dh)
        assert record["c_over_c_den_hartog"] == pytest.approx(record["c_N_s_per_m"] / c_dh)
        assert record["stroke_limit_m"] == 0.005
        assert record["converged"] == record["status"].startswith("ok")
        # retuning lowers the host peak; friction makes it a stiffer, less damped TID
        assert record["x_peak_after_over_A_K"] < record["x_peak_before_over_A_K"]
        assert record["k_over_k_den_hartog"] > 1
        assert record["c_over_c_den_hartog"] < 1
    low, high = data["results"]
    # the stroke grows with amplitude: 200 N stays within 5 mm, 600 N does not
    assert low["within_stroke_limit"] and low["stroke_after_m"] <= 0.005
    assert not high["within_stroke_limit"] and high["stroke_after_m"] > 0.005
    assert "stroke over limit" not in low["status"] and "stroke over limit" in high["status"]
    assert low["c_over_c_den_hartog"] < high["c_over_c_den_hartog"]
    # the saved table prints as the stdout table
    assert f"{low['k_over_k_den_hartog']:.3f}" in stdout.splitlines()[3]


# --- bad input ------------------------------------------------------------------------------

BAD_TOML = 'host_mass = 1500\nfriction_force = "twenty\n'


@pytest.mark.parametrize(
    "argv, config, expected",
    [
        (["retune", "--host-mas", "1"], None, "unrecognized arguments: --host-mas"),
        (["frf", "--host-mass", "-1"], None, "host_mass must be finite and positive, got -1.0"),
        (["frf", "--host-mass", "heavy"], None, "argument --host-mass: invalid float value"),
        (
            ["frf", "--friction-force", "nan"],
            None,
            "friction_force must be finite and non-negative, got nan",
        ),
        (
            ["retune", "--amplitudes", "100", "-5"],
            None,
            "amplitudes must be finite and positive, got -5.0",
        ),
        (["frf", "--band-hz", "5", "3"], None, "band_hz is empty"),
        (["frf", "--band-hz", "4", "4"], None, "band_hz is empty"),
        (["frf", "--n-frequencies", "0"], None, "n_frequencies must be an integer >= 5, got 0"),
        (["fly"], None, "invalid choice: 'fly'"),
        (["frf"], BAD_TOML, "is not valid TOML"),
        (["frf"], "host_mas = 1500.0\n", "unknown key 'host_mas'"),
        (["frf"], "host_mass = 'heavy'\n", "host_mass must be a number, got 'heavy'"),
        (["frf"], "host_mass = -3.0\n", "host_mass must be finite and positive, got -3.0"),
        (["frf"], "band_hz = [4.0]\n", "band_hz must be two frequencies"),
        (["frf"], "host_frequency_hz = 4.0\nhost_stiffness = 1e6\n", "not both"),
        (["frf"], "[solver]\nrtoll = 1e-6\n", "unknown key 'rtoll' in [solver]"),
        (["frf"], "[solver]\nrtol = -1.0\n", "SolverSettings.rtol must be a positive number"),
        (["frf", "--series-stiffness", "3e5"], None, "needs terminal_mass > 0"),
        (["retune"], "series_stiffness = 3e5\n", "tid-jax retune needs terminal_mass > 0"),
        (["frf", "--series-stiffness", "0"], None, "series_stiffness must be finite and positive"),
        (["frf", "--backlash", "1e-4"], None, "backlash needs a finite series_stiffness"),
        (["frf", "--parasitic-damping", "-3"], None, "parasitic_damping must be finite and"),
        (["frf"], "[inerter]\nhost_mass = 1.0\n", "unknown key 'host_mass' in [inerter]"),
        (["frf"], "inerter = 75.0\n", "inerter must be a table [inerter]"),
        (["frf"], "inertance = 75.0\n[inerter]\ninertance = 70.0\n",
         "'inertance' is given both at the top level and in [inerter]"),
        (["frf"], "[inerter]\nbacklash = -1e-4\n", "backlash must be finite and non-negative"),
        (["frf", "--friction-width", "wide"], None,
         "argument --friction-width: must be a number (m/s) or 'relative', got 'wide'"),
        (["frf"], "friction_width = 'wide'\n", "friction_width must be a number, got 'wide'"),
        (["frf", "--friction-width", "-0.0001"], None,
         "friction_width must be finite and non-negative, got -0.0001"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, argv, config, expected):
    if config is not None:
        (tmp_path / "bad.toml").write_text(config)
        argv = [*argv, "--config", tmp_path / "bad.toml"]
    status, stdout, stderr = run([*argv, "--out", tmp_path / "out"])
    assert status == 2
    assert stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith("tid-jax: error: ")
    assert expected in stderr
    assert not (tmp_path / "out").exists()  # nothing computed, nothing written


def test_device_terms_from_config_and_flags(tmp_path):
    from tid_jax.cli._common import INPUT_KEYS, _inputs, _system

    args = type("Args", (), {key: None for key in INPUT_KEYS})()
    args.config = str(tmp_path / "device.toml")
    # the device's keys at the top level or in the [inerter] table
    for text in ("parasitic_damping = 300.0\nterminal_mass = 2.0\n",
                 "[inerter]\nparasitic_damping = 300.0\nterminal_mass = 2.0\n"):
        (tmp_path / "device.toml").write_text(text)
        args.terminal_mass = 3.0  # a flag overrides the file
        system = _system(_inputs(args))
        assert float(system.parasitic_damping) == 300.0 and float(system.terminal_mass) == 3.0
        assert system.rigid and float(system.backlash) == 0.0
    (tmp_path / "device.toml").write_text(
        "host_mass = 2000.0\n[inerter]\ninertance = 60.0\nfriction_force = 15.0\n"
        "terminal_mass = 2.0\nseries_stiffness = 3e5\nbacklash = 1e-4\n")
    args.terminal_mass = None
    system = _system(_inputs(args))
    assert float(system.host_mass) == 2000.0 and float(system.inertance) == 60.0
    assert float(system.friction_force) == 15.0 and float(system.series_stiffness) == 3e5
    assert system.compliant and float(system.backlash) == 1e-4


def test_friction_width_defaults_and_the_relative_width(tmp_path):
    from tid_jax.cli._common import INPUT_KEYS, _inputs, _system

    args = type("Args", (), {key: None for key in INPUT_KEYS})()
    args.config = None
    # a rigid device: exact Coulomb friction by default
    system = _system(_inputs(args))
    assert system.exact_friction and float(system.friction_width) == 0.0
    args.friction_width = "relative"
    system = _system(_inputs(args))
    assert system.friction_width is None and not system.exact_friction
    args.friction_width = 1e-4
    assert float(_system(_inputs(args)).friction_width) == 1e-4
    # the same from a config file; a compliant device's default is the relative width
    args.friction_width = None
    args.config = str(tmp_path / "width.toml")
    (tmp_path / "width.toml").write_text("[inerter]\nfriction_width = 'relative'\n")
    assert _system(_inputs(args)).friction_width is None
    (tmp_path / "width.toml").write_text("terminal_mass = 2.0\nseries_stiffness = 3e5\n")
    system = _system(_inputs(args))
    assert system.compliant and system.friction_width is None


def test_missing_config_file(tmp_path):
    status, _, stderr = run(["frf", "--config", tmp_path / "none.toml"])
    assert status == 2
    assert (
        stderr == f"tid-jax: error: cannot read config {tmp_path / 'none.toml'}: "
        "No such file or directory\n"
    )


@pytest.mark.parametrize("below", ["a-file", "a-file/sub"])
def test_unwritable_output_folder(tmp_path, below):
    (tmp_path / "a-file").write_text("not a folder")
    status, stdout, stderr = run([*FRF_ARGS, "--out", tmp_path / below])
    assert status == 2 and stdout == ""
    assert stderr.count("\n") == 1
    assert stderr.startswith(f"tid-jax: error: output folder {tmp_path / below} is ")
    assert (tmp_path / "a-file").read_text() == "not a folder"


@pytest.mark.parametrize("argv", [["--help"], ["retune", "--help"], ["frf", "--help"]])
def test_help(argv):
    status, stdout, stderr = run(argv)
    assert status == 0 and stderr == ""
    assert stdout.startswith("usage: tid-jax")
    if argv[0] != "--help":
        for flag in ("--config", "--host-frequency-hz", "--band-hz", "--out", "--json"):
            assert flag in stdout


# --- atomic files ---------------------------------------------------------------------------


def test_interrupted_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    path = _io.write_csv(tmp_path / "table.csv", ["a", "b"], [[1, 2], [3, 4]])
    before = path.read_text()

    def write_half_then_interrupt(self, text, *args, **kwargs):
        with open(self, "w") as file:
            file.write(text[: len(text) // 2])
        raise KeyboardInterrupt

    monkeypatch.setattr(pathlib.Path, "write_text", write_half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        _io.write_csv(path, ["a", "b"], [[5, 6], [7, 8]] * 100)
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_interrupted_run_leaves_only_complete_files(frf_run, tmp_path, monkeypatch):
    _, _, _, previous = frf_run
    out = tmp_path / "out"
    shutil.copytree(previous, out)
    old = {name: (out / name).read_bytes() for name in FRF_FILES}
    replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        if pathlib.Path(dst).parent == out:
            calls.append(dst)
            if len(calls) == 2:
                raise KeyboardInterrupt
        replace(src, dst)

    monkeypatch.setattr(os, "replace", replace_then_interrupt)
    argv = ["frf", "--amplitudes", "200", "250", "--band-hz", "3", "5", "--n-frequencies", "5"]
    status, _, stderr = run([*argv, "--out", out])
    assert status == 130
    assert stderr.splitlines()[-1].startswith("tid-jax: interrupted")
    assert leftovers(out) == []
    assert sorted(p.name for p in out.iterdir()) == sorted(FRF_FILES)
    written, interrupted = (pathlib.Path(p).name for p in calls)
    assert "250.0" in (out / written).read_text()  # renamed into place whole
    assert (out / interrupted).read_bytes() == old[interrupted]  # untouched
    for name in set(FRF_FILES) - {written, interrupted}:
        assert (out / name).read_bytes() == old[name]


# --- the installed console script -----------------------------------------------------------


def console_script():
    script = shutil.which("tid-jax", path=os.path.dirname(sys.executable))
    if script is None:
        pytest.fail("console script tid-jax is not installed beside this Python")
    return script


def test_console_script_runs_and_fails_cleanly(tmp_path):
    script = console_script()
    argv = [
        script,
        "frf",
        "--amplitudes",
        "200",
        "--band-hz",
        "3",
        "5",
        "--n-frequencies",
        "5",
        "--out",
        tmp_path,
        "--json",
        "--quiet",
    ]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["amplitudes"] == [200.0]
    assert all((tmp_path / name).exists() for name in FRF_FILES)
    bad = subprocess.run(
        [script, "retune", "--inertance", "-75"], capture_output=True, text=True, timeout=300
    )
    assert bad.returncode == 2
    assert bad.stderr == "tid-jax: error: inertance must be finite and positive, got -75.0\n"
    assert "Traceback" not in bad.stderr



def test_a_refused_command_leaves_no_worker_processes():
    # A command that maps lanes starts its worker processes before its arguments are
    # judged: refused, it waits for them to end, so that none outlives it (holding its
    # output open, this run would not end).
    done = subprocess.run([console_script(), "retune", "--workers", "2", "--bogus"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.startswith("tid-jax: error: unrecognized arguments: --bogus")


# --- the README's quick start and example ---------------------------------------------------

ROOT = pathlib.Path(__file__).resolve().parents[2]


def readme_blocks(heading):
    """The fenced code blocks under the `## heading` section of README.md."""
    text = (ROOT / "README.md").read_text()
    section = text.split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    return [block.split("\n", 1)[1] for block in section.split("```")[1::2]]


def test_quick_start_is_two_commands_and_ci_runs_the_second():
    (block,) = readme_blocks("Quick start")
    install_and_retune, install_and_test = block.strip().splitlines()
    assert install_and_retune.endswith("pip install -e . && tid-jax retune")
    assert install_and_test.endswith("python -m pytest")
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert install_and_test in ci


def test_readme_example_uses_the_public_api():
    (example,) = readme_blocks("Python example")
    code = compile(example, "README.md", "exec")
    assert len(example.strip().splitlines()) <= 10
    names = {name for name in code.co_names if hasattr(tj, name)}
    assert {"paper_system", "retune", "frequency_response", "default_omegas"} <= names


def test_compilation_cache_is_filled_and_can_be_turned_off(tmp_path):
    # The console script saves its compiled programs in --cache-dir (or $TID_JAX_CACHE_DIR),
    # so that a second run compiles nothing; --no-cache saves none.
    script = console_script()
    argv = [script, "frf", "--amplitudes", "200", "--band-hz", "3", "5", "--n-frequencies",
            "5", "--quiet"]
    cache = tmp_path / "cache"
    done = subprocess.run(argv + ["--out", tmp_path / "a", "--cache-dir", cache],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert any(cache.iterdir()) and any((cache / "programs").iterdir())
    # The cache moved to where $TID_JAX_CACHE_DIR points: a run there uses its traced
    # programs (marked used) and traces none.
    moved = tmp_path / "moved"
    shutil.copytree(cache, moved)
    programs = sorted((moved / "programs").iterdir())
    for path in programs:
        os.utime(path, (time.time() - 3600,) * 2)
    environment = dict(os.environ, TID_JAX_CACHE_DIR=str(moved))
    done = subprocess.run(argv + ["--out", tmp_path / "b"], capture_output=True, text=True,
                          timeout=300, env=environment)
    assert done.returncode == 0, done.stderr
    assert sorted((moved / "programs").iterdir()) == programs
    assert all(path.stat().st_mtime > time.time() - 600 for path in programs)
    off = tmp_path / "off"
    environment = dict(os.environ, TID_JAX_CACHE_DIR=str(off))
    done = subprocess.run(argv + ["--out", tmp_path / "c", "--no-cache"], capture_output=True,
                          text=True, timeout=300, env=environment)
    assert done.returncode == 0, done.stderr
    assert not off.exists()


@pytest.mark.parametrize("value", ["off", "0", ""])
def test_cache_environment_variable_turns_the_cache_off(monkeypatch, value):
    monkeypatch.setenv("TID_JAX_CACHE_DIR", value)
    assert tj.default_cache_dir() is None
    monkeypatch.setenv("TID_JAX_CACHE_DIR", "~/elsewhere")
    assert tj.default_cache_dir() == pathlib.Path.home() / "elsewhere"
    monkeypatch.delenv("TID_JAX_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/somewhere")
    assert tj.default_cache_dir() == pathlib.Path("/somewhere/tid_jax")


def test_json_is_strict_with_numbers_that_could_not_be_computed_as_null():
    # Python's json writes NaN and inf as bare tokens, which strict readers reject.
    data = {"peak": float("nan"), "rows": [1.5, np.float64(np.inf), {"x": -np.inf}],
            "pair": (2.0, float("nan")), "ok": True, "n": 3}
    text = _io.json_text(data)

    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    assert json.loads(text, parse_constant=refuse) == {
        "peak": None, "rows": [1.5, None, {"x": None}], "pair": [2.0, None], "ok": True, "n": 3}
