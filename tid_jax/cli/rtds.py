"""`tid-jax rtds`: a virtual real-time substructuring test of the inerter."""

import math

import numpy as np

from .. import plot
from .._runtime._io import write_json
from .._substructuring._simulate import (
    GUESSED_FORCES,
    PREDICTIONS,
    SCHEMES,
    simulate_substructuring,
)
from . import _building
from ._arguments import _add_band_arguments, _add_output_arguments, _add_structure_arguments
from ._common import (
    RELATIVE_WIDTH,
    CLIError,
    _describe,
    _frequencies,
    _inputs,
    _number,
    _Output,
    _read_config,
    _settings,
    _system,
)
from ._schema import amplitude_unit
from ._tables import Shown, save_records, shown, table

RTDS_COLUMNS = (
    "frequency_Hz",
    "amplitude_N",
    "x_whole_m",
    "y_whole_m",
    "x_test_m",
    "y_test_m",
    "x_amplitude_error",
    "y_amplitude_error",
    "x_phase_error_rad",
    "y_phase_error_rad",
    "stable",
    "diverged",
    "growth",
)
RTDS_AMPLITUDE = 200.0  # N, default forcing of `tid-jax rtds`


def _add_rtds_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "rtds",
        help="plan a real-time dynamic substructuring test of the inerter",
        description="Simulate a real-time dynamic substructuring test of the inerter (paper "
        "section 5) as a digital controller runs it: host, TID spring and damper numerical, "
        "the inerter physical behind an actuator with delay, compensated by default by "
        "harmonic forward prediction as in the paper's tests (--prediction none turns it "
        "off: with the default 10 ms delay the host amplitude is then about 10%% off). "
        "Compares the test with the "
        "whole system (amplitude and phase errors) and reports unstable tests. The "
        "friction is smoothed (the default width 0.02 omega A/K unless --friction-width "
        "gives one). Prints a "
        "table and saves rtds.csv, rtds.json and rtds.png to --out. With a [structure]: the "
        "structure, spring and damper numerical, the device along the stroke, the "
        "[response] and the stroke compared (one --amplitude, N or m/s2).",
    )
    _add_structure_arguments(
        parser,
        "TOML file with the structure and device keys (and amplitudes, band_hz, "
        "n_frequencies), as for the other commands",
    )
    _add_forcing_arguments(parser.add_argument_group("forcing"))
    _add_test_arguments(parser.add_argument_group("substructuring test"))
    _add_output_arguments(parser)


def _add_forcing_arguments(forcing) -> None:
    forcing.add_argument(
        "--amplitude",
        dest="amplitudes",
        type=float,
        metavar="N",
        help=f"forcing amplitude A of A sin(wt) [N] (default {RTDS_AMPLITUDE:g})",
    )
    forcing.add_argument(
        "--frequency-hz",
        dest="frequency_hz",
        nargs="+",
        type=float,
        metavar="HZ",
        help="forcing frequencies [Hz] (instead of --band-hz)",
    )
    _add_band_arguments(forcing)


def _add_test_arguments(test) -> None:
    test.add_argument(
        "--scheme",
        choices=SCHEMES,
        default="error_feedback",
        help="feed back the measured force (conventional, unstable for any delay) or its "
        "error from the guessed inertance (error_feedback, default)",
    )
    test.add_argument(
        "--delay-ms", type=float, default=10.0, metavar="MS", help="actuator delay [ms] (10)"
    )
    test.add_argument(
        "--guessed-inertance-ratio",
        type=float,
        default=1.0,
        metavar="RATIO",
        help="guessed inertance b_g over the device's inertance plus terminal mass, b + mt "
        "(1.0)",
    )
    test.add_argument(
        "--guessed-force",
        choices=GUESSED_FORCES,
        default="acceleration",
        help="b_g times the actuator's acceleration, or the paper's -b_g w^2 y* (harmonic)",
    )
    test.add_argument(
        "--prediction",
        choices=("none", *PREDICTIONS),
        default="harmonic",
        help="compensation of the delay: forward prediction of the commanded motion "
        "(default harmonic, as in the paper's tests; none: uncompensated)",
    )
    test.add_argument(
        "--actuator-lag-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="time constant of the actuator's first-order lag [ms] (0: none)",
    )
    test.add_argument(
        "--sample-rate",
        type=float,
        default=1000.0,
        metavar="HZ",
        help="controller sample rate [Hz] (1000)",
    )
    test.add_argument(
        "--periods",
        type=int,
        default=60,
        metavar="N",
        help="simulated duration in forcing periods (60)",
    )


def _test_options(args, system, amplitude: float) -> dict:
    """The test's options (SI) as the JSON reports them."""
    ratio = _number("guessed_inertance_ratio", args.guessed_inertance_ratio, "positive")
    return {
        "scheme": args.scheme,
        "amplitude_N": amplitude,
        "delay_s": _number("delay_ms", args.delay_ms, "non-negative") / 1e3,
        "guessed_inertance_kg": ratio * float(system.inertance + system.terminal_mass),
        "guessed_force": args.guessed_force,
        "prediction": args.prediction,
        "actuator_lag_s": _number("actuator_lag_ms", args.actuator_lag_ms, "non-negative") / 1e3,
        "sample_rate_Hz": _number("sample_rate", args.sample_rate, "positive"),
        "periods": args.periods,
    }


