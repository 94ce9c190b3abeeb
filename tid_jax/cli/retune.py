"""`tid-jax retune`: the TID retuned for each amplitude."""

import math
import textwrap

import numpy as np

from .. import plot
from .._model._building import BuildingTID, Quantity, as_building, first_mode_tunings
from .._model._linear import host_breakaway
from .._optimise._design import parameter_unit
from .._response import _on_host
from .._retune import RetuneSettings, retune
from .._runtime._io import write_json
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._building import uncontrolled_peak
from ._common import (
    _breakaway_line,
    _den_hartog,
    _host_frequency_hz,
    _inputs,
    _linear_curves,
)
from ._schema import RETUNE_COLUMNS, RETUNE_TABLE, finite, ratio, row, status, stroke_problem
from ._tables import save_records, table


def _add_retune_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "retune",
        help="retune the TID's k and c for each forcing amplitude",
        description="For each forcing amplitude, find the TID stiffness k and damping c that "
        "minimise the peak steady-state host displacement (with a [structure], the peak of "
        "the [response] quantity) over the frequency band, starting from the given "
        "(default: Den Hartog) tuning. Prints a table and saves retune.csv, retune.json, "
        "retune_config.toml, retune_frequency_response.png and retune_summary.png to --out.",
    )
    _add_system_arguments(parser)
    _add_output_arguments(parser)


def _run_retune(args) -> int:
    start = _building.design_start(args, _inputs(args), "retuning {amplitudes} amplitude(s) "
                                   "over {frequencies} frequencies")
    system, quantity, amplitudes, output = (start.system, start.quantity, start.amplitudes,
                                            start.output)
    limit = start.inputs["stroke_limit"]
    with output.steps(RetuneSettings().progress_steps()) as step:
        result = retune(system, amplitudes, omegas=start.omegas, quantity=quantity,
                        settings=start.settings, progress=step, map_lanes=args.map_lanes)
    result = _on_host(result)  # read entry by entry below: no array operation each
    records = _records(result, system, quantity, limit)
    save_records(output, "retune.csv", RETUNE_COLUMNS, records)
    _building.save_config(start.inputs, output, "retune")
    if quantity is None:
        _save_plots(output, result, system, amplitudes, start.frequencies_hz, limit,
                    args.map_lanes)
        extra = {}
    else:
        _save_building_plots(output, system, quantity, records, result, limit)
        extra = dict(first_mode_tunings={name: {"k_N_per_m": k, "c_N_s_per_m": c}
                                         for name, (k, c) in first_mode_tunings(system).items()})
    data = _building.design_document(start, "retune", **extra, results=records)
    write_json(output.path("retune.json"), data)
    text = _table(records, system, limit, start.described)
    if quantity is None:
        text += "\nWith the initial tuning: " + _breakaway_line(host_breakaway(system,
                                                                          start.omegas))
    return output.finish(data, text)


def _records(result, system, quantity, stroke_limit) -> list[dict]:
    """One record per amplitude, keyed by `RETUNE_COLUMNS`: the design, its peak before
    (the given tuning's) and after, their ratios (to the static displacement A/K on the
    paper's host) and the strokes."""
    k_dh, c_dh = _building.reference_tuning(system)
    amplitudes = np.asarray(result.amplitudes)
    static = None if quantity is not None else amplitudes / float(system.host_stiffness)
    before, after = np.asarray(result.x_peak_initial), np.asarray(result.x_peak)
    y_before, y_after = np.asarray(result.y_peak_initial), np.asarray(result.y_peak)
    # the given tuning is Den Hartog's (the default): its peak is the "before"
    given_is_den_hartog = np.allclose([float(system.tid_stiffness), float(system.tid_damping)],
                                      [k_dh, c_dh], rtol=1e-12)
    structure = as_building(system) if quantity is None else system
    bare = amplitudes * uncontrolled_peak(structure, quantity or Quantity(),
                                          np.asarray(result.check_omegas))
    statuses = result.status_messages()
    records = []
    for i, amplitude in enumerate(amplitudes):
        k, c = float(result.tid_stiffness[i]), float(result.tid_damping[i])
        over_static = {} if static is None else dict(
            x_peak_before_over_A_K=finite(before[i] / static[i]),
            x_peak_after_over_A_K=finite(after[i] / static[i]))
        records.append(row(
            RETUNE_COLUMNS, amplitude=float(amplitude),
            amplitude_unit=parameter_unit("amplitude", system),
            k_N_per_m=k, c_N_s_per_m=c, k_over_k_den_hartog=k / k_dh,
            c_over_c_den_hartog=c / c_dh, peak_unit="m" if quantity is None else quantity.unit,
            peak_before=finite(before[i]), peak_after=finite(after[i]),
            peak_frequency_after_Hz=finite(float(result.omega_peak[i]) / (2 * math.pi)),
            peak_after_over_before=ratio(after[i], before[i]),
            peak_after_over_den_hartog=(ratio(after[i], before[i]) if given_is_den_hartog
                                        else None),
            peak_after_over_uncontrolled=ratio(after[i], bare[i]), **over_static,
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


def _save_building_plots(output, system, quantity, records, result, limit) -> None:
    """The paper's Figures 7 (k and c, peaks and strokes against amplitude) and 6 (the
    response over the band before and after retuning, on the retune's check grid) for
    a building, in SI."""
    amplitudes = np.asarray(result.amplitudes)
    k_ratio = [r["k_over_k_den_hartog"] for r in records]
    c_ratio = [r["c_over_c_den_hartog"] for r in records]
    peak_label = f"peak {quantity.describe(system.floors)} [{quantity.unit}]"
    described = textwrap.fill(_building.describe(system, quantity), 110)
    plot.save_figure(plot.plot_retune_summary(
        amplitudes, k_ratio, c_ratio, np.asarray(result.x_peak_initial),
        np.asarray(result.x_peak), np.asarray(result.y_peak_initial),
        np.asarray(result.y_peak), stroke_limit=limit, converged=np.asarray(result.converged),
        amplitude_label=_building.amplitude_label(system), peak_label=peak_label,
        reference="first-mode Den Hartog",
        title=f"TID retuned for each amplitude\n{described}"),
        output.path("retune_summary.png"))
    plot.save_figure(plot.plot_retune_responses(
        np.asarray(result.check_omegas) / (2 * math.pi), amplitudes,
        np.asarray(result.x_response_initial), np.asarray(result.x_response), k_ratio,
        c_ratio, ylabel=peak_label, amplitude_unit=parameter_unit("amplitude", system),
        title=f"{quantity.describe(system.floors).capitalize()} before and after retuning "
        "the TID"), output.path("retune_frequency_response.png"))


def _table(records, system, stroke_limit, described: str) -> str:
    """The printed table of the records, with its title."""
    k_dh, c_dh = _building.reference_tuning(system)
    title = (
        f"Retuned TID ({described}); Den Hartog k_DH = {k_dh:.5g} N/m, c_DH = {c_dh:.4g} "
        "N s/m" + (" (of the first mode)" if isinstance(system, BuildingTID) else
                   "; peaks in m, and x over the static displacement A/K")
    )
    return title + "\n" + table(RETUNE_TABLE, records, limit_cm=100 * stroke_limit)
