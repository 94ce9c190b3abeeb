"""The model: a structure, its TID and its load, SI units; their linear theory."""