def _simulate(args, system, omegas, amplitude, test: dict, settings, **options):
    return simulate_substructuring(
        system,
        omegas,
        amplitude,
        scheme=args.scheme,
        delay=test["delay_s"],
        guessed_inertance=test["guessed_inertance_kg"],
        guessed_force=args.guessed_force,
        prediction=None if args.prediction == "none" else args.prediction,
        actuator_lag=test["actuator_lag_s"],
        sample_rate=test["sample_rate_Hz"],
        periods=args.periods,
        settings=settings,
        **options,
    )


def _run_rtds(args) -> int:
    config = _read_config(args.config) if args.config else {}
    if args.amplitudes is None and "amplitudes" not in config and "structure" not in config:
        args.amplitudes = RTDS_AMPLITUDE
    inputs = _inputs(args)
    if "friction_width" not in inputs:
        # the test runs in real time with fixed steps: the friction smoothed, at the
        # relative width (exact Coulomb friction, the default elsewhere, needs events)
        inputs["friction_width"] = RELATIVE_WIDTH
    if len(inputs["amplitudes"]) != 1 or ("structure" in inputs
                                          and "amplitudes_given" not in inputs):
        raise CLIError(f"rtds takes one amplitude (--amplitude), got {inputs['amplitudes']}")
    amplitude = inputs["amplitudes"][0]
    if "structure" in inputs:
        return _run_building_rtds(args, inputs, amplitude)
    system, settings = _system(inputs), _settings(inputs)
    frequencies_hz, omegas = _test_frequencies(args, inputs, _frequencies(inputs, system))
    test = _test_options(args, system, amplitude)
    delay, rate, ratio = test["delay_s"], test["sample_rate_Hz"], args.guessed_inertance_ratio
    output = _Output(args)
    output.say(
        f"substructuring test ({args.scheme}, delay {1e3 * delay:g} ms, b_g = {ratio:g} b, "
        f"prediction {args.prediction}) at {omegas.size} frequencies, A = {amplitude:g} N; "
        f"{_describe(system)}"
    )
    result = _simulate(args, system, omegas, amplitude, test, settings)
    columns = _columns(result)
    records = [
        dict(zip(RTDS_COLUMNS, (float(f), amplitude,
                                *(columns[key][j] for key in RTDS_COLUMNS[2:])), strict=True))
        for j, f in enumerate(frequencies_hz)
    ]
    save_records(output, "rtds.csv", RTDS_COLUMNS, records)
    label = f"test: {args.scheme}, {1e3 * delay:g} ms, b_g = {ratio:g} b"
    plot.save_figure(
        plot.plot_substructuring_response(
            frequencies_hz,
            columns["x_whole_m"],
            columns["y_whole_m"],
            [(label, columns["x_test_m"], columns["y_test_m"], columns["stable"])],
            title=f"Virtual substructuring test, A = {amplitude:g} N, {rate:g} Hz controller",
        ),
        output.path("rtds.png"),
    )
    json_path = output.path("rtds.json")
    data = output.document("rtds", inputs, system, settings, frequencies_hz, test=test, **columns)
    write_json(json_path, data)

    text = table(RTDS_TABLE, records)
    title = (
        f"Substructuring test ({args.scheme}, delay {1e3 * delay:g} ms, b_g = {ratio:g} b, "
        f"prediction {args.prediction}, {rate:g} Hz) against the whole system, "
        f"A = {amplitude:g} N; {_describe(system)}"
    )
    return output.finish(data, title + "\n" + text)


