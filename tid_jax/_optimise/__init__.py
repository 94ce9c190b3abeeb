"""The optimisers and the designs built on them: retunes, best tunings, robust designs,
sensitivities."""
