"""The one output schema: each command's columns (its CSV header and the keys of its
JSON's per-row results), the same for the single-storey host and for a [structure].

A name carries its unit where the unit is fixed (`k_N_per_m`, `stroke_after_m`,
`frequency_Hz`); where it depends on the load or on the response asked for, the name has
none and a column ending in `_unit` gives it (`amplitude` and `amplitude_unit`: N for a
force, m/s2 for a ground acceleration; `peak_before` and `peak_unit`: m, or m/s2 for an
acceleration). A column that does not apply to a system is present and empty (null in the
JSON). `status` starts with "ok" where the computation converged (else it says what
did not) and adds the problems found, such as a stroke over its limit, after "; "."""

from collections.abc import Sequence

from .._model._building import LOAD_UNITS
from ._tables import Shown, shown

OK = "ok"
NOT_CONVERGED = "not converged: a steady state or the search was not found to tolerance"

RETUNE_COLUMNS = (
    "amplitude", "amplitude_unit",
    "k_N_per_m", "c_N_s_per_m", "k_over_k_den_hartog", "c_over_c_den_hartog",
    "peak_unit", "peak_before", "peak_after", "peak_frequency_after_Hz",
    "peak_after_over_before", "peak_after_over_den_hartog", "peak_after_over_uncontrolled",
    "x_peak_before_over_A_K", "x_peak_after_over_A_K",
    "stroke_before_m", "stroke_after_m", "stroke_limit_m", "within_stroke_limit",
    "converged", "status",
)
FRF_COLUMNS = (
    "amplitude", "amplitude_unit", "frequency_Hz", "k_N_per_m", "c_N_s_per_m",
    "peak_unit", "peak", "uncontrolled_peak", "peak_over_uncontrolled",
    "x_over_A_K", "x_linear_over_A_K", "y_over_A_K", "y_linear_over_A_K",
    "stroke_m", "stick_fraction", "transitions", "stable", "converged", "status",
)
# `frf`'s summary per amplitude (its JSON's "summary" and its printed table)
FRF_SUMMARY_COLUMNS = (
    "amplitude", "amplitude_unit", "peak_unit", "peak", "peak_frequency_Hz",
    "peak_over_uncontrolled", "x_peak_over_A_K", "stroke_m", "converged_points", "points",
    "unstable_points", "status",
)
ROBUST_COLUMNS = (
    "frequency_scale", "amplitude", "amplitude_unit", "k_N_per_m", "c_N_s_per_m",
    "best_k_N_per_m", "best_c_N_s_per_m",
    "peak_unit", "peak_best", "peak_before", "peak_after",
    "peak_before_over_best", "peak_after_over_best",
    "stroke_before_m", "stroke_after_m", "stroke_limit_m", "within_stroke_limit",
    "converged", "status",
)
SENSITIVITY_COLUMNS = (
    "amplitude", "amplitude_unit", "parameter", "value", "unit",
    "k_N_per_m", "c_N_s_per_m", "peak_unit", "peak", "derivative_per_unit", "elasticity",
    "stroke_m", "stroke_derivative_m_per_unit", "stroke_elasticity",
    "optimum_k_N_per_m", "optimum_c_N_s_per_m", "optimum_peak", "optimum_elasticity",
    "optimum_stroke_elasticity", "optimum_stiffness_elasticity",
    "optimum_damping_elasticity", "optimum_damping_at_bound",
    "converged", "optimum_converged", "status",
)
RANDOM_COLUMNS = (
    "psd", "psd_unit", "k_N_per_m", "c_N_s_per_m",
    "rms_unit", "rms_before", "rms_before_se", "rms_after", "rms_after_se",
    "rms_after_over_before", "linearised_k_N_per_m", "linearised_c_N_s_per_m",
    "rms_linearised", "rms_linearised_se", "rms_frictionless", "linearised_status",
    "stroke_before_m", "stroke_after_m", "stroke_rms_before_m", "stroke_rms_after_m",
    "at_bound", "stroke_limited", "converged", "status",
)
RECORDS_COLUMNS = (
    "name", "file", "amplitude", "amplitude_unit", "duration_s", "k_N_per_m", "c_N_s_per_m",
    "peak_unit", "peak_before", "peak_after", "peak_after_over_before",
    "rms_before", "rms_after", "stroke_before_m", "stroke_after_m", "stroke_limit_m",
    "within_stroke_limit", "converged", "status",
)


def amplitude_unit(load: str) -> str:
    """The unit of a harmonic load's amplitude: N for a force, m/s2 for the ground's."""
    return LOAD_UNITS[load]


def row(columns: Sequence[str], **values) -> dict:
    """A record keyed by `columns` in their order, None where `values` has no entry
    (a column that does not apply); `ValueError` for a value of no column."""
    unknown = set(values) - set(columns)
    if unknown:
        raise ValueError(f"no column {sorted(unknown)[0]!r}")
    return {name: values.get(name) for name in columns}


def ratio(top, bottom) -> float | None:
    """`top / bottom`; None where either is None, `top` is NaN or `bottom` is not positive
    and finite."""
    if top is None or bottom is None:
        return None
    top, bottom = float(top), float(bottom)
    if not (bottom > 0 and bottom < float("inf")) or top != top:
        return None
    return top / bottom


def status(converged: bool, *problems: str, base: str | None = None) -> str:
    """`base` (default "ok", or `NOT_CONVERGED` where not `converged`) and the problems
    found beside it, separated by "; ": the text starts with "ok" where it converged."""
    base = base if base is not None else OK if converged else NOT_CONVERGED
    return "; ".join([base, *(p for p in problems if p)])


