"""`tid-jax sensitivity`: sensitivities of the peaks, at the tuning and the optimum."""



from .. import plot
from .._design import PARAMETER_UNITS
from .._io import write_json, write_toml
from .._response import _on_host
from .._retune import RetuneSettings
from .._sensitivity import amplitude_sensitivities, elasticity_series
from . import _building
from ._arguments import _add_output_arguments, _add_system_arguments
from ._common import _config_comment, _config_data, _describe, _inputs, _start
from ._tables import Shown, save_records, shown, table

SENSITIVITY_COLUMNS = (
    "amplitude_N",
    "parameter",
    "value",
    "unit",
    "host_peak_m",
    "host_derivative_m_per_unit",
    "host_elasticity",
    "stroke_peak_m",
    "stroke_derivative_m_per_unit",
    "stroke_elasticity",
    "optimum_k_N_per_m",
    "optimum_c_N_s_per_m",
    "optimum_host_elasticity",
    "optimum_stroke_elasticity",
    "optimum_stiffness_elasticity",
    "optimum_damping_elasticity",
    "converged",
    "optimum_converged",
    "optimum_damping_at_bound",
)


# The printed table, a row per amplitude and parameter; the optimum's columns where it
# was found.
SENSITIVITY_TABLE = (
    shown("A [N]", "amplitude_N", "g"),
    shown("parameter", "parameter", "s"),
    shown("value", "value", ".5g"),
    shown("unit", "unit", "s"),
    shown("d x/dp [m/unit]", "host_derivative_m_per_unit", ".3e"),
    shown("e_x", "host_elasticity", ".4f"),
    shown("e_y", "stroke_elasticity", ".4f"),
)
OPTIMUM_TABLE = (
    shown("e_x retuned", "optimum_host_elasticity", ".4f"),
    shown("e_y retuned", "optimum_stroke_elasticity", ".4f"),
    shown("e_k*", "optimum_stiffness_elasticity", ".4f"),
    Shown("e_c*", lambda r: "c* at 0" if r["optimum_damping_at_bound"]
          else f"{r['optimum_damping_elasticity']:.4f}"),
)


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
    inputs = _inputs(args)
    if "structure" in inputs:
        return _building.run_sensitivity(args, inputs)
    start = _start(args)
    inputs, system, settings, frequencies_hz, omegas, amplitudes, output = start
    optimum = not args.no_optimum
    output.say(
        f"sensitivities at {amplitudes.size} amplitude(s) over {omegas.size} frequencies"
        f"{', with the retuned optimum' if optimum else ''}; {_describe(system)}"
    )
    retune_steps = RetuneSettings().progress_steps() if optimum else 0
    with output.steps(retune_steps + (2 if optimum else 1)) as step:
        if optimum:
            output.say(f"retuning at {amplitudes.size} amplitude(s), all in one batch")
        results = amplitude_sensitivities(system, amplitudes, omegas=omegas, optimum=optimum,
                                          settings=settings, progress=step,
                                          map_lanes=args.map_lanes)
    results = _on_host(results)  # read entry by entry below: no array operation each
    records = [record for amplitude, result in zip(amplitudes, results, strict=True)
               for record in _records(amplitude, result)]
    save_records(output, "sensitivity.csv", SENSITIVITY_COLUMNS, records)
    write_toml(
        output.path("sensitivity_config.toml"),
        _config_data(inputs),
        comment=_config_comment("sensitivity"),
    )
    if amplitudes.size > 1:
        _save_plot(output, amplitudes, results)
    json_path = output.path("sensitivity.json")
    data = output.document("sensitivity", inputs, system, settings, frequencies_hz, results=records)
    write_json(json_path, data)
    return output.finish(data, _table(records, results, amplitudes, system, optimum))


def _records(amplitude, result) -> list[dict]:
    """One record per parameter at one amplitude, keyed by `SENSITIVITY_COLUMNS`."""
    optimum = result.optimum
    at_bound = optimum is not None and bool(optimum.damping_at_bound)
    records = []
    for i, name in enumerate(result.parameters):
        optimal = (
            [None] * 8
            if optimum is None
            else [
                float(optimum.tid_stiffness),
                float(optimum.tid_damping),
                float(optimum.host_elasticity[i]),
                float(optimum.stroke_elasticity[i]),
                float(optimum.stiffness_elasticity[i]),
                # Undefined (c* held at 0 by its bound): left empty.
                None if at_bound else float(optimum.damping_elasticity[i]),
                at_bound,
                bool(optimum.converged),
            ]
        )
        values = [
            float(amplitude),
            name,
            float(result.values[i]),
            PARAMETER_UNITS[name],
            float(result.host_peak),
            float(result.host_derivative[i]),
            float(result.host_elasticity[i]),
            float(result.stroke_peak),
            float(result.stroke_derivative[i]),
            float(result.stroke_elasticity[i]),
            *optimal[:6],
            bool(result.converged),
            optimal[7],
            optimal[6],
        ]
        records.append(dict(zip(SENSITIVITY_COLUMNS, values, strict=True)))
    return records


def _save_plot(output, amplitudes, results) -> None:
    """The elasticities against amplitude."""
    host, stroke, optimum_host, optimum_stroke = elasticity_series(results)
    plot.save_figure(
        plot.plot_elasticities(amplitudes, host, stroke, optimum_host=optimum_host,
                               optimum_stroke=optimum_stroke),
        output.path("sensitivity.png"),
    )


def _table(records, results, amplitudes, system, optimum: bool) -> str:
    """The printed table, ranked by |e_x| per amplitude, with its title."""
    columns = SENSITIVITY_TABLE + (OPTIMUM_TABLE if optimum else ())
    ranked = [
        r
        for amplitude in amplitudes
        for r in sorted((r for r in records if r["amplitude_N"] == float(amplitude)),
                        key=lambda r: -abs(r["host_elasticity"]))
    ]
    unconverged = [
        f"{a:g} N"
        for a, r in zip(amplitudes, results, strict=True)
        if not bool(r.converged) or (r.optimum is not None and not bool(r.optimum.converged))
    ]
    title = (
        f"Sensitivities of the peak responses ({_describe(system)}); e_x, e_y: elasticities "
        f"d ln(peak) / d ln(p) of the host peak and the inerter stroke; 'retuned': at the "
        f"tuning retuned for that amplitude, e_k*, e_c*: of its k and c ('c* at 0': the "
        f"optimal damping is at its bound 0, where it stays); ranked by |e_x|"
        + (f"\nnot converged at {', '.join(unconverged)}" if unconverged else "")
    )
    return title + "\n" + table(columns, ranked)
