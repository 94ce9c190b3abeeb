"""`tid-jax random`: the TID's k and c retuned per intensity S0 of a stationary random
load, with its friction (Monte Carlo with common random numbers, and the statistical
linearisation's design), judged by an independent Monte Carlo run; and what `tid-jax
records` shares with it: the system (the single-storey host or a [structure]) as a
`BuildingTID`, the response quantity, the JSON record and the saved config."""

import math
import textwrap
from typing import NamedTuple

import numpy as np
from scipy import signal

from .. import __version__, plot
from .._loads._monte_carlo import MonteCarloSettings, first_period, plan, random_history
from .._loads._random_design import default_bounds, retune_random
from .._loads._stationary import StationaryLoad, rms_response
from .._model._building import BuildingTID, Quantity, as_building, linear_building_response
from .._model._system import TIDSystem
from .._runtime._io import write_json
from . import _building
from ._arguments import _add_output_arguments, _add_structure_arguments
from ._building_config import RANDOM_KEYS, RANDOM_KINDS
from ._common import PROG, CLIError, _describe, _inputs, _number, _Output, _system
from ._schema import RANDOM_COLUMNS, finite, ratio, row, status, stroke_problem
from ._tables import save_records, shown, table

# S0 (N^2 s/rad) of the white-noise force on the paper's host by default: from the inerter
# held by its friction most of the time to slipping most of the time.
DEFAULT_PSD_LEVELS = (30.0, 100.0, 300.0, 1000.0, 3000.0)
PSD_UNITS = {"force": "N^2 s/rad", "ground": "(m/s2)^2 s/rad"}
LOAD_NAMES = {"force": "force", "ground": "ground acceleration"}
# The harmonic commands' inputs, which do not apply to `random` and `records`.
HARMONIC_INPUTS = ("amplitudes", "amplitudes_given", "band_hz", "n_frequencies")
def _add_random_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "random",
        help="retune the TID's k and c per intensity of a stationary random load",
        description="For each intensity S0 of a stationary random load (white noise, or a "
        "Kanai-Tajimi or Clough-Penzien ground acceleration: [load] kind in --config), find "
        "the TID stiffness k and damping c that minimise the RMS response with the "
        "inerter's friction, by Monte Carlo (common random numbers; also the statistical "
        "linearisation's design), and compare the RMS with the given and the retuned "
        "tuning by an independent Monte Carlo run (standard errors SE; exact, SE 0, "
        "without friction). Default: the paper's host under a white-noise force. Each level "
        "with friction takes tens of seconds at the default --samples and --duration. "
        "Prints a table and saves random.csv, random.json, random_config.toml, "
        "random_rms.png, random_history.png and random_spectrum.png to --out.",
    )
    _add_structure_arguments(
        parser,
        "TOML file with the structure and device keys, as for the other commands, and a "
        "[load] table: on = 'force' | 'ground', kind = 'white_noise' (default here) | "
        "'kanai_tajimi' | 'clough_penzien', psd_levels (S0), ground_frequency, "
        "ground_damping, filter_frequency, filter_damping (rad/s and ratios); [response] "
        "kind and floor",
    )
    load = parser.add_argument_group("random load")
    load.add_argument(
        "--psd", nargs="+", type=float, metavar="S0",
        help="intensities to retune at: S0, the two-sided spectral density over angular "
        "frequency of the white noise [N^2 s/rad; (m/s2)^2 s/rad for a ground acceleration] "
        "(overrides [load] psd_levels; default for the single-storey host under a force: "
        f"{' '.join(f'{s:g}' for s in DEFAULT_PSD_LEVELS)})",
    )
    _add_monte_carlo_arguments(parser.add_argument_group("Monte Carlo"))
    limits = parser.add_argument_group("design limits")
    add_bounds_arguments(limits)
    limits.add_argument(
        "--stroke-rms-limit", type=float, metavar="M",
        help="limit on the Monte Carlo design's stroke RMS [m] (default: none)")
    _add_output_arguments(parser)
    parser.set_defaults(amplitudes=None, band_hz=None, n_frequencies=None)


