"""Simulation-based calibration: the command, its tests' power, and (slow) the full check."""

import json

import numpy as np
import pytest

from brdf_infer.sbc import QUANTITIES, SbcSettings, assess_ranks, ecdf_band, run_sbc
from tests.helpers import run_cli

N, L = 200, 100


def ranks_from(fractions: np.ndarray, rng) -> dict[str, np.ndarray]:
    """Ranks of a truth whose posterior CDF value is ``fractions`` (one per replicate)."""
    draws = rng.uniform(size=(len(fractions), L))
    return np.sum(draws < fractions[:, None], axis=1)


@pytest.mark.parametrize(
    ("fault", "transform"),
    [
        ("none", lambda u: u),
        ("posterior 35 % too wide", lambda u: _normal_cdf(_normal_ppf(u) / 1.35)),
        ("posterior 35 % too narrow", lambda u: _normal_cdf(_normal_ppf(u) * 1.35)),
        ("posterior biased by 0.3 sd", lambda u: _normal_cdf(_normal_ppf(u) + 0.3)),
    ],
)
def test_rank_checks_flag_planted_miscalibration(fault, transform):
    """A truth at posterior quantile u ~ U(0, 1) is calibrated; a too-wide posterior puts the
    truth nearer its centre, a too-narrow one nearer its tails, a biased one to one side."""
    rng = np.random.default_rng(7)
    settings = SbcSettings(replicates=N, draws=L)
    ranks = {name: ranks_from(transform(rng.uniform(size=N)), rng) for name in QUANTITIES}
    result = assess_ranks(settings, ranks)
    assert result.passed == (fault == "none"), result.failures


def _normal_cdf(x):
    from scipy import stats

    return stats.norm.cdf(x)


def _normal_ppf(u):
    from scipy import stats

    return stats.norm.ppf(u)


def test_simultaneous_ecdf_band_holds_95_percent_of_uniform_ecdfs():
    points = np.linspace(0, 1, 51)[1:-1]
    low, high = ecdf_band(N, points, level=0.95, seed=1)
    rng = np.random.default_rng(2)
    inside = []
    for _ in range(1000):
        ecdf = np.mean(rng.uniform(size=(N, 1)) <= points[None, :], axis=0)
        inside.append(np.all((ecdf >= low) & (ecdf <= high)))
    assert 0.93 <= np.mean(inside) <= 0.97  # binomial sd of 1000 trials ≈ 0.7 %


@pytest.mark.parametrize("draws", [100, 29])
def test_rank_tests_reject_uniform_ranks_no_more_often_than_their_level(draws):
    """Exactly uniform ranks, 4000 sets: each test's p-value falls below 5 % and 1 % no more
    often than that (plus three binomial sd). With histogram bins of equal width on the real
    line instead of whole ranks, the χ² test rejected 5.6 % at 5 % for L = 100 and far more for
    L = 29, where a bin holds one rank or two."""
    rng = np.random.default_rng(3)
    sets = 4000
    settings = SbcSettings(replicates=N, draws=draws)
    result = assess_ranks(settings, {str(k): rng.integers(0, draws + 1, N) for k in range(sets)})
    for test in (result.chi2_p, result.ks_p):
        p = np.array(list(test.values()))
        for level in (0.05, 0.01):
            assert np.mean(p < level) <= level + 3 * np.sqrt(level * (1 - level) / sets)


@pytest.mark.parametrize("replicates", [N, 20])
def test_family_wise_error_of_the_verdict_on_uniform_null_ranks_is_at_most_one_percent(
    replicates,
):
    """Exactly uniform ranks of the nine quantities of the bundled scene: the verdict (three
    tests per quantity) fails ≤ 1 % of the time (2000 null replicates; the bound allows three
    binomial sd of Monte Carlo error). Measured over 6000 at N = 200: 1.0 %; 1.3 % with χ² bins
    of equal width, 3.1 % with a Bonferroni division by the quantities only. At N = 20 (L = 20,
    3000 sets): 0.4 %; 1.8 % with 20 χ² bins expecting one replicate each."""
    rng = np.random.default_rng(11)
    settings = SbcSettings(replicates=replicates, draws=L)
    names = (*QUANTITIES, "sample_sd", "repeatability")
    simulations = 2000
    failed = sum(
        not assess_ranks(
            settings, {name: rng.integers(0, L + 1, replicates) for name in names}
        ).passed
        for _ in range(simulations)
    )
    assert failed / simulations <= 0.01 + 3 * np.sqrt(0.01 * 0.99 / simulations), failed


def test_sbc_command_json_contract_and_files(tmp_path, capsys):
    """On ``lya-fixed``: α and θs0 equal their truth in every draw and are not ranked."""
    code, out, err = run_cli(
        "sbc",
        "lya-fixed",
        "--replicates",
        "6",
        "--draws",
        "20",
        "--thin",
        "1",
        "--warmup",
        "150",
        "--warmup-tree-depth",
        "4",
        "--out",
        str(tmp_path),
        "--json",
        capsys=capsys,
    )
    assert code == 0, err
    payload = json.loads(out)
    assert payload["replicates"] == 6 and payload["draws"] == 20
    assert payload["settings"]["warmup_tree_depth"] == 4
    free = set(QUANTITIES) - {"alpha", "theta_s0"}
    assert free <= set(payload["quantities"]) and "alpha" not in payload["quantities"]
    for entry in payload["quantities"].values():
        assert len(entry["ranks"]) == 6 and all(0 <= r <= 20 for r in entry["ranks"])
        assert 0 <= entry["chi2_p"] <= 1 and 0 <= entry["ks_p"] <= 1
    assert set(payload["coverage"]) == {"0.5", "0.9", "0.95"}
    assert free == set(payload["coverage"]["0.9"]) - {"sample_sd", "repeatability"}
    assert payload["seconds"] > 0
    for name in ("sbc.json", "sbc.html", "sbc_ranks.png", "sbc_ecdf.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert json.loads((tmp_path / "sbc.json").read_text())["replicates"] == 6


def test_sbc_options_are_checked_before_any_work(tmp_path, capsys):
    for option, value in (
        ("--replicates", "0"),
        ("--draws", "0"),
        ("--sigma-scale", "0"),
        ("--warmup-tree-depth", "11"),
    ):
        code, out, err = run_cli("sbc", option, value, "--out", str(tmp_path / "x"), capsys=capsys)
        assert code == 2 and out == "" and option in err
        assert not (tmp_path / "x").exists()


@pytest.mark.slow
@pytest.mark.parametrize("sigma_scale", [1.0, 1.35])
def test_bundled_scene_is_calibrated_and_a_too_wide_sigma_is_flagged(lya, sigma_scale):
    """N = 200 (the benchmark runs the same): passes as built, fails with σ 35 % too wide."""
    result = run_sbc(*lya, SbcSettings(replicates=200, sigma_scale=sigma_scale))
    assert result.passed == (sigma_scale == 1.0), result.failures
