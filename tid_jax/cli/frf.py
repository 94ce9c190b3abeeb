"""`tid-jax frf`: the steady-state frequency response and the breakaway amplitude."""

import math
from typing import NamedTuple

import numpy as np

from .. import plot
from .._model._building import Quantity, as_building, uncontrolled_amplitude
from .._model._linear import host_breakaway
from .._response import frequency_response
from .._runtime._io import write_json, write_toml
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._common import (
    _breakaway_line,
    _config_comment,
    _config_data,
    _describe,
    _host_frequency_hz,
    _inputs,
    _linear_curves,
    _linear_normalised,
    _start,
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
    inputs = _inputs(args)
    if "structure" in inputs:
        return _building.run_frf(args, inputs)
    inputs, system, settings, frequencies_hz, omegas, amplitudes, output = _start(args)
    output.say(
        f"frequency response at {amplitudes.size} amplitude(s) x {omegas.size} "
        f"frequencies; {_describe(system)}"
    )
    grid = _solve(system, omegas, amplitudes, settings, output)
    static = (amplitudes / float(system.host_stiffness))[:, None]
    x_norm, y_norm = grid.x_max / static, grid.y_max / static
    x_linear, y_linear = _linear_normalised(system, frequencies_hz)
    records = _records(system, grid, amplitudes, frequencies_hz, omegas, x_linear, y_linear)
    breakaway = host_breakaway(system, omegas)
    save_records(output, "frf.csv", FRF_COLUMNS, records)
    write_toml(output.path("frf_config.toml"), _config_data(inputs), comment=_config_comment("frf"))
    plot.save_figure(
        plot.plot_frequency_response(
            frequencies_hz,
            amplitudes,
            x_norm,
            y_norm,
            linear=_linear_curves(system, frequencies_hz),
            stuck=(*_stuck_curve(system, frequencies_hz), float(breakaway.minimum)),
            host_frequency_hz=_host_frequency_hz(system),
        ),
        output.path("frf.png"),
    )
    summary = frf_summary(records, amplitudes, omegas.size)
    json_path = output.path("frf.json")
    data = output.document(
        "frf",
        inputs,
        system,
        settings,
        frequencies_hz,
        amplitudes_N=[float(a) for a in amplitudes],
        x_max_m=grid.x_max.tolist(),
        y_max_m=grid.y_max.tolist(),
        converged=grid.converged.tolist(),
        stable=grid.stable.tolist(),
        stick_fraction=grid.stick_fraction.tolist(),
        transitions=grid.transitions.tolist(),
        x_linear_over_A_K=x_linear.tolist(),
        y_linear_over_A_K=y_linear.tolist(),
        breakaway_amplitude_N=np.asarray(breakaway.amplitude).tolist(),
        breakaway_minimum_N=float(breakaway.minimum),
        breakaway_minimum_frequency_Hz=float(breakaway.omega_minimum) / (2 * math.pi),
        summary=summary,
        results=records,
    )
    write_json(json_path, data)
    return output.finish(data, _table(summary, system, inputs["stroke_limit"]) + "\n"
                         + _breakaway_line(breakaway))


def _solve(system, omegas, amplitudes, settings, output) -> _Grid:
    """The frequency response, one amplitude after another (a progress step each)."""
    shape = (amplitudes.size, omegas.size)
    grid = _Grid(np.empty(shape), np.empty(shape), np.empty(shape, bool), np.empty(shape, bool),
                 np.empty(shape), np.empty(shape, int))
    with output.steps(amplitudes.size) as step:
        for i, amplitude in enumerate(amplitudes):
            response = frequency_response(system, omegas, amplitude, settings=settings)
            for name, array in zip(_Grid._fields, grid, strict=True):
                array[i] = np.asarray(getattr(response, name))
            step(
                f"amplitude {i + 1}/{amplitudes.size} (A = {amplitude:g} N): "
                f"{grid.converged[i].sum()}/{omegas.size} steady states converged"
            )
    return grid


def _records(system, grid: _Grid, amplitudes, frequencies_hz, omegas, x_linear,
             y_linear) -> list[dict]:
    """One record per amplitude and frequency, keyed by `FRF_COLUMNS`."""
    bare = np.asarray(uncontrolled_amplitude(as_building(system), Quantity(), omegas))
    bare_peak = _building.uncontrolled_peak(as_building(system), Quantity(), omegas)
    stiffness = float(system.host_stiffness)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    return [
        row(FRF_COLUMNS, amplitude=float(a), amplitude_unit="N",
            frequency_Hz=float(frequencies_hz[j]), k_N_per_m=k, c_N_s_per_m=c,
            peak_unit="m", peak=finite(grid.x_max[i, j]),
            uncontrolled_peak=float(a * bare[j]),
            peak_over_uncontrolled=ratio(grid.x_max[i, j], a * bare_peak),
            x_over_A_K=finite(grid.x_max[i, j] * stiffness / a),
            x_linear_over_A_K=float(x_linear[j]),
            y_over_A_K=finite(grid.y_max[i, j] * stiffness / a),
            y_linear_over_A_K=float(y_linear[j]), stroke_m=finite(grid.y_max[i, j]),
            stick_fraction=finite(grid.stick_fraction[i, j]),
            transitions=int(grid.transitions[i, j]), stable=bool(grid.stable[i, j]),
            converged=bool(grid.converged[i, j]),
            status=status(bool(grid.converged[i, j]), "" if grid.stable[i, j] else "unstable"))
        for i, a in enumerate(amplitudes)
        for j in range(omegas.size)
    ]


def _table(summary, system, stroke_limit) -> str:
    title = (
        f"Frequency response ({_describe(system)}); peaks on the grid, x normalised by "
        f"the static displacement A/K"
    )
    return title + "\n" + table(FRF_TABLE, summary, limit_cm=100 * stroke_limit)
