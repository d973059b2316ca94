"""``python -m brdf_infer`` runs the command line."""

from brdf_infer.cli import entry_point

entry_point()
