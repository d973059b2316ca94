"""Measure one section of the benchmark report again and splice it into the report.

    python tools/bench_section.py SECTION [--report reports/benchmarks.md]

(SECTION: sbc, misspec, design, design-time, cost-curve or model-check-power.)

The full benchmark (``brdf-infer bench``) takes long; after a change that touches one study,
this reruns that study's section as ``brdf-infer bench`` would and replaces the section of the
same heading (up to the next ``## `` heading) in the report, leaving every other section as it
was measured. The section's text says which code measured it (the header of the report does
not: see the commit that spliced it).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from brdf_infer._internal.atomic import atomic_write_bytes

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/


def sbc(report: Path) -> list[str]:
    from benchmarks._sbc import sbc_rows
    from benchmarks._sections import sbc_section
    from brdf_infer.report import ecdf_differences, png
    from brdf_infer.scene import load_scene

    rows = sbc_rows(load_scene("lya"), quick=False)
    plots = []
    for row, suffix in zip(rows[:2], ("sbc", "sbc_planted"), strict=True):
        path = report.with_name(f"{report.stem}_{suffix}.png")
        atomic_write_bytes(path, png(ecdf_differences(row.result)))
        plots.append(path)
    return sbc_section(rows, plots)


def misspec(report: Path) -> list[str]:
    from benchmarks._misspec import misspec_rows
    from benchmarks._sections import misspec_section
    from brdf_infer.scene import load_scene

    return misspec_section(misspec_rows(load_scene("lya"), quick=False))


def design(report: Path) -> list[str]:
    from benchmarks._design_section import design_section

    return design_section(False, report.with_name(f"{report.stem}_design.png"))


def design_time(report: Path) -> list[str]:
    from benchmarks._design_section import command_section

    return command_section(False)


def cost_curve(report: Path) -> list[str]:
    from benchmarks._cost_curve import cost_rows, cost_section

    return cost_section(cost_rows(quick=False))


def model_check_power(report: Path) -> list[str]:
    from benchmarks._model_check_power import model_check_power, power_section

    return power_section(model_check_power())


SECTIONS = {
    "sbc": sbc,
    "misspec": misspec,
    "design": design,
    "design-time": design_time,
    "cost-curve": cost_curve,
    "model-check-power": model_check_power,
}


def provenance(seconds: float, commit: str) -> str:
    """Where and when a spliced section was measured, and on which commit."""
    import platform

    import jax

    dirty = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no", "brdf_infer"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    code = f"commit {commit}" + (" with uncommitted changes to brdf_infer" if dirty else "")
    return (
        f"Measured on its own (`python tools/bench_section.py`, full size, {seconds:.0f} s wall, "
        f"{platform.machine()}, {os.cpu_count()} cores shared with other jobs, JAX "
        f"{jax.__version__} on {jax.default_backend()}, Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d')}; the code of {code}) and spliced into this report; "
        "`brdf-infer bench` regenerates it with the rest."
    )


def splice(report: Path, lines: list[str]) -> None:
    """Replace the section whose ``## `` heading is ``lines[0]`` in ``report`` (a section the
    report does not have yet is added at its end)."""
    text = report.read_text()
    heading = lines[0]
    pattern = re.compile(rf"^{re.escape(heading)}\n.*?(?=^## |\Z)", re.S | re.M)
    new = "\n".join(lines).rstrip("\n") + "\n\n"
    if not pattern.search(text):
        atomic_write_bytes(report, (text.rstrip("\n") + "\n\n" + new).encode())
        return
    atomic_write_bytes(report, pattern.sub(lambda _: new, text, count=1).encode())


def main() -> None:
    import brdf_infer

    brdf_infer.use_float64()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("section", choices=sorted(SECTIONS))
    parser.add_argument("--report", type=Path, default=Path("reports/benchmarks.md"))
    args = parser.parse_args()
    started = time.perf_counter()
    commit = subprocess.run(  # the code measured: HEAD when the run starts
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    lines = SECTIONS[args.section](args.report)
    lines = [lines[0], "", provenance(time.perf_counter() - started, commit), *lines[1:]]
    splice(args.report, lines)
    print(f"{args.section}: spliced into {args.report} ({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
