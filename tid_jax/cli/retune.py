"""`tid-jax retune`: the TID retuned for each amplitude."""

import math

import numpy as np

from .. import plot
from .._model._building import Quantity, as_building
from .._model._linear import host_breakaway
from .._response import _on_host
from .._retune import RetuneSettings, retune
from .._runtime._io import write_json, write_toml
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._building import uncontrolled_peak
from ._common import (
    _breakaway_line,
    _config_comment,
    _config_data,
    _den_hartog,
    _describe,
    _host_frequency_hz,
    _inputs,
    _linear_curves,
    _start,
)
from ._schema import RETUNE_COLUMNS, RETUNE_TABLE, finite, ratio, row, status, stroke_problem
from ._tables import save_records, table


def _add_retune_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "retune",
        help="retune the TID's k and c for each forcing amplitude",
        description="For each forcing amplitude, find the TID stiffness k and damping c that "
        "minimise the peak steady-state host displacement over the frequency "
        "band, starting from the given (default: Den Hartog) tuning. Prints a "
        "table and saves retune.csv, retune.json, retune_config.toml, "
        "retune_frequency_response.png and retune_summary.png to --out.",
    )
    _add_system_arguments(parser)
    _add_output_arguments(parser)


def _run_retune(args) -> int:
    inputs = _inputs(args)
    if "structure" in inputs:
        return _building.run_retune(args, inputs)
    start = _start(args)
    inputs, system, settings, frequencies_hz, omegas, amplitudes, output = start
    output.say(
        f"retuning {amplitudes.size} amplitude(s) over {omegas.size} frequencies, "
        f"{frequencies_hz[0]:.3g}-{frequencies_hz[-1]:.3g} Hz; "
        f"{_describe(system)}"
    )
    with output.steps(RetuneSettings().progress_steps()) as step:
        result = retune(system, amplitudes, omegas=omegas, settings=settings, progress=step,
                        map_lanes=args.map_lanes)
    result = _on_host(result)  # read entry by entry below: no array operation each
    records = _records(result, system, amplitudes, inputs["stroke_limit"])
    save_records(output, "retune.csv", RETUNE_COLUMNS, records)
    write_toml(
        output.path("retune_config.toml"), _config_data(inputs), comment=_config_comment("retune")
    )
    _save_plots(output, result, system, amplitudes, frequencies_hz, inputs["stroke_limit"],
                args.map_lanes)
    json_path = output.path("retune.json")
    data = output.document("retune", inputs, system, settings, frequencies_hz, results=records)
    write_json(json_path, data)
    breakaway = host_breakaway(system, omegas)
    return output.finish(data, _table(records, system, inputs["stroke_limit"]) + "\n"
                         + "With the initial tuning: " + _breakaway_line(breakaway))


def _records(result, system, amplitudes, stroke_limit) -> list[dict]:
    """One record per amplitude, keyed by `RETUNE_COLUMNS`."""
    k_dh, c_dh = _den_hartog(system)
    static = amplitudes / float(system.host_stiffness)
    before, after = np.asarray(result.x_peak_initial), np.asarray(result.x_peak)
    y_before, y_after = np.asarray(result.y_peak_initial), np.asarray(result.y_peak)
    # the given tuning is Den Hartog's (the default): its peak is the "before"
    given_is_den_hartog = np.allclose([float(system.tid_stiffness), float(system.tid_damping)],
                                      [k_dh, c_dh], rtol=1e-12)
    bare = amplitudes * uncontrolled_peak(as_building(system), Quantity(),
                                          np.asarray(result.check_omegas))
    statuses = result.status_messages()
    records = []
    for i, amplitude in enumerate(amplitudes):
        k, c = float(result.tid_stiffness[i]), float(result.tid_damping[i])
        records.append(row(
            RETUNE_COLUMNS, amplitude=float(amplitude), amplitude_unit="N",
            k_N_per_m=k, c_N_s_per_m=c, k_over_k_den_hartog=k / k_dh,
            c_over_c_den_hartog=c / c_dh, peak_unit="m",
            peak_before=finite(before[i]), peak_after=finite(after[i]),
            peak_frequency_after_Hz=finite(float(result.omega_peak[i]) / (2 * math.pi)),
            peak_after_over_before=ratio(after[i], before[i]),
            peak_after_over_den_hartog=(ratio(after[i], before[i]) if given_is_den_hartog
                                        else None),
            peak_after_over_uncontrolled=ratio(after[i], bare[i]),
            x_peak_before_over_A_K=finite(before[i] / static[i]),
            x_peak_after_over_A_K=finite(after[i] / static[i]),
            stroke_before_m=finite(y_before[i]), stroke_after_m=finite(y_after[i]),
            stroke_limit_m=stroke_limit, within_stroke_limit=bool(y_after[i] <= stroke_limit),
            converged=bool(result.converged[i]),
            status=status(bool(result.converged[i]), stroke_problem(y_after[i], stroke_limit),
                          "" if after[i] <= before[i] else "peak above the initial tuning's",
                          base=statuses[i])))
    return records


def _save_plots(output, result, system, amplitudes, frequencies_hz, stroke_limit,
                map_lanes) -> None:
    """The frequency responses before and after retuning (on retune's check grid) and the
    summary against amplitude."""
    k_dh, c_dh = _den_hartog(system)
    static = amplitudes / float(system.host_stiffness)
    k_ratio = np.asarray(result.tid_stiffness) / k_dh
    c_ratio = np.asarray(result.tid_damping) / c_dh
    linear_hz, x_linear, _ = _linear_curves(system, frequencies_hz)
    plot.save_figures([
        (plot.plot_retune_responses, (
            np.asarray(result.check_omegas) / (2 * math.pi),
            amplitudes,
            np.asarray(result.x_response_initial) / static[:, None],
            np.asarray(result.x_response) / static[:, None],
            k_ratio,
            c_ratio,
        ), dict(linear=(linear_hz, np.asarray(x_linear)),
                host_frequency_hz=_host_frequency_hz(system)),
         output.path("retune_frequency_response.png")),
        (plot.plot_retune_summary, (
            amplitudes,
            k_ratio,
            c_ratio,
            np.asarray(result.x_peak_initial) / static,
            np.asarray(result.x_peak) / static,
            np.asarray(result.y_peak_initial),
            np.asarray(result.y_peak),
        ), dict(stroke_limit=stroke_limit, converged=np.asarray(result.converged)),
         output.path("retune_summary.png")),
    ], map_lanes=map_lanes)


def _table(records, system, stroke_limit) -> str:
    """The printed table of the records, with its title."""
    k_dh, c_dh = _den_hartog(system)
    title = (
        f"Retuned TID ({_describe(system)}); Den Hartog k_DH = {k_dh:.5g} N/m, "
        f"c_DH = {c_dh:.4g} N s/m; peaks in m, and x over the static displacement A/K"
    )
    return title + "\n" + table(RETUNE_TABLE, records, limit_cm=100 * stroke_limit)