def _add_monte_carlo_arguments(group) -> None:
    defaults = MonteCarloSettings()
    group.add_argument("--samples", type=int, default=defaults.samples, metavar="N",
                       help=f"realisations (default {defaults.samples})")
    group.add_argument("--duration", type=float, default=defaults.duration, metavar="S",
                       help=f"length of each realisation [s] (default {defaults.duration:g})")
    group.add_argument("--transient", type=float, metavar="S",
                       help="its first part left out of the statistics [s] (default: 20 "
                       "periods of the first mode with the TID)")
    group.add_argument("--time-step", dest="time_step", type=float, metavar="S",
                       help="time step [s] (default: that period / 200)")
    group.add_argument("--seed", type=int, default=defaults.seed, metavar="N",
                       help=f"random seed (default {defaults.seed}; the standard errors come "
                       "from a run with seed + 1)")


# --- what `random` and `records` share ----------------------------------------------------


class Case(NamedTuple):
    """What `random` and `records` compute on: the `system`, the `quantity`, the
    single-storey `host` (None for a [structure]) and the description of the three."""

    system: BuildingTID
    quantity: Quantity
    host: TIDSystem | None
    description: str


def case_inputs(args) -> dict:
    """The inputs (`_inputs`) without the harmonic commands' amplitudes and band."""
    return {key: value for key, value in _inputs(args).items() if key not in HARMONIC_INPUTS}


def build_case(inputs: dict, on: str) -> Case:
    """The system (a [structure], else the single-storey host) under the load `on`
    ("force" or "ground"), and its [response]."""
    if on not in LOAD_NAMES:
        raise CLIError(f"[load] on must be 'force' or 'ground', got {on!r}")
    if "structure" in inputs:
        load = {**inputs.get("load", {}), "on": on}
        system, quantity, _ = _building.building_inputs(
            {**inputs, "load": load, "amplitudes": [1.0], "amplitudes_given": True})
        return Case(system, quantity, None, f"{_building.describe(system, quantity)}; given "
                    f"k = {float(system.tid_stiffness):.5g} N/m, c = "
                    f"{float(system.tid_damping):.4g} N s/m")
    host = _system(inputs)
    response = inputs.get("response", {})
    try:
        system = as_building(host, load=on)
        quantity = Quantity(response.get("kind", "displacement"), response.get("floor"))
        quantity.floor_of(1)
    except ValueError as error:
        raise CLIError(str(error)) from None
    return Case(system, quantity, host,
                f"{_describe(host)}; {LOAD_NAMES[on]}; {quantity.describe(1)}")


def document(command: str, inputs: dict, case: Case, output: _Output, **results) -> dict:
    """The JSON record of a run: inputs, the system (a single-storey host's fields, or a
    structure's matrices and its TID), the friction model, the response, the given
    tuning, results and the files written."""
    system, quantity = case.system, case.quantity
    if case.host is not None:
        where = {"system": case.host.to_dict()}
    else:
        building = _building.document(command, inputs, system, quantity, [], output)
        where = {key: building[key] for key in ("structure", "tid")}
    width = system.friction_width
    return {
        "command": f"{PROG} {command}",
        "version": __version__,
        "inputs": inputs,
        **where,
        # 0: exact Coulomb friction; null: the width relative to the frictionless RMS
        # velocity of the friction's coordinate
        "friction_width": None if width is None else float(width),
        "response": {"kind": quantity.kind, "floor": quantity.floor_of(system.floors),
                     "unit": quantity.unit, "describes": quantity.describe(system.floors)},
        "given_tuning": {"tid_stiffness": float(system.tid_stiffness),
                         "tid_damping": float(system.tid_damping)},
        **results,
        "files": [str(path) for path in output.files],
    }


def tuned(system: BuildingTID, k, c) -> BuildingTID:
    return system.replace(tid_stiffness=float(k), tid_damping=float(c))


def wrapped(title: str) -> str:
    """A figure's title in lines of at most 130 characters."""
    return textwrap.fill(title, 130)


# --- `random` ---------------------------------------------------------------------------


