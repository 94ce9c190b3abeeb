"""Outcome codes: one `eqx.Enumeration`, `Outcome`, for every result, whose first item,
`ok`, means success; results hold the items' integer codes (arrays of them, as NumPy, CSV
and JSON take them) in their `status`, whose messages `outcome_message` reads."""

import equinox as eqx
import jax
import numpy as np


def outcome_code(item) -> int:
    """The integer code of `item`, an item of an `eqx.Enumeration`: its place in the
    enumeration, from 0 (an item is a pytree whose one leaf is its code)."""
    (code,) = jax.tree.leaves(item)
    return int(code)


def outcome_message(enumeration: type[eqx.Enumeration], code) -> str:
    """The message of the integer `code` (an int, or a 0-d array of one) of
    `enumeration`."""
    # The item of that code: the structure of the enumeration's items, with the code as
    # its leaf.
    structure = jax.tree.structure(enumeration.ok)
    item = jax.tree.unflatten(structure, [np.asarray(code, dtype=np.int32)])
    return enumeration[item]


def outcome_messages(status) -> list[str]:
    """The messages of the `Outcome` codes `status` (an int or an array of them), one per
    entry in C order: what every result's `status_messages()` returns."""
    return [outcome_message(Outcome, code) for code in np.ravel(np.asarray(status))]


class Outcome(eqx.Enumeration):
    """How a solve or a design ended, the same codes on every result (`status`)."""

    ok = "ok"
    not_stationary = "optimiser did not converge"
    steady_states_failed = "some steady states did not converge"
    peak_at_band_edge = "peak at the edge of the frequency band"
    initial_kept = ("the retuned peak was above the initial tuning's on the check grid: "
                    "initial tuning kept")
    stuck = ("below the breakaway amplitude: the inerter never slips and the TID is a spring "
             "and damper to ground, which retuning would only stiffen; initial tuning kept")
    stroke_over_limit = "stroke over the limit on the check grid"
    locked = ("no statistical linearisation: the spring and damper's RMS force stays below "
              "what the friction holds (about 1.4 ff), the inerter locks and no viscous "
              "equivalent is self-consistent; no linearised design")
