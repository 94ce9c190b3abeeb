"""`tid-jax frf`: the steady-state frequency response and the breakaway amplitude."""

import math
from typing import NamedTuple

import numpy as np

from .. import plot
from .._model._building import Quantity, as_building, uncontrolled_amplitude
from .._model._linear import host_breakaway
from .._optimise._design import parameter_unit
from .._response import frequency_response
from .._runtime._io import write_json
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._common import (
    _breakaway_line,
    _describe,
    _host_frequency_hz,
    _inputs,
    _linear_curves,
    _linear_normalised,
    _stuck_curve,
)
from ._schema import FRF_COLUMNS, FRF_TABLE, finite, frf_summary, ratio, row, status
from ._tables import save_records, table


def _add_frf_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "frf",
        help="steady-state frequency response over a band and a list of amplitudes",
        description="Peak steady-state host displacement x and inerter displacement y over "
        "the frequency band for each forcing amplitude (the paper's Figure 5), "
        "beside the linear (frictionless) TID. Saves frf.csv, frf.json, "
        "frf_config.toml and frf.png to --out.",
    )
    _add_system_arguments(parser)
    _add_output_arguments(parser)


class _Grid(NamedTuple):
    """The responses over amplitudes x frequencies (SI)."""

    x_max: np.ndarray
    y_max: np.ndarray
    converged: np.ndarray
    stable: np.ndarray
    stick_fraction: np.ndarray
    transitions: np.ndarray


def _run_frf(args) -> int:
    start = _building.design_start(args, _inputs(args), "frequency response at {amplitudes} "
                                   "amplitude(s) x {frequencies} frequencies", design=False)
    system, quantity, amplitudes, output = (start.system, start.quantity, start.amplitudes,
                                            start.output)
    frequencies_hz, omegas = start.frequencies_hz, start.omegas
    grid = _solve(system, quantity, omegas, amplitudes, start.settings, output)
    structure = as_building(system) if quantity is None else system
    uncontrolled = amplitudes[:, None] * np.asarray(
        uncontrolled_amplitude(structure, quantity or Quantity(), omegas))[None, :]
    bare = amplitudes * _building.uncontrolled_peak(structure, quantity or Quantity(), omegas)
    records = _records(system, quantity, grid, amplitudes, frequencies_hz, uncontrolled, bare)
    save_records(output, "frf.csv", FRF_COLUMNS, records)
    _building.save_config(start.inputs, output, "frf")
    summary = frf_summary(records, amplitudes, omegas.size)
    # the same arrays for one storey and many: amplitudes x frequencies
    extra = dict(amplitudes=amplitudes.tolist(),
                 amplitude_unit=parameter_unit("amplitude", system),
                 response_unit=(quantity or Quantity()).unit,
                 response_max=grid.x_max.tolist(), uncontrolled=uncontrolled.tolist(),
                 y_max_m=grid.y_max.tolist(), converged=grid.converged.tolist(),
                 stable=(grid.converged & grid.stable).tolist(),
                 stick_fraction=grid.stick_fraction.tolist(),
                 transitions=grid.transitions.tolist())
    if quantity is None:
        breakaway = _host_outputs(output, system, grid, amplitudes, frequencies_hz, omegas,
                                  extra)
        text = (_table(summary, system, start.inputs["stroke_limit"]) + "\n"
                + _breakaway_line(breakaway))
    else:
        plot.save_figure(plot.plot_building_response(
            frequencies_hz, amplitudes, grid.x_max, uncontrolled,
            ylabel=f"{quantity.describe(system.floors)} [{quantity.unit}]",
            amplitude_unit=extra["amplitude_unit"]), output.path("frf.png"))
        text = f"Frequency response: {start.described}\n" + table(
            FRF_TABLE, summary, limit_cm=100 * start.inputs["stroke_limit"])
    data = _building.design_document(start, "frf", **extra, summary=summary, results=records)
    write_json(output.path("frf.json"), data)
    return output.finish(data, text)


