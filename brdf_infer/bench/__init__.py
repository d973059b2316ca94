"""Benchmarks (``brdf-infer bench``): error next to run time, compile time apart."""

from brdf_infer.bench._report import write_report
from brdf_infer.bench._speed import write_speed_report, write_stress_report

__all__ = ["write_report", "write_speed_report", "write_stress_report"]