def _stationary_load(inputs: dict, case: Case, psd_flag) -> tuple[dict, np.ndarray]:
    """The random load's `StationaryLoad` arguments but S0, and the levels S0."""
    table = inputs.get("load", {})
    kind = table.get("kind", "white_noise")
    if kind not in RANDOM_KINDS:
        raise CLIError(f"{PROG} random needs a random load: [load] kind = "
                       f"{' | '.join(repr(k) for k in RANDOM_KINDS)}, got {kind!r}")
    parameters = {key: _number(f"[load] {key}", table[key], "positive")
                  for key in RANDOM_KEYS[1:] if key in table}
    name, levels = ("--psd", psd_flag) if psd_flag is not None else (
        "[load] psd_levels", table.get("psd_levels"))
    if levels is None:
        if case.host is None or case.system.load != "force":
            raise CLIError(f"give the intensities S0 to retune at: [load] psd_levels or --psd "
                           f"({PSD_UNITS[case.system.load]})")
        levels = list(DEFAULT_PSD_LEVELS)
    levels = levels if isinstance(levels, list | tuple) else [levels]
    if not levels:
        raise CLIError(f"{name} must not be empty")
    levels = np.asarray([_number(name, level, "positive") for level in levels])
    try:
        StationaryLoad(kind, float(levels[0]), **parameters)
    except ValueError as error:
        raise CLIError(f"[load]: {error}") from None
    return {"kind": kind, **parameters}, levels


def _run_random(args) -> int:
    inputs = case_inputs(args)
    on = inputs.get("load", {}).get("on", "force")
    case = build_case(inputs, on)
    system, quantity = case.system, case.quantity
    parameters, levels = _stationary_load(inputs, case, args.psd)
    load = lambda s0: StationaryLoad(psd=float(s0), **parameters)
    settings = MonteCarloSettings(samples=args.samples, duration=args.duration,
                                  transient=args.transient, time_step=args.time_step,
                                  seed=args.seed)
    run_plan = plan(system, settings)  # (checks the duration against the transient)
    inputs["load"] = {**inputs.get("load", {}), "on": on, "kind": parameters["kind"],
                      "psd_levels": levels.tolist()}
    frictionless = [float(rms_response(system, load(s0), quantity)) for s0 in levels]
    unit = PSD_UNITS[on]
    output = _Output(args)
    output.say(f"retuning k and c at {levels.size} intensities S0 of a "
               f"{parameters['kind'].replace('_', '-')} {LOAD_NAMES[on]} by Monte Carlo "
               f"({settings.samples} realisations of {settings.duration:g} s, step "
               f"{1e3 * run_plan.time_step:.3g} ms){_cost(system)}; {case.description}")
    top = int(np.argmax(levels))
    with output.steps(levels.size + 1) as step:
        design = retune_random(
            system, load(levels[0]), levels, quantity, settings=settings,
            bounds=design_bounds(args, system), stroke_limit=args.stroke_rms_limit,
            progress=lambda done, total: step(
                f"S0 = {levels[done - 1]:g} {unit}: retuned ({done}/{total})"))
        retuned = tuned(system, design.tid_stiffness[top], design.tid_damping[top])
        # both on the given tuning's time step and transient: the same noise
        common = MonteCarloSettings(
            samples=settings.samples, duration=settings.duration, seed=settings.seed,
            transient=run_plan.first * run_plan.time_step, time_step=run_plan.time_step)
        histories = [random_history(s, load(levels[top]), quantity, settings=common)
                     for s in (system, retuned)]
        step(f"time histories at S0 = {levels[top]:g} {unit}, given and retuned tuning")
    records = _records(design, frictionless, histories, top, unit, quantity.unit,
                       inputs["stroke_limit"])
    save_records(output, "random.csv", RANDOM_COLUMNS, records)
    _building.save_config(inputs, output, "random")
    _save_plots(output, case, design, records, histories, run_plan, load(levels[top]), unit)
    load_record = {"on": on, **parameters, "psd_unit": unit}
    json_path = output.path("random.json")
    data = document("random", inputs, case, output, load=load_record,
                    settings={"samples": settings.samples, "duration": settings.duration,
                              "transient": run_plan.first * run_plan.time_step,
                              "time_step": run_plan.time_step, "seed": settings.seed},
                    history={"psd": float(levels[top]),
                             "rms_before": float(histories[0].rms),
                             "rms_after": float(histories[1].rms),
                             "peak_before": float(histories[0].peak),
                             "peak_after": float(histories[1].peak)},
                    results=records)
    write_json(json_path, data)
    notes = "".join(f"\nS0 = {r['psd']:g} {unit}: {r['linearised_status']}" for r in records
                    if r["linearised_status"] != "ok")
    return output.finish(data, _table(records, case, parameters["kind"], unit) + notes)