def stroke_problem(stroke, limit) -> str:
    """The status's part for a stroke over its limit (m), else ""."""
    if stroke is None or limit is None or float(stroke) <= float(limit):
        return ""
    return f"stroke over limit ({100 * float(stroke):.3g} cm > {100 * float(limit):g} cm)"


def finite(value) -> float | None:
    """`value` as a float, None where it is NaN or infinite."""
    if value is None:
        return None
    value = float(value)
    return value if abs(value) < float("inf") else None


# --- the printed tables, for the host and a building ---------------------------------

# `frf`'s printed table, a row per amplitude (`frf_summary`), for the host and a building
FRF_TABLE = (
    shown("A", "amplitude", "g"), shown("unit", "amplitude_unit", "s"),
    shown("peak", "peak", ".4g"), shown("unit", "peak_unit", "s"),
    shown("at f [Hz]", "peak_frequency_Hz", ".3f"),
    shown("/ uncontrolled", "peak_over_uncontrolled", ".3f"),
    shown("x/(A/K)", "x_peak_over_A_K", ".2f"),
    shown("stroke [cm] (limit {limit_cm:g})", "stroke_m", ".2f", unit=0.01),
    Shown("converged", lambda s: f"{s['converged_points']}/{s['points']}"),
    shown("unstable", "unstable_points", "d"),
)


def frf_summary(records: list[dict], amplitudes, frequencies: int) -> list[dict]:
    """Per amplitude, from `frf`'s records (amplitude-major): the peak over the converged
    points, where it is, its ratios and the largest stroke."""
    summary = []
    for i, amplitude in enumerate(amplitudes):
        mine = records[i * frequencies:(i + 1) * frequencies]
        found = [r for r in mine if r["converged"]]
        top = max(found, key=lambda r: r["peak"]) if found else None
        unstable = sum(not r["stable"] for r in found)
        summary.append(row(
            FRF_SUMMARY_COLUMNS, amplitude=float(amplitude),
            amplitude_unit=mine[0]["amplitude_unit"], peak_unit=mine[0]["peak_unit"],
            **({} if top is None else dict(
                peak=top["peak"], peak_frequency_Hz=top["frequency_Hz"],
                peak_over_uncontrolled=top["peak_over_uncontrolled"],
                x_peak_over_A_K=top["x_over_A_K"])),
            stroke_m=max((r["stroke_m"] for r in found), default=None),
            converged_points=len(found), points=len(mine), unstable_points=unstable,
            status=status(len(found) == len(mine),
                          f"{unstable} unstable steady state(s)" if unstable else "")))
    return summary


# `retune`'s printed table, for the host and a building
RETUNE_TABLE = (
    shown("A", "amplitude", "g"), shown("unit", "amplitude_unit", "s"),
    shown("k/k_DH", "k_over_k_den_hartog", ".3f"),
    shown("k [kN/m]", "k_N_per_m", ".2f", unit=1e3),
    shown("c/c_DH", "c_over_c_den_hartog", ".3f"),
    shown("c [N s/m]", "c_N_s_per_m", ".1f"),
    shown("peak before", "peak_before", ".4g"), shown("peak after", "peak_after", ".4g"),
    shown("unit", "peak_unit", "s"),
    shown("after/before", "peak_after_over_before", ".3f"),
    shown("/ uncontrolled", "peak_after_over_uncontrolled", ".3f"),
    shown("x/(A/K) after", "x_peak_after_over_A_K", ".2f"),
    shown("f_peak [Hz]", "peak_frequency_after_Hz", ".3f"),
    shown("stroke [cm] (limit {limit_cm:g})", "stroke_after_m", ".2f", unit=0.01),
    shown("status", "status", "s"),
)


# `sensitivity`'s printed table, a row per amplitude and parameter, for the host and a
# building; the optimum's columns where it was found
SENSITIVITY_TABLE = (
    shown("A", "amplitude", "g"), shown("unit", "amplitude_unit", "s"),
    shown("parameter", "parameter", "s"), shown("value", "value", ".5g"),
    shown("unit", "unit", "s"), shown("peak", "peak", ".4g"),
    shown("d peak/dp", "derivative_per_unit", ".3e"), shown("e", "elasticity", ".4f"),
    shown("e_stroke", "stroke_elasticity", ".4f"),
)
OPTIMUM_TABLE = (
    shown("e retuned", "optimum_elasticity", ".4f"),
    shown("e_stroke retuned", "optimum_stroke_elasticity", ".4f"),
    shown("e_k*", "optimum_stiffness_elasticity", ".4f"),
    Shown("e_c*", lambda r: "c* at 0" if r["optimum_damping_at_bound"] else "-"
          if r["optimum_damping_elasticity"] is None
          else f"{r['optimum_damping_elasticity']:.4f}"),
)


# `robust`'s printed table, a row per scenario, for the host and a building
ROBUST_TABLE = (
    shown("f_n x", "frequency_scale", ".3g"), shown("A", "amplitude", "g"),
    shown("unit", "amplitude_unit", "s"),
    shown("best", "peak_best", ".4g"), shown("unit", "peak_unit", "s"),
    shown("robust / best", "peak_after_over_best", ".3f"),
    shown("given / best", "peak_before_over_best", ".3f"),
    shown("stroke robust [cm]", "stroke_after_m", ".2f", unit=0.01),
    shown("stroke given [cm]", "stroke_before_m", ".2f", unit=0.01),
    shown("status", "status", "s"),
)


def sensitivity_table(optimum: bool) -> tuple[Shown, ...]:
    """`sensitivity`'s printed columns: the optimum's where it was found, and the status."""
    return SENSITIVITY_TABLE + (OPTIMUM_TABLE if optimum else ()) + (
        shown("status", "status", "s"),)
