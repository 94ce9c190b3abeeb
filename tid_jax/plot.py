"""Figures. The only module of tid_jax that imports matplotlib.

Every function takes plain arrays (SI units, frequencies in Hz, responses of the host `x`
normalised by the static displacement A / K as in the paper) and returns a `Figure`;
`save_figure` writes it as PNG atomically.
"""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker as ticker  # noqa: E402
import numpy as np  # noqa: E402

from ._runtime._io import atomic_path  # noqa: E402
from ._runtime._parallel import serial  # noqa: E402

LINEAR_STYLE = dict(color="black", linestyle="--", linewidth=2.0, label="linear TID (no friction)")
AMPLITUDE_LABEL = "forcing amplitude A [N]"  # the single-storey host's amplitude axis
HOST_FREQUENCY_STYLE = dict(color="0.5", linestyle=":", linewidth=1.2)


def save_figure(fig, path: str | os.PathLike) -> None:
    """Save `fig` as PNG atomically and close it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=130)
    plt.close(fig)


def save_figures(figures, *, map_lanes=serial) -> None:
    """Draw and save each of `figures`, `(plot_function, args, kwargs, path)`, as
    `save_figure(plot_function(*args, **kwargs), path)`, mapped by `map_lanes` (default:
    one after another here; a `ProcessMap` draws them at once, the arguments then NumPy
    arrays)."""
    map_lanes(_draw_and_save, [tuple(figure) for figure in figures])


def _draw_and_save(plot_function, args, kwargs, path) -> None:
    save_figure(plot_function(*args, **kwargs), path)


def _amplitude_colours(amplitudes):
    amplitudes = np.asarray(amplitudes, dtype=float)
    span = np.log(amplitudes.max() / amplitudes.min()) if amplitudes.size > 1 else 0.0
    fractions = (
        np.log(amplitudes / amplitudes.min()) / span if span > 0 else np.zeros_like(amplitudes)
    )
    return plt.get_cmap("viridis")(0.9 * fractions)


def _plain_log_axis(axis):
    """Log-scaled axis with ticks labelled 100, 200, 500, 1000 rather than 10^2, 10^3."""
    axis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ticker.FormatStrFormatter("%g"))
    axis.set_minor_formatter(ticker.NullFormatter())


def _mark_host_frequency(ax, host_frequency_hz):
    if host_frequency_hz is not None:
        ax.axvline(
            host_frequency_hz,
            **HOST_FREQUENCY_STYLE,
            label=f"host frequency {host_frequency_hz:.3g} Hz",
        )


def plot_frequency_response(
    frequencies_hz, amplitudes, x_norm, y_norm, *, linear=None, stuck=None,
    host_frequency_hz=None, title=None
):
    """The paper's Figure 5: peak host displacement (a) and inerter displacement (b) over
    A / K against forcing frequency (Hz), one line per forcing amplitude (N); arrays
    `x_norm`, `y_norm` are `(n_amplitudes, n_frequencies)`. `linear = (frequencies_hz, x,
    y)` adds the frictionless TID; `stuck = (frequencies_hz, x, breakaway)` the host with
    the inerter stuck, labelled with the minimum breakaway amplitude (N) below which
    every forcing leaves it stuck."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    colours = _amplitude_colours(amplitudes)
    panels = (
        ("(a) host structure", x_norm, "peak host displacement  x / (A/K)"),
        ("(b) inerter", y_norm, "peak inerter displacement  y / (A/K)"),
    )
    for index, (ax, (name, values, ylabel)) in enumerate(zip(axes, panels, strict=True)):
        for amplitude, colour, row in zip(amplitudes, colours, np.atleast_2d(values), strict=True):
            ax.plot(frequencies_hz, row, color=colour, linewidth=1.0, label=f"A = {amplitude:g} N")
        if linear is not None:
            ax.plot(linear[0], linear[1 + index], **LINEAR_STYLE)
        if stuck is not None and index == 0:
            ax.plot(stuck[0], stuck[1], color="0.45", linestyle=":", linewidth=1.2,
                    label=f"inerter stuck (every A below {stuck[2]:.3g} N)")
            ax.legend(fontsize=7, loc="upper left")
        _mark_host_frequency(ax, host_frequency_hz)
        ax.set(xlabel="forcing frequency [Hz]", ylabel=ylabel, title=name)
        ax.set_xlim(frequencies_hz[0], frequencies_hz[-1])
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, ncol=2, loc="upper right")
    if title:
        fig.suptitle(title)
    return fig


