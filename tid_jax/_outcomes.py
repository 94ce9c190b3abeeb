"""Outcome codes of the optimisers. Each optimiser's outcomes are an `eqx.Enumeration`
whose first item, `ok`, means success; its results hold the items' integer codes (arrays
of them, as NumPy, CSV and JSON take them), whose messages `outcome_message` reads."""

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
