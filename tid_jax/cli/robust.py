"""`tid-jax robust`: one tuning for every amplitude (and host frequency)."""

import math

import numpy as np

from .. import plot
from .._optimise._design import parameter_unit
from .._response import _on_host
from .._retune import RetuneSettings
from .._robust import RobustSettings, robust_tune, tuning_performance
from .._runtime._io import write_json
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._common import (
    CLIError,
    _inputs,
)
from ._schema import ROBUST_COLUMNS, ROBUST_TABLE, finite, row, status, stroke_problem
from ._tables import save_records, table


def _add_robust_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "robust",
        help="one TID tuning for a range of forcing amplitudes (and host frequencies)",
        description="The TID stiffness k and damping c minimising the worst case, over the "
        "forcing amplitudes (and host frequencies), of the peak host displacement over "
        "the best achievable at that amplitude, with the inerter stroke within the "
        "stroke limit; compared with the given (default: Den Hartog) tuning. Prints a "
        "table and saves robust.csv, robust.json, robust_config.toml and robust.png "
        "to --out. With a [structure]: over the amplitudes and (with "
        "--host-frequency-tolerance) the structure's natural frequencies, for the "
        "[response] quantity, the stroke not limited.",
    )
    _add_system_arguments(parser)
    parser.add_argument(
        "--host-frequency-tolerance",
        dest="host_frequency_tolerance",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="also hold for host frequencies (1 +- FRACTION) times the nominal one, "
        "e.g. 0.05 (default 0: nominal only)",
    )
    parser.add_argument(
        "--no-stroke-limit",
        action="store_true",
        help="leave the inerter stroke free",
    )
    _add_output_arguments(parser)


def _run_robust(args) -> int:
    tolerance = args.host_frequency_tolerance
    if not (math.isfinite(tolerance) and 0 <= tolerance < 1):
        raise CLIError(f"host_frequency_tolerance must be a fraction in [0, 1), got {tolerance!r}")
    scales = (1 - tolerance, 1.0, 1 + tolerance) if tolerance > 0 else (1.0,)
    start = _building.design_start(
        args, _inputs(args), f"robust tuning over {{amplitudes}} amplitude(s) x {len(scales)} "
        "host frequencies, {frequencies} frequencies each")
    system, quantity, amplitudes, output = (start.system, start.quantity, start.amplitudes,
                                            start.output)
    stroke_limit = None if args.no_stroke_limit else start.inputs["stroke_limit"]
    # The retune's steps, then the robust design's: its start, its stages and its end.
    total = RetuneSettings().progress_steps() + 3 + len(RobustSettings().sharpness)
    with output.steps(total) as step:
        result = robust_tune(system, amplitudes, host_frequency_scales=scales,
                             stroke_limit=stroke_limit, omegas=start.omegas, quantity=quantity,
                             settings=start.settings, progress=step,
                             map_lanes=args.map_lanes)
    given = tuning_performance(system, result.best, settings=start.settings,
                               map_lanes=args.map_lanes)
    result, given = _on_host((result, given))  # read entry by entry below
    units = (parameter_unit("amplitude", system), "m" if quantity is None else quantity.unit)
    records = _records(result, given, scales, amplitudes, stroke_limit, units)
    save_records(output, "robust.csv", ROBUST_COLUMNS, records)
    _building.save_config(start.inputs, output, "robust")
    _save_plot(output, result, given, amplitudes, scales.index(1.0), stroke_limit,
               nominal_only=tolerance > 0, system=system, quantity=quantity)
    summary = _summary(result, given, system, stroke_limit)
    data = _building.design_document(start, "robust", frequency_scales=list(scales),
                                     robust=summary, results=records)
    write_json(output.path("robust.json"), data)
    return output.finish(data, _table(records, summary, system, stroke_limit, tolerance,
                                      start.described, units[0]))


