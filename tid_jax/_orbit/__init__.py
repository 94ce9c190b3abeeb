"""Periodic orbits: the period map (exact stick-slip flows, diffrax), shooting, Floquet multipliers."""
