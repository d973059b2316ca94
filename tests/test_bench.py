"""``brdf-infer bench --quick`` writes a report with error next to time for every method."""

import pytest

from tests.helpers import run_cli


@pytest.mark.slow  # ≈ 80 s before the misspecification section (9 × 20 replicates, ≈ 140 s on
# shared cores; the whole test took 924 s with the cores shared three ways); the benchmark
# itself (brdf-infer bench) runs every section
def test_quick_benchmark_report(tmp_path, capsys):
    out = tmp_path / "benchmarks.md"
    code, _, err = run_cli("bench", "--quick", "--out", str(out), capsys=capsys)
    assert code == 0, err
    text = out.read_text()
    assert "Machine:" in text and "compile [s]" in text
    for method in (
        "2-D midpoint",
        "2-D Gauss-Legendre",
        "exact 1-D",
        "optimistix lm",
        "scipy least_squares",
        "paper regression",
    ):
        assert method in text, method
    assert "max rel. error" in text and "final χ²" in text
    assert "## Model families" in text and "harvey-shack" in text and "elpd_loo" in text
    for case in ("σ × 1.35", "log-Jacobian dropped", "priors moved 1 sd"):
        assert f"| planted: {case} |" in text, case
    assert "## Misspecification: what SBC cannot see" in text
    for case in ("well specified", "latent angles", "calibration left out"):
        assert f"| {case} |" in text, case
    assert "## Bad input" in text and "| parameter JSON | 500 |" in text
    assert "## Cost against the number of rows" in text and "| 2 × 10³ |" in text
    assert (tmp_path / "benchmarks_tis.png").stat().st_size > 10_000


def test_unwritable_output_is_a_clear_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, out, err = run_cli("run", "--out", str(blocker / "sub"), capsys=capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