def plot_retune_responses(
    frequencies_hz,
    amplitudes,
    x_before,
    x_after,
    k_ratio,
    c_ratio,
    *,
    linear=None,
    host_frequency_hz=None,
    title=None,
    ylabel="peak host displacement x / (A/K)",
    amplitude_unit="N",
):
    """The paper's Figure 6: for each forcing amplitude (one panel each), the peak host
    displacement over A / K (or a building's response, named by `ylabel`) against
    frequency (Hz) before retuning (`x_before`) and after (`x_after`, arrays
    `(n_amplitudes, n_frequencies)`), with the retuned `k_ratio` and `c_ratio` to Den
    Hartog's in the panel title; `linear = (frequencies_hz, x)` adds the frictionless TID
    with the initial tuning."""
    n = len(amplitudes)
    columns = min(n, 4)
    rows = -(-n // columns)
    width, height = 3.6 * columns + 0.85, 3.0 * rows + 0.6
    fig, axes = plt.subplots(rows, columns, figsize=(width, height), sharex=True, squeeze=False)
    # Fixed margins (inches) for the labels and titles: as the constrained layout would
    # place them, without its search over a dozen panels, which takes as long as drawing.
    # (more between rows where the last is short: the panels above its gaps are labelled)
    fig.subplots_adjust(left=0.85 / width, right=1 - 0.1 / width, bottom=0.5 / height,
                        top=1 - 0.7 / height, wspace=0.15, hspace=0.16 if n % columns == 0 else 0.3)
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.set_visible(False)
            continue
        ax.plot(frequencies_hz, x_before[i], color="tab:red", linestyle="-.",
                label="before (initial tuning)")
        ax.plot(frequencies_hz, x_after[i], color="tab:blue", linewidth=2.0, label="retuned")
        if linear is not None:
            ax.plot(*linear, color="black", linestyle="--", linewidth=1.0,
                    label="linear TID (no friction)")
        _mark_host_frequency(ax, host_frequency_hz)
        ax.set_title(
            f"A = {amplitudes[i]:g} {amplitude_unit}: k = {k_ratio[i]:.3f} k_DH, "
            f"c = {c_ratio[i]:.2f} c_DH",
            fontsize=9,
        )
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        if i % columns == 0:
            ax.set_ylabel(ylabel)
        if i >= n - columns:
            ax.xaxis.set_tick_params(labelbottom=True)
            ax.set_xlabel("forcing frequency [Hz]")
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(title or "Host response before and after retuning the TID")
    return fig


def _draw_tuning_ratios(ax_k, ax_c, amplitudes, k_ratio, c_ratio, paper=None, converged=None,
                        amplitude_label=AMPLITUDE_LABEL, reference="Den Hartog"):
    amplitudes = np.asarray(amplitudes)
    failed = np.zeros(amplitudes.shape, bool) if converged is None else ~np.asarray(converged)
    paper_style = dict(color="tab:orange", markersize=8, fillstyle="none", markeredgewidth=2,
                       linestyle="none", label="paper, section 4.2")
    for ax, ratio in ((ax_k, np.asarray(k_ratio)), (ax_c, np.asarray(c_ratio))):
        ax.plot(amplitudes, ratio, "o-", color="tab:blue", label="retuned (this package)")
        if failed.any():
            ax.plot(amplitudes[failed], ratio[failed], "x", color="tab:red", markersize=10,
                    markeredgewidth=2, label="status not ok (see table)")
        if paper is not None:
            ax.plot(paper[0], paper[1 if ax is ax_k else 2], "s", **paper_style)
    for ax, label in ((ax_k, "stiffness  k / k_DH"), (ax_c, "damping  c / c_DH")):
        ax.axhline(1.0, color="black", linestyle="--", linewidth=1.0, label=reference)
        ax.set(xscale="log", xlabel=amplitude_label, ylabel=label)
        _plain_log_axis(ax.xaxis)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    ax_k.set_title("(a) retuned stiffness")
    ax_c.set_title("(b) retuned damping")
    ax_c.set_ylim(bottom=0)


def plot_tuning_ratios(amplitudes, k_ratio, c_ratio, *, paper=None, converged=None, title=None):
    """The paper's Figure 7: retuned stiffness and damping as ratios to Den Hartog's against
    forcing amplitude (N). `paper = (amplitudes, k_ratio, c_ratio)` adds reference points;
    `converged` (bool per amplitude; the retune status is ok) marks the others."""
    fig, (ax_k, ax_c) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    _draw_tuning_ratios(ax_k, ax_c, amplitudes, k_ratio, c_ratio, paper, converged)
    if title:
        fig.suptitle(title)
    return fig


def _draw_peaks(ax_x, ax_y, curves, stroke_limit, amplitude_label=AMPLITUDE_LABEL,
                peak_label="peak host displacement  x / (A/K)"):
    for label, amplitudes, x_norm, y_peak, style in curves:
        ax_x.plot(amplitudes, x_norm, label=label, **style)
        ax_y.plot(amplitudes, 100 * np.asarray(y_peak), label=label, **style)
    if stroke_limit is not None:
        ax_y.axhline(100 * stroke_limit, color="tab:red", linewidth=1.5,
                     label=f"stroke limit +-{100 * stroke_limit:g} cm")
    ax_x.set(xscale="log", xlabel=amplitude_label, ylabel=peak_label,
             title="(a) host structure")
    ax_y.set(xscale="log", yscale="log", xlabel=amplitude_label,
             ylabel="peak inerter stroke  |y| [cm]", title="(b) inerter stroke")
    ax_x.set_ylim(bottom=0)
    _plain_log_axis(ax_y.yaxis)
    for ax in (ax_x, ax_y):
        _plain_log_axis(ax.xaxis)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)


