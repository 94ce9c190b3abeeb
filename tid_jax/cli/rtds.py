"""`tid-jax rtds`: a virtual real-time substructuring test of the inerter."""

import math

import numpy as np

from .. import plot
from .._io import write_json
from .._substructuring import GUESSED_FORCES, PREDICTIONS, SCHEMES, simulate_substructuring
from ._arguments import _add_band_arguments, _add_output_arguments, _add_structure_arguments
from ._common import (
    CLIError,
    _describe,
    _frequencies,
    _inputs,
    _number,
    _Output,
    _read_config,
    _settings,
    _single_storey,
    _system,
)
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
        "table and saves rtds.csv, rtds.json and rtds.png to --out.",
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


def _run_rtds(args) -> int:
    if args.amplitudes is None and not (args.config and "amplitudes" in _read_config(args.config)):
        args.amplitudes = RTDS_AMPLITUDE
    inputs = _inputs(args)
    _single_storey(inputs, args.command)
    if len(inputs["amplitudes"]) != 1:
        raise CLIError(f"rtds takes one amplitude, got {inputs['amplitudes']}")
    amplitude = inputs["amplitudes"][0]
    delay = _number("delay_ms", args.delay_ms, "non-negative") / 1e3
    ratio = _number("guessed_inertance_ratio", args.guessed_inertance_ratio, "positive")
    lag = _number("actuator_lag_ms", args.actuator_lag_ms, "non-negative") / 1e3
    rate = _number("sample_rate", args.sample_rate, "positive")
    system, settings = _system(inputs), _settings(inputs)
    if "friction_width" not in inputs:
        # the test runs in real time with fixed steps: the friction smoothed, at the
        # relative width (exact Coulomb friction, the default elsewhere, needs events)
        system = system.replace(friction_width=None)
    frequencies_hz, omegas = _test_frequencies(args, inputs, system)
    prediction = None if args.prediction == "none" else args.prediction
    test = {
        "scheme": args.scheme,
        "amplitude_N": amplitude,
        "delay_s": delay,
        "guessed_inertance_kg": ratio * float(system.inertance + system.terminal_mass),
        "guessed_force": args.guessed_force,
        "prediction": args.prediction,
        "actuator_lag_s": lag,
        "sample_rate_Hz": rate,
        "periods": args.periods,
    }
    output = _Output(args)
    output.say(
        f"substructuring test ({args.scheme}, delay {1e3 * delay:g} ms, b_g = {ratio:g} b, "
        f"prediction {args.prediction}) at {omegas.size} frequencies, A = {amplitude:g} N; "
        f"{_describe(system)}"
    )
    result = simulate_substructuring(
        system,
        omegas,
        amplitude,
        scheme=args.scheme,
        delay=delay,
        guessed_inertance=test["guessed_inertance_kg"],
        guessed_force=args.guessed_force,
        prediction=prediction,
        actuator_lag=lag,
        sample_rate=rate,
        periods=args.periods,
        settings=settings,
    )
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


def _test_frequencies(args, inputs, system):
    """The forcing frequencies in Hz and rad/s: --frequency-hz, or the band."""
    if args.frequency_hz is None:
        return _frequencies(inputs, system)
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