def add_bounds_arguments(group) -> None:
    """--stiffness-bounds and --damping-bounds, for a design's (k, c)."""
    group.add_argument(
        "--stiffness-bounds", nargs=2, type=float, metavar=("LOW", "HIGH"),
        help="bounds on k [N/m] (default: 1/10 and 10 times the first mode's Den Hartog k)")
    group.add_argument(
        "--damping-bounds", nargs=2, type=float, metavar=("LOW", "HIGH"),
        help="bounds on c [N s/m] (default: 1/10 and 10 times the first mode's Den "
        "Hartog c)")


def design_bounds(args, system: BuildingTID):
    """The bounds on (k, c) of --stiffness-bounds and --damping-bounds, the default for
    one not given; None where neither is."""
    if args.stiffness_bounds is None and args.damping_bounds is None:
        return None
    default = default_bounds(system)
    return (default[0] if args.stiffness_bounds is None else tuple(args.stiffness_bounds),
            default[1] if args.damping_bounds is None else tuple(args.damping_bounds))


def _limit_records(design) -> list[dict]:
    """Per level: the linearisation's outcome (its text), the stroke RMS before and
    after (m), and whether a bound and the stroke limit are active."""
    columns = {name: np.asarray(getattr(design, name)) for name in (
        "stroke_rms_before", "stroke_rms_after", "at_bound", "stroke_limited")}
    return [{"linearised_status": message,
             **{name + ("_m" if name.startswith("stroke_rms") else ""):
                (bool(c[i]) if c.dtype == bool else finite(c[i]))
                for name, c in columns.items()}}
            for i, message in enumerate(design.linearised_messages())]


def _cost(system: BuildingTID) -> str:
    if float(system.friction_force) == 0:
        return "; without friction the RMS and the optimum are exact"
    return "; each level takes tens of seconds at the default settings"


def _records(design, frictionless, histories, top, psd_unit, rms_unit,
             stroke_limit) -> list[dict]:
    """One record per level S0, keyed by `RANDOM_COLUMNS`; the strokes (the first
    realisation's peaks) at the level `top` of the time histories."""
    def column(name):
        return np.asarray(getattr(design, name))

    records = []
    limits = _limit_records(design)
    for i, s0 in enumerate(column("psd_levels")):
        stroke = ({} if i != top else {
            f"stroke_{when}_m": float(np.max(np.abs(np.asarray(h.stroke))))
            for when, h in zip(("before", "after"), histories, strict=True)})
        converged = bool(column("converged")[i])
        records.append(row(
            RANDOM_COLUMNS, psd=float(s0), psd_unit=psd_unit,
            k_N_per_m=finite(column("tid_stiffness")[i]),
            c_N_s_per_m=finite(column("tid_damping")[i]), rms_unit=rms_unit,
            rms_before=finite(column("rms_before")[i]),
            rms_before_se=finite(column("rms_before_se")[i]),
            rms_after=finite(column("rms_after")[i]),
            rms_after_se=finite(column("rms_after_se")[i]),
            rms_after_over_before=ratio(column("rms_after")[i], column("rms_before")[i]),
            linearised_k_N_per_m=finite(column("linearised_stiffness")[i]),
            linearised_c_N_s_per_m=finite(column("linearised_damping")[i]),
            rms_linearised=finite(column("rms_linearised")[i]),
            rms_linearised_se=finite(column("rms_linearised_se")[i]),
            rms_frictionless=finite(frictionless[i]), converged=converged,
            status=status(converged, stroke_problem(stroke.get("stroke_after_m"),
                                                    stroke_limit)),
            **stroke, **limits[i]))
    return records