def plot_peaks_vs_amplitude(curves, *, stroke_limit=None, title=None):
    """The paper's Figure 8: peak host displacement over A / K (a) and peak inerter stroke
    in cm (b) against forcing amplitude (N). `curves` is a sequence of
    `(label, amplitudes, x_norm, y_peak_m, style)` with `style` matplotlib line keywords;
    `stroke_limit` (m) draws the stroke limit."""
    fig, (ax_x, ax_y) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    _draw_peaks(ax_x, ax_y, curves, stroke_limit)
    if title:
        fig.suptitle(title)
    return fig


def plot_device_designs(devices, *, title=None):
    """Designs with several inerter devices against forcing amplitude (N): the peak host
    displacement over A / K with Den Hartog's tuning (dashed) and retuned (solid), and the
    retuned k and c over Den Hartog's. `devices` maps a device's name to its
    `(amplitudes, x_den_hartog, x_retuned, k_ratio, c_ratio)`."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), layout="constrained")
    for name, (amplitudes, x_dh, x_retuned, k_ratio, c_ratio) in devices.items():
        (line,) = axes[0].plot(amplitudes, x_dh, "--o", label=f"{name}, Den Hartog")
        style = dict(color=line.get_color(), marker="s")
        axes[0].plot(amplitudes, x_retuned, label=f"{name}, retuned", **style)
        axes[1].plot(amplitudes, k_ratio, label=name, **style)
        axes[2].plot(amplitudes, c_ratio, label=name, **style)
    for ax, label in zip(axes, ("peak host displacement x / (A/K)", "retuned k / k_DH",
                                "retuned c / c_DH"), strict=True):
        ax.set(xlabel="forcing amplitude A [N]", ylabel=label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[1].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_retune_summary(amplitudes, k_ratio, c_ratio, x_before, x_after, y_before, y_after, *,
                        stroke_limit=None, converged=None, title=None,
                        amplitude_label=AMPLITUDE_LABEL,
                        peak_label="peak host displacement  x / (A/K)",
                        reference="Den Hartog"):
    """Retuning at a glance, in the style of the paper's Figure 7: k / k_DH and c / c_DH
    (top) and the peak response (`x_before`, `x_after`: the host's over A / K, or a
    building's in SI, named by `peak_label`) and inerter stroke (m, drawn in cm) before and
    after retuning (bottom) against amplitude (N, or as `amplitude_label` names it);
    `reference` names the tuning k_DH, c_DH."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), layout="constrained")
    _draw_tuning_ratios(axes[0, 0], axes[0, 1], amplitudes, k_ratio, c_ratio, None, converged,
                        amplitude_label, reference)
    curves = (("before (initial tuning)", amplitudes, x_before, y_before,
               dict(color="tab:red", linestyle="-.", marker="s")),
              ("retuned", amplitudes, x_after, y_after, dict(color="tab:blue", marker="o")))
    _draw_peaks(axes[1, 0], axes[1, 1], curves, stroke_limit, amplitude_label, peak_label)
    axes[1, 0].set_title("(c) structure")
    axes[1, 1].set_title("(d) inerter stroke")
    fig.suptitle(title or "TID retuned for each forcing amplitude")
    return fig


_SUBSTRUCTURING_PANELS = (("(a) host structure, x", "peak displacement [mm]", 1e3),
                          ("(b) TID (inerter terminal), y", "peak displacement [mm]", 1e3))


def plot_substructuring_response(frequencies_hz, whole_x, whole_y, tests, *, title=None,
                                 panels=_SUBSTRUCTURING_PANELS):
    """The paper's Figure 14: peak host displacement x and inerter displacement y (m, drawn
    in mm) against forcing frequency (Hz), the whole system as a dashed line and each
    virtual substructuring test as markers. `tests` is a sequence of
    `(label, x_max, y_max, stable)` on the same frequencies; unstable points are left out
    and marked by a cross on the frequency axis. `panels`: each panel's title, y label
    and the factor from SI to its unit (a building's quantity and stroke, say)."""
    frequencies_hz = np.asarray(frequencies_hz, dtype=float)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    markers = ("o", "s", "^", "D", "v")
    for ax, whole, index, (name, ylabel, factor) in zip(
            axes, (whole_x, whole_y), (1, 2), panels, strict=True):
        ax.plot(frequencies_hz, factor * np.asarray(whole), color="black", linestyle="--",
                linewidth=1.5, label="whole system")
        for number, test in enumerate(tests):
            label, stable = test[0], np.asarray(test[3], dtype=bool)
            values = factor * np.asarray(test[index], dtype=float)
            ax.plot(frequencies_hz[stable], values[stable], linestyle="none",
                    marker=markers[number % len(markers)], markersize=4, label=label)
            if not np.all(stable):
                ax.plot(frequencies_hz[~stable], np.zeros(int((~stable).sum())),
                        linestyle="none", marker="x", color="tab:red",
                        label=f"{label}: unstable")
        ax.set(xlabel="forcing frequency [Hz]", ylabel=ylabel, title=name)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower center")
    fig.suptitle(title or "Virtual substructuring test against the whole system")
    return fig


def plot_substructuring_stability(curves, *, max_delay=None, title=None):
    """Largest stable actuator delay (s, drawn in ms) against the guessed-to-true inertance
    ratio b_g / b. `curves` is a sequence of `(label, ratios, largest_stable_delay)` with
    -1 where even the smallest delay was unstable (drawn at 0 with open markers);
    `max_delay` (s), the largest delay tried, is drawn as a line: curves on it were stable
    for every delay tried."""
    fig, ax = plt.subplots(figsize=(9, 4.2), layout="constrained")
    markers = ("o", "s", "^", "D")
    for number, (label, ratios, largest) in enumerate(curves):
        ratios = np.asarray(ratios, dtype=float)
        largest = np.asarray(largest, dtype=float)
        marker = markers[number % len(markers)]
        (line,) = ax.plot(ratios, 1e3 * np.maximum(largest, 0), marker=marker, label=label)
        none = largest < 0
        if np.any(none):
            ax.plot(ratios[none], np.zeros(int(none.sum())), linestyle="none", marker=marker,
                    markerfacecolor="white", color=line.get_color())
    if max_delay is not None:
        ax.axhline(1e3 * max_delay, color="0.5", linestyle=":", label="largest delay tried")
    ax.axvline(0.5, color="0.7", linewidth=1)
    ax.set(
        xlabel="guessed / true inertance  b_g / b",
        ylabel="largest stable delay [ms]",
        title=title or "Error-feedback substructuring: stability against delay",
    )
    ax.set_ylim(bottom=-1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return fig


PARAMETER_LABELS = {
    "host_mass": "host mass M",
    "host_stiffness": "host stiffness K",
    "host_damping": "host damping C",
    "inertance": "inertance b",
    "friction_force": "friction force ff",
    "tid_stiffness": "TID stiffness k",
    "tid_damping": "TID damping c",
    "parasitic_damping": "parasitic damping cp",
    "terminal_mass": "terminal mass mt",
    "series_stiffness": "series stiffness ks",
    "backlash": "backlash",
    "amplitude": "forcing amplitude A",
}


def plot_elasticities(
    amplitudes, host, stroke, *, optimum_host=None, optimum_stroke=None, title=None,
    xlabel="forcing amplitude A [N]", peak="host displacement",
):
    """Elasticities d ln(peak) / d ln(p) of the peak response (a; `peak` names it) and of
    the peak inerter stroke (b) against amplitude (`xlabel`), one colour per parameter.
    `host` and `stroke` map parameter names to arrays over `amplitudes` at the given
    tuning (solid lines); `optimum_host` and `optimum_stroke`, if given, the same at the
    tuning retuned for each amplitude (dashed lines)."""
    fig, (ax_x, ax_y) = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
    colours = plt.get_cmap("tab10")
    for ax, given, optimum in ((ax_x, host, optimum_host), (ax_y, stroke, optimum_stroke)):
        for n, (name, values) in enumerate(given.items()):
            colour = colours(n % 10)
            ax.plot(amplitudes, values, color=colour, marker=".",
                    label=PARAMETER_LABELS.get(name, name))
            if optimum is not None and name in optimum:
                ax.plot(amplitudes, optimum[name], color=colour, linestyle="--", marker=".")
        ax.axhline(0.0, color="black", linewidth=0.8)
        ax.set(xscale="log", xlabel=xlabel)
        _plain_log_axis(ax.xaxis)
        ax.grid(alpha=0.3, which="both")
    ax_x.set(ylabel="elasticity  d ln x_peak / d ln p", title=f"(a) peak {peak}")
    ax_y.set(ylabel="elasticity  d ln y_peak / d ln p", title="(b) peak inerter stroke")
    handles, labels = ax_x.get_legend_handles_labels()
    if optimum_host is not None:
        handles += [
            matplotlib.lines.Line2D([], [], color="0.3", label="at the given tuning"),
            matplotlib.lines.Line2D([], [], color="0.3", linestyle="--",
                                    label="at the tuning retuned for each A"),
        ]
        labels += ["at the given tuning", "at the tuning retuned for each A"]
    fig.legend(handles, labels, loc="outside right center", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_robust_comparison(amplitudes, designs, *, stroke_limit=None, title=None,
                           amplitude_label=AMPLITUDE_LABEL,
                           ratio_label="peak host displacement / best achievable at A"):
    """TID tunings over a range of amplitudes (N; a building's axis named by
    `amplitude_label`): (a) the peak response over the best achievable at each amplitude
    (`ratio_label`), (b) peak inerter stroke (cm). `designs` is a sequence of
    `(label, ratio, stroke_m, style)` with `style` matplotlib line keywords;
    `stroke_limit` (m) draws the stroke limit."""
    fig, (ax_r, ax_y) = plt.subplots(1, 2, figsize=(11, 4.4), layout="constrained")
    for label, ratio, stroke, style in designs:
        ax_r.plot(amplitudes, ratio, label=label, **style)
        ax_y.plot(amplitudes, 100 * np.asarray(stroke), label=label, **style)
    ax_r.axhline(1.0, color="black", linewidth=0.8)
    if stroke_limit is not None:
        ax_y.axhline(100 * stroke_limit, color="tab:red", linewidth=1.5,
                     label=f"stroke limit +-{100 * stroke_limit:g} cm")
    ax_r.set(xscale="log", xlabel=amplitude_label, ylabel=ratio_label,
             title="(a) structure, relative to retuning for each A")
    ax_y.set(xscale="log", yscale="log", xlabel=amplitude_label,
             ylabel="peak inerter stroke  |y| [cm]", title="(b) inerter stroke")
    _plain_log_axis(ax_y.yaxis)
    for ax in (ax_r, ax_y):
        _plain_log_axis(ax.xaxis)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_identification(records, *, title=None):
    """Measured and fitted force of inerter test records (the paper's Figures 2-3):
    against time, against displacement and against velocity, one row per record.
    `records` holds dicts with `name`, `time` (s), `displacement` (m), `velocity` (m/s),
    `force` and `fitted` (N)."""
    fig, axes = plt.subplots(len(records), 3, figsize=(12, 3.0 * len(records)),
                             squeeze=False)
    for row, record in zip(axes, records, strict=True):
        for ax, key, label in zip(row, ("time", "displacement", "velocity"),
                                  ("time [s]", "displacement [mm]", "velocity [mm/s]"),
                                  strict=True):
            scale = 1.0 if key == "time" else 1e3
            ax.plot(scale * np.asarray(record[key]), record["force"], color="0.6",
                    linewidth=0.8, label="measured")
            ax.plot(scale * np.asarray(record[key]), record["fitted"], color="C3",
                    linewidth=1.2, label="fitted")
            ax.set_xlabel(label)
            ax.grid(True, alpha=0.3)
        row[0].set_ylabel(f"force [N]\n{record['name']}")
    axes[0, 0].legend(loc="best")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_building_response(frequencies_hz, amplitudes, response, uncontrolled, *, ylabel,
                           amplitude_unit="N", title=None):
    """A structure's peak response (SI) against frequency, one line per amplitude, with
    the bare structure's dotted in the same colour; arrays `(n_amplitudes, n_freqs)`."""
    fig, ax = plt.subplots(figsize=(7.5, 4.6), layout="constrained")
    for amplitude, colour, row, bare in zip(amplitudes, _amplitude_colours(amplitudes),
                                            np.atleast_2d(response),
                                            np.atleast_2d(uncontrolled), strict=True):
        ax.plot(frequencies_hz, row, color=colour, linewidth=1.0,
                label=f"A = {amplitude:g} {amplitude_unit}")
        ax.plot(frequencies_hz, bare, color=colour, linewidth=0.8, linestyle=":")
    ax.set(xlabel="forcing frequency [Hz]", ylabel=ylabel,
           title=title or "with the TID (solid), without (dotted)")
    ax.set_xlim(frequencies_hz[0], frequencies_hz[-1])
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return fig


def plot_elasticity_bars(names, elasticities, *, title=None):
    """Elasticities of the peak at one amplitude, one bar per parameter of `names`."""
    fig, ax = plt.subplots(figsize=(8.5, max(4.6, 0.22 * len(names))), layout="constrained")
    ax.barh(np.arange(len(names)), np.asarray(elasticities))
    ax.set_yticks(np.arange(len(names)), [PARAMETER_LABELS.get(n, n) for n in names],
                  fontsize=7)
    ax.invert_yaxis()
    ax.set(xlabel="d ln peak / d ln p")
    ax.axvline(0.0, color="0.5", linewidth=0.6)
    ax.set_title(title or "elasticities of the peak")
    ax.grid(alpha=0.3)
    return fig


# The given tuning, then the retuned or designed one, then references.
TUNING_STYLES = (dict(color="tab:red", linestyle="-."), dict(color="tab:blue"),
                 dict(color="tab:green", linestyle=":"), dict(color="black", linestyle="--"))


def plot_random_design(levels, rms, ratios, *, xlabel, ylabel, title=None):
    """The TID retuned per intensity S0 of a random load (log axes): (a) the RMS response
    of each tuning, `rms` mapping a label to `(values, standard_errors)` over `levels`,
    with error bars of 2 SE (NaN left out); (b) retuned k and c over the given ones,
    `ratios` mapping a label to values."""
    fig, (ax_r, ax_t) = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    for (label, (values, errors)), style in zip(rms.items(), TUNING_STYLES, strict=False):
        ax_r.errorbar(levels, values, yerr=2 * np.asarray(errors, float), marker="o",
                      markersize=4, capsize=3, label=label, **style)
    for (label, values), marker in zip(ratios.items(), "os^D", strict=False):
        ax_t.plot(levels, values, marker=marker, markersize=4, label=label)
    ax_t.axhline(1.0, color="black", linewidth=0.8)
    ax_r.set(xscale="log", yscale="log", xlabel=xlabel, ylabel=ylabel,
             title="(a) RMS response (error bars: 2 standard errors)")
    ax_t.set(xscale="log", yscale="log", xlabel=xlabel, ylabel="over the given tuning",
             title="(b) retuned stiffness k and damping c")
    for ax in (ax_r, ax_t):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def plot_histories(panels, *, shade=None, title=None):
    """Time histories, a panel per `(name, ylabel, time, curves)` or `(name, ylabel, time,
    curves, limit)` (time in s), `curves` mapping a label to values over `time`, in
    `TUNING_STYLES`, and `limit` (if given) drawn at plus and minus its value;
    `shade = (start, end, label)` marks a stretch of time."""
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 0.8 + 2.4 * len(panels)),
                             squeeze=False, layout="constrained")
    for ax, (name, ylabel, time, curves, *limit) in zip(axes[:, 0], panels, strict=True):
        for (label, values), style in zip(curves.items(), TUNING_STYLES, strict=False):
            ax.plot(time, values, linewidth=0.7, label=label, **style)
        for sign in (1, -1) if limit and limit[0] is not None else ():
            ax.axhline(sign * limit[0], color="0.3", linestyle=":", linewidth=1.0,
                       label="limit" if sign > 0 else None)
        if shade is not None:
            ax.axvspan(shade[0], shade[1], color="0.9", label=shade[2])
        ax.set(ylabel=ylabel, title=name, xlim=(time[0], time[-1]))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def plot_spectra(curves, *, ylabel, xmax=None, title=None):
    """Spectral densities against frequency (Hz, up to `xmax`) on a log axis: `curves`
    maps a label to `(frequencies_hz, density)`, in `TUNING_STYLES`."""
    fig, ax = plt.subplots(figsize=(8, 4.6), layout="constrained")
    for (label, (frequencies, density)), style in zip(curves.items(), TUNING_STYLES,
                                                      strict=False):
        ax.plot(frequencies, density, linewidth=1.2, label=label, **style)
    shown = [d[(f > 0) & (f <= (xmax or np.inf)) & (d > 0)] for f, d in curves.values()]
    ax.set(yscale="log", xlabel="frequency [Hz]", ylabel=ylabel, xlim=(0, xmax),
           ylim=(0.5 * min(np.min(d, initial=np.inf) for d in shown), None))
    ax.set_title(title or "spectral density of the response", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return fig


def plot_record_peaks(names, peaks, *, ylabel, title=None):
    """Bars of each record's peak response, a bar per tuning: `peaks` maps a label to
    values over the records `names`."""
    fig, ax = plt.subplots(figsize=(max(6.0, 2.0 + 1.1 * len(names)), 4.6),
                           layout="constrained")
    width, places = 0.8 / len(peaks), np.arange(len(names))
    for i, ((label, values), style) in enumerate(zip(peaks.items(), TUNING_STYLES,
                                                     strict=False)):
        ax.bar(places + (i - (len(peaks) - 1) / 2) * width, values, width, label=label,
               color=style["color"])
    ax.set_xticks(places, names, fontsize=7, rotation=20 if len(names) > 3 else 0)
    ax.set(ylabel=ylabel)
    ax.set_title(title or "peak response per record", fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    ax.margins(y=0.15)
    ax.legend(fontsize=8)
    return fig