def _run_building_rtds(args, inputs: dict, amplitude: float) -> int:
    """The test on a [structure]: x is the chosen response, y the stroke."""
    system, quantity, _ = _building.building_inputs(inputs)
    frequencies_hz, omegas = _test_frequencies(args, inputs, _building.band(inputs, system))
    test = _test_options(args, system, amplitude)
    unit = amplitude_unit(system.load)
    test["amplitude"] = test.pop("amplitude_N")  # in the JSON's "amplitude_unit"
    output = _Output(args)
    options = (f"({args.scheme}, delay {1e3 * test['delay_s']:g} ms, b_g = "
               f"{args.guessed_inertance_ratio:g} (b + mt), prediction {args.prediction})")
    case = f"A = {amplitude:g} {unit}; {_building.describe(system, quantity)}"
    output.say(f"substructuring test {options} at {omegas.size} frequencies, {case}")
    try:
        result = _simulate(args, system, omegas, amplitude, test, _settings(inputs),
                           quantity=quantity)
    except ValueError as error:
        raise CLIError(str(error)) from None
    columns = {name: values for name, values in zip(
        BUILDING_RTDS_COLUMNS[2:], _columns(result).values(), strict=True)}
    records = [dict(zip(BUILDING_RTDS_COLUMNS, (float(f), amplitude, *(
        columns[key][j] for key in BUILDING_RTDS_COLUMNS[2:])), strict=True))
        for j, f in enumerate(frequencies_hz)]
    save_records(output, "rtds.csv", BUILDING_RTDS_COLUMNS, records)
    described = quantity.describe(system.floors)
    panels = ((f"(a) {described}", f"peak [{quantity.unit}]", 1.0),
              ("(b) TID stroke, r", "peak stroke [mm]", 1e3))
    plot.save_figure(plot.plot_substructuring_response(
        frequencies_hz, columns["response_whole"], columns["stroke_whole_m"],
        [("test", columns["response_test"], columns["stroke_test_m"], columns["stable"])],
        title=f"Virtual substructuring test, A = {amplitude:g} {unit}", panels=panels),
        output.path("rtds.png"))
    _building.save_config(inputs, output, "rtds")
    data = _building.document("rtds", inputs, system, quantity, frequencies_hz, output,
                               test=test, **columns)
    write_json(output.path("rtds.json"), data)
    rows = (shown("f [Hz]", "frequency_Hz", ".3f"),
            shown(f"whole [{quantity.unit}]", "response_whole", ".4g"),
            _if_stable(shown(f"test [{quantity.unit}]", "response_test", ".4g")),
            _if_stable(shown("err [%]", "response_amplitude_error", ".2f", unit=0.01)),
            shown("stroke whole [mm]", "stroke_whole_m", ".4f", unit=1e-3),
            _if_stable(shown("stroke test [mm]", "stroke_test_m", ".4f", unit=1e-3)),
            _if_stable(shown("err [%]", "stroke_amplitude_error", ".2f", unit=0.01)),
            Shown("test", _outcome))
    return output.finish(data, f"Substructuring test {options} against the whole building, "
                         f"{case}\n" + table(rows, records))


# a building's columns: the response (its unit in the JSON's "response") and the stroke
BUILDING_RTDS_COLUMNS = (
    "frequency_Hz",
    "amplitude",
    "response_whole",
    "stroke_whole_m",
    "response_test",
    "stroke_test_m",
    "response_amplitude_error",
    "stroke_amplitude_error",
    "response_phase_error_rad",
    "stroke_phase_error_rad",
    "stable",
    "diverged",
    "growth",
)


def _test_frequencies(args, inputs, band):
    """The forcing frequencies in Hz and rad/s: --frequency-hz, or the `band`'s."""
    if args.frequency_hz is None:
        return band
    if args.band_hz is not None:
        raise CLIError("give --frequency-hz or --band-hz, not both")
    frequencies_hz = np.asarray([_number("frequency_hz", f, "positive")
                                 for f in args.frequency_hz])
    return frequencies_hz, 2 * math.pi * frequencies_hz


def _if_stable(column: Shown) -> Shown:
    """`column`, shown only where the test was stable ("-" elsewhere)."""
    return Shown(column.header, lambda r: column.cell(r) if r["stable"] else "-")


def _phase_errors(record: dict) -> str:
    x, y = (math.degrees(record[f"{axis}_phase_error_rad"]) for axis in "xy")
    return f"{x:.2f}/{y:.2f}"


def _outcome(record: dict) -> str:
    return ("stable" if record["stable"]
            else "diverged" if record["diverged"] else "growing")


# The printed table: the test against the whole system at each frequency (the test's
# values shown only where it was stable).
RTDS_TABLE = (
    shown("f [Hz]", "frequency_Hz", ".3f"),
    shown("x whole [mm]", "x_whole_m", ".4f", unit=1e-3),
    _if_stable(shown("x test [mm]", "x_test_m", ".4f", unit=1e-3)),
    _if_stable(shown("x err [%]", "x_amplitude_error", ".2f", unit=0.01)),
    shown("y whole [mm]", "y_whole_m", ".4f", unit=1e-3),
    _if_stable(shown("y test [mm]", "y_test_m", ".4f", unit=1e-3)),
    _if_stable(shown("y err [%]", "y_amplitude_error", ".2f", unit=0.01)),
    _if_stable(Shown("phase err x/y [deg]", _phase_errors)),
    Shown("test", _outcome),
)


def _columns(result) -> dict[str, list]:
    """The result's columns of `RTDS_COLUMNS` (but frequency and amplitude), as lists."""
    columns = {
        "x_whole_m": result.reference_x_max,
        "y_whole_m": result.reference_y_max,
        "x_test_m": result.x_max,
        "y_test_m": result.y_max,
        "x_amplitude_error": result.x_amplitude_error,
        "y_amplitude_error": result.y_amplitude_error,
        "x_phase_error_rad": result.x_phase_error,
        "y_phase_error_rad": result.y_phase_error,
        "stable": result.stable,
        "diverged": result.diverged,
        "growth": result.growth,
    }
    return {key: np.atleast_1d(np.asarray(value)).tolist() for key, value in columns.items()}
