"""`tid-jax sensitivity`: sensitivities of the peaks, at the tuning and the optimum."""

from .. import plot
from .._optimise._design import parameter_unit
from .._response import _on_host
from .._retune import RetuneSettings
from .._runtime._io import write_json
from .._sensitivity import amplitude_sensitivities, elasticity_series
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._common import _inputs
from ._schema import SENSITIVITY_COLUMNS, finite, row, sensitivity_table, status
from ._tables import save_records, table


def _add_sensitivity_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sensitivity",
        help="derivatives of the peak responses with respect to every parameter",
        description="For each forcing amplitude: derivatives and elasticities (d ln peak / "
        "d ln p) of the peak host displacement and inerter stroke over the band with "
        "respect to the host mass, stiffness and damping, the inertance, the friction "
        "force, the TID stiffness and damping and the amplitude, at the given tuning and "
        "at the tuning retuned for that amplitude (envelope theorem and implicit "
        "differentiation). Prints a table ranked by the host elasticity and saves "
        "sensitivity.csv, sensitivity.json, sensitivity_config.toml and, for several "
        "amplitudes, sensitivity.png to --out. With a [structure]: the elasticities of the "
        "peak of the [response] quantity, in the TID's parameters, the amplitude, every "
        "floor's mass and every storey's stiffness, at the given tuning and of the "
        "retuned optimum's peak, k and c.",
    )
    _add_system_arguments(parser)
    parser.add_argument(
        "--no-optimum",
        action="store_true",
        help="only at the given tuning (skips finding the retuned optimum)",
    )
    _add_output_arguments(parser)


def _run_sensitivity(args) -> int:
    optimum = not args.no_optimum
    start = _building.design_start(
        args, _inputs(args), "sensitivities at {amplitudes} amplitude(s) over {frequencies} "
        "frequencies" + (", with the retuned optimum" if optimum else ""))
    system, quantity, amplitudes, output = (start.system, start.quantity, start.amplitudes,
                                            start.output)
    retune_steps = RetuneSettings().progress_steps() if optimum else 0
    with output.steps(retune_steps + (2 if optimum else 1)) as step:
        if optimum:
            output.say(f"retuning at {amplitudes.size} amplitude(s), all in one batch")
        results = amplitude_sensitivities(system, amplitudes, omegas=start.omegas,
                                          quantity=quantity, optimum=optimum,
                                          settings=start.settings, progress=step,
                                          map_lanes=args.map_lanes)
    results = _on_host(results)  # read entry by entry below: no array operation each
    peak_unit = "m" if quantity is None else quantity.unit
    records = [record for amplitude, result in zip(amplitudes, results, strict=True)
               for record in _records(amplitude, result, system, peak_unit)]
    save_records(output, "sensitivity.csv", SENSITIVITY_COLUMNS, records)
    _building.save_config(start.inputs, output, "sensitivity")
    _save_plot(output, amplitudes, results, system, quantity)
    extra = {} if quantity is None else dict(
        tid_stiffness_N_per_m=float(system.tid_stiffness),
        tid_damping_N_s_per_m=float(system.tid_damping))
    data = _building.design_document(start, "sensitivity", **extra, results=records)
    write_json(output.path("sensitivity.json"), data)
    return output.finish(data, _table(records, results, amplitudes, system, optimum,
                                      start.described))


def _records(amplitude, result, system, peak_unit: str) -> list[dict]:
    """One record per parameter at one amplitude, keyed by `SENSITIVITY_COLUMNS`."""
    optimum = result.optimum
    at_bound = optimum is not None and bool(optimum.damping_at_bound)
    ok = bool(result.converged) and (optimum is None or bool(optimum.converged))
    records = []
    for i, name in enumerate(result.parameters):
        optimal = {} if optimum is None else dict(
            optimum_k_N_per_m=float(optimum.tid_stiffness),
            optimum_c_N_s_per_m=float(optimum.tid_damping),
            optimum_peak=finite(optimum.host_peak),
            optimum_elasticity=finite(optimum.host_elasticity[i]),
            optimum_stroke_elasticity=finite(optimum.stroke_elasticity[i]),
            optimum_stiffness_elasticity=finite(optimum.stiffness_elasticity[i]),
            # Undefined (c* held at 0 by its bound): left empty.
            optimum_damping_elasticity=(None if at_bound
                                        else finite(optimum.damping_elasticity[i])),
            optimum_damping_at_bound=at_bound, optimum_converged=bool(optimum.converged))
        records.append(row(
            SENSITIVITY_COLUMNS, amplitude=float(amplitude),
            amplitude_unit=parameter_unit("amplitude", system),
            parameter=name, value=float(result.values[i]), unit=parameter_unit(name, system),
            k_N_per_m=float(system.tid_stiffness), c_N_s_per_m=float(system.tid_damping),
            peak_unit=peak_unit, peak=finite(result.host_peak),
            derivative_per_unit=finite(result.host_derivative[i]),
            elasticity=finite(result.host_elasticity[i]), stroke_m=finite(result.stroke_peak),
            stroke_derivative_m_per_unit=finite(result.stroke_derivative[i]),
            stroke_elasticity=finite(result.stroke_elasticity[i]),
            converged=bool(result.converged), status=status(ok), **optimal))
    return records


def _save_plot(output, amplitudes, results, system, quantity) -> None:
    """The elasticities against amplitude; for one amplitude, as bars."""
    host, stroke, optimum_host, optimum_stroke = elasticity_series(results)
    peak = ("host displacement" if quantity is None
            else quantity.describe(system.floors))
    if amplitudes.size == 1:
        figure = plot.plot_elasticity_bars(
            results[0].parameters, [host[name][0] for name in results[0].parameters],
            title=f"elasticities d ln peak / d ln p of the peak {peak}")
    else:
        figure = plot.plot_elasticities(
            amplitudes, host, stroke, optimum_host=optimum_host, optimum_stroke=optimum_stroke,
            xlabel=("forcing amplitude A [N]" if quantity is None
                    else _building.amplitude_label(system)), peak=peak)
    plot.save_figure(figure, output.path("sensitivity.png"))


def _table(records, results, amplitudes, system, optimum: bool, described: str) -> str:
    """The printed table, ranked by |e| per amplitude, with its title."""
    columns = sensitivity_table(optimum)
    ranked = [
        r
        for amplitude in amplitudes
        for r in sorted((r for r in records if r["amplitude"] == float(amplitude)),
                        key=lambda r: -abs(r["elasticity"] or 0.0))
    ]
    unconverged = [
        f"{a:g} {parameter_unit('amplitude', system)}"
        for a, r in zip(amplitudes, results, strict=True)
        if not bool(r.converged) or (r.optimum is not None and not bool(r.optimum.converged))
    ]
    title = (
        f"Sensitivities of the peak responses ({described}); e, e_stroke: elasticities "
        f"d ln(peak) / d ln(p) of the peak and the inerter stroke; 'retuned': at the "
        f"tuning retuned for that amplitude, e_k*, e_c*: of its k and c ('c* at 0': the "
        f"optimal damping is at its bound 0, where it stays); ranked by |e|"
        + (f"\nnot converged at {', '.join(unconverged)}" if unconverged else "")
    )
    return title + "\n" + table(columns, ranked)
