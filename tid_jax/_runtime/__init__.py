"""What runs the computations: compiled programs kept on disk, processes, device sharding,
files, outcome codes."""
