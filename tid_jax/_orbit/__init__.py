"""Periodic orbits: period maps (exact stick-slip flows, diffrax), shooting, Floquet
multipliers."""
