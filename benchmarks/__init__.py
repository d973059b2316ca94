"""Benchmarks (``brdf-infer bench``, ``python -m benchmarks``): error next to run time, compile
time apart. Not part of the installed package: they live in the checkout, need the ``test`` and
``peers`` extras and write the checkout's ``reports/``."""

from benchmarks._report import write_report
from benchmarks._speed import write_speed_report, write_stress_report

__all__ = ["write_report", "write_speed_report", "write_stress_report"]