def _records(result, given, scales, amplitudes, stroke_limit, units) -> list[dict]:
    """One record per scenario, keyed by `ROBUST_COLUMNS`."""
    robust, best = result.performance, result.best
    converged = bool(result.converged)
    base = result.status_messages()[0]
    return [
        row(ROBUST_COLUMNS, frequency_scale=float(scale), amplitude=float(amplitude),
            amplitude_unit=units[0], k_N_per_m=float(result.tid_stiffness),
            c_N_s_per_m=float(result.tid_damping),
            best_k_N_per_m=float(best.tid_stiffness[i, j]),
            best_c_N_s_per_m=float(best.tid_damping[i, j]), peak_unit=units[1],
            peak_best=finite(best.host_peak[i, j]), peak_before=finite(given.host_peak[i, j]),
            peak_after=finite(robust.host_peak[i, j]),
            peak_before_over_best=finite(given.ratio[i, j]),
            peak_after_over_best=finite(robust.ratio[i, j]),
            stroke_before_m=finite(given.stroke_peak[i, j]),
            stroke_after_m=finite(robust.stroke_peak[i, j]), stroke_limit_m=stroke_limit,
            within_stroke_limit=(None if stroke_limit is None
                                 else bool(robust.stroke_peak[i, j] <= stroke_limit)),
            converged=converged,
            status=status(converged, stroke_problem(robust.stroke_peak[i, j], stroke_limit),
                          base=base))
        for i, scale in enumerate(scales)
        for j, amplitude in enumerate(amplitudes)
    ]


def _save_plot(output, result, given, amplitudes, nominal, stroke_limit, *, nominal_only,
               system, quantity):
    robust = result.performance
    labels = {} if quantity is None else dict(
        amplitude_label=_building.amplitude_label(system),
        ratio_label=f"peak {quantity.describe(system.floors)} / best achievable")
    plot.save_figure(
        plot.plot_robust_comparison(
            amplitudes,
            [
                (
                    f"given tuning: worst {float(given.worst_ratio):.3f}",
                    np.asarray(given.ratio[nominal]),
                    np.asarray(given.stroke_peak[nominal]),
                    dict(color="tab:red", linestyle="--", marker="."),
                ),
                (
                    f"robust: worst {float(result.worst_ratio):.3f}",
                    np.asarray(robust.ratio[nominal]),
                    np.asarray(robust.stroke_peak[nominal]),
                    dict(color="tab:blue", linewidth=2.0, marker="."),
                ),
            ],
            stroke_limit=stroke_limit,
            title="Robust TID tuning" + (" (nominal host frequency)" if nominal_only else ""),
            **labels,
        ),
        output.path("robust.png"),
    )


def _summary(result, given, system, stroke_limit) -> dict:
    """The robust design and the given tuning's worst case, for the JSON and the title."""
    k_dh, c_dh = _building.reference_tuning(system)
    k, c = float(result.tid_stiffness), float(result.tid_damping)
    return {
        "k_N_per_m": k,
        "c_N_s_per_m": c,
        "k_over_k_den_hartog": k / k_dh,
        "c_over_c_den_hartog": c / c_dh,
        "worst_ratio": float(result.worst_ratio),
        "worst_amplitude": float(result.worst_amplitude),
        "worst_host_frequency_scale": float(result.worst_host_frequency_scale),
        "stroke_limit_m": stroke_limit,
        "max_stroke_m": float(result.max_stroke),
        "given_worst_ratio": float(given.worst_ratio),
        "given_worst_amplitude": float(given.worst_amplitude),
        "iterations": int(result.iterations),
        "converged": bool(result.converged),
        "status": result.status_messages()[0],
    }


def _table(records, summary, system, stroke_limit, tolerance, described, unit) -> str:
    """The printed table of the scenarios, with its title."""
    k_dh, c_dh = _building.reference_tuning(system)
    k, c = summary["k_N_per_m"], summary["c_N_s_per_m"]
    limit_text = (
        "no stroke limit"
        if stroke_limit is None
        else (f"max stroke {100 * summary['max_stroke_m']:.2f} cm (limit {100 * stroke_limit:g})")
    )
    title = (
        f"Robust tuning ({described}): k = {k:.5g} N/m ({k / k_dh:.3f} k_DH), "
        f"c = {c:.4g} N s/m ({c / c_dh:.3f} c_DH); worst ratio to the best tuning "
        f"{summary['worst_ratio']:.3f} at {summary['worst_amplitude']:g} {unit}"
        + (f", host frequency x {summary['worst_host_frequency_scale']:g}" if tolerance else "")
        + f" (given tuning: {summary['given_worst_ratio']:.3f} at "
        f"{summary['given_worst_amplitude']:g} {unit}); {limit_text}; {summary['status']}"
    )
    return title + "\n" + table(ROBUST_TABLE, records)