def _save_plots(output, case, design, records, histories, run_plan, load, unit) -> None:
    system, quantity = case.system, case.quantity
    described, q_unit = quantity.describe(system.floors), quantity.unit
    levels = np.asarray(design.psd_levels)
    column = lambda key: np.asarray([np.nan if r[key] is None else r[key] for r in records])
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    xlabel = f"intensity S0 [{unit}]"
    plot.save_figure(plot.plot_random_design(
        levels, {"given tuning": (column("rms_before"), column("rms_before_se")),
                 "retuned (Monte Carlo)": (column("rms_after"), column("rms_after_se")),
                 "linearisation's design": (column("rms_linearised"),
                                            column("rms_linearised_se")),
                 "given tuning, no friction (exact)": (column("rms_frictionless"),
                                                       np.zeros(levels.size))},
        {"k / k given": column("k_N_per_m") / k, "c / c given": column("c_N_s_per_m") / c,
         "k / k given, linearisation": column("linearised_k_N_per_m") / k,
         "c / c given, linearisation": column("linearised_c_N_s_per_m") / c},
        xlabel=xlabel, ylabel=f"RMS {described} [{q_unit}]",
        title=wrapped(f"TID retuned per intensity: {case.description}")),
        output.path("random_rms.png"))
    s0 = float(load.psd)
    time = np.asarray(histories[0].time)
    curves = lambda name, scale=1.0: {label: scale * np.asarray(getattr(h, name))
                                      for label, h in zip(TUNINGS, histories, strict=True)}
    plot.save_figure(plot.plot_histories(
        [(f"{described}", f"[{q_unit}]", time, curves("quantity")),
         ("TID stroke", "[mm]", time, curves("stroke", 1e3))],
        shade=(0.0, run_plan.first * run_plan.time_step, "transient (left out)"),
        title=f"The first realisation at S0 = {s0:g} {unit}"),
        output.path("random_history.png"))
    top = _top_frequency(system, run_plan.time_step)
    squared = f"({q_unit})" if "/" in q_unit else q_unit
    plot.save_figure(plot.plot_spectra(
        _spectra(histories, run_plan, system, quantity, load, top),
        ylabel=f"two-sided PSD over angular frequency [{squared}^2 s/rad]", xmax=top,
        title=f"Spectral density of the {described} at S0 = {s0:g} {unit}\n(Welch, the "
        "first realisation after its transient)"), output.path("random_spectrum.png"))


TUNINGS = ("given tuning", "retuned")


def _spectra(histories, run_plan, system, quantity, load, top: float) -> dict:
    """The two-sided densities over angular frequency of the histories' counted parts
    (Welch's one-sided density per Hz over 4 pi), and the frictionless exact one up to
    `top` (Hz)."""
    counted = [np.asarray(h.quantity)[run_plan.first:] for h in histories]
    segment = min(counted[0].size, max(256, 2 ** int(math.log2(max(counted[0].size // 4, 1)))))
    curves = {}
    for label, values in zip(TUNINGS, counted, strict=True):
        frequencies, density = signal.welch(values, fs=1 / run_plan.time_step,
                                            nperseg=segment)
        curves[label] = (frequencies, density / (4 * math.pi))
    fine = np.linspace(0, top, 801)[1:]
    omegas = 2 * math.pi * fine
    exact = linear_building_response(system, omegas, quantity) ** 2 * np.asarray(
        load.spectrum(omegas))
    curves["given tuning, no friction (exact)"] = (fine, exact)
    return curves


def _top_frequency(system: BuildingTID, time_step: float) -> float:
    """The spectra's upper frequency (Hz): three times the first mode's with the TID, or
    1.5 times the structure's highest, below the Nyquist frequency."""
    highest = float(np.max(system.structure.natural_frequencies_hz()))
    return min(max(3 / first_period(system), 1.5 * highest), 0.5 / time_step)


def _table(records, case: Case, kind: str, unit: str) -> str:
    q_unit = case.quantity.unit
    columns = [shown(f"S0 ({unit})", "psd", "g"), shown("k (N/m)", "k_N_per_m", ".5g"),
               shown("c (N s/m)", "c_N_s_per_m", ".4g"),
               shown(f"RMS given ({q_unit})", "rms_before", ".4g"),
               shown("SE", "rms_before_se", ".2g"),
               shown(f"RMS retuned ({q_unit})", "rms_after", ".4g"),
               shown("SE", "rms_after_se", ".2g"),
               shown("linearised design", "rms_linearised", ".4g"),
               shown("no friction", "rms_frictionless", ".4g"),
               shown("stroke after (mm)", "stroke_after_m", ".3g", unit=1e-3),
               shown("status", "status", "s")]
    title = (f"TID retuned per intensity of a {kind.replace('_', '-')} load, RMS by Monte "
             f"Carlo (SE: standard error; '-': no linearised design): {case.description}")
    return title + "\n" + table(columns, records)