def _host_outputs(output, system, grid, amplitudes, frequencies_hz, omegas, arrays):
    """The paper's host's figure (normalised by A/K, with the linear and stuck curves),
    its curves and breakaway amplitudes added to the JSON's `arrays`; the breakaway
    amplitude over the band."""
    static = (amplitudes / float(system.host_stiffness))[:, None]
    x_linear, y_linear = _linear_normalised(system, frequencies_hz)
    breakaway = host_breakaway(system, omegas)
    plot.save_figure(
        plot.plot_frequency_response(
            frequencies_hz, amplitudes, grid.x_max / static, grid.y_max / static,
            linear=_linear_curves(system, frequencies_hz),
            stuck=(*_stuck_curve(system, frequencies_hz), float(breakaway.minimum)),
            host_frequency_hz=_host_frequency_hz(system),
        ),
        output.path("frf.png"),
    )
    arrays.update(
        x_linear_over_A_K=x_linear.tolist(),
        y_linear_over_A_K=y_linear.tolist(),
        breakaway_amplitude_N=np.asarray(breakaway.amplitude).tolist(),
        breakaway_minimum_N=float(breakaway.minimum),
        breakaway_minimum_frequency_Hz=float(breakaway.omega_minimum) / (2 * math.pi),
    )
    return breakaway


def _solve(system, quantity, omegas, amplitudes, settings, output) -> _Grid:
    """The frequency response, one amplitude after another (a progress step each)."""
    shape = (amplitudes.size, omegas.size)
    grid = _Grid(np.empty(shape), np.empty(shape), np.empty(shape, bool), np.empty(shape, bool),
                 np.empty(shape), np.empty(shape, int))
    unit = parameter_unit("amplitude", system)
    with output.steps(amplitudes.size) as step:
        for i, amplitude in enumerate(amplitudes):
            response = frequency_response(system, omegas, amplitude, quantity=quantity,
                                          settings=settings)
            for name, array in zip(_Grid._fields, grid, strict=True):
                array[i] = np.asarray(getattr(response, name)).reshape(-1)
            step(
                f"amplitude {i + 1}/{amplitudes.size} (A = {amplitude:g} {unit}): "
                f"{grid.converged[i].sum()}/{omegas.size} steady states converged"
            )
    return grid


def _records(system, quantity, grid: _Grid, amplitudes, frequencies_hz, uncontrolled,
             bare) -> list[dict]:
    """One record per amplitude and frequency, keyed by `FRF_COLUMNS`: the normalised
    columns (over A/K, and the linear TID's) on the paper's host only."""
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    if quantity is None:
        stiffness = float(system.host_stiffness)
        x_linear, y_linear = _linear_normalised(system, frequencies_hz)
    stable = grid.converged & grid.stable
    records = []
    for i, a in enumerate(amplitudes):
        for j, f in enumerate(frequencies_hz):
            normalised = {} if quantity is not None else dict(
                x_over_A_K=finite(grid.x_max[i, j] * stiffness / a),
                x_linear_over_A_K=float(x_linear[j]),
                y_over_A_K=finite(grid.y_max[i, j] * stiffness / a),
                y_linear_over_A_K=float(y_linear[j]))
            records.append(row(
                FRF_COLUMNS, amplitude=float(a), amplitude_unit=parameter_unit("amplitude",
                                                                               system),
                frequency_Hz=float(f), k_N_per_m=k, c_N_s_per_m=c,
                peak_unit="m" if quantity is None else quantity.unit,
                peak=finite(grid.x_max[i, j]), uncontrolled_peak=float(uncontrolled[i, j]),
                peak_over_uncontrolled=ratio(grid.x_max[i, j], bare[i]), **normalised,
                stroke_m=finite(grid.y_max[i, j]),
                stick_fraction=finite(grid.stick_fraction[i, j]),
                transitions=int(grid.transitions[i, j]), stable=bool(stable[i, j]),
                converged=bool(grid.converged[i, j]),
                status=status(bool(grid.converged[i, j]),
                              "unstable" if grid.converged[i, j] and not stable[i, j] else "")))
    return records


def _table(summary, system, stroke_limit) -> str:
    title = (
        f"Frequency response ({_describe(system)}); peaks on the grid, x normalised by "
        f"the static displacement A/K"
    )
    return title + "\n" + table(FRF_TABLE, summary, limit_cm=100 * stroke_limit)
