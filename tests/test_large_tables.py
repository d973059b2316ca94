"""Whole instrument tables: the leave-one-out terms, PSIS-LOO and the stored draws hold no
rows × rows object and no draws × rows × columns block beyond a bounded size, and give the
numbers of the direct computation (ArviZ's ``loo``, one block of every draw)."""

from __future__ import annotations

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer._internal.lowrank import leave_one_out_conditionals
from brdf_infer.posterior import _blocks as blocks
from brdf_infer.posterior import _results as results
from brdf_infer.posterior._loo import loo_pit, psis_loo, relative_efficiency
from brdf_infer.posterior._power_scaling import log_likelihood_draws
from brdf_infer.posterior._prior import prior_draws
from brdf_infer.posterior._run import build_model, predictive_checks


def _posterior_like(rng, chains: int, draws: int, rows: int):
    """Correlated chains of two variables and pointwise log likelihoods with a heavy row."""
    walk = np.cumsum(rng.normal(size=(chains, draws, 2)), axis=1) * 0.05
    log_lik = -0.5 * (rng.normal(size=(chains, draws, rows)) + walk[..., :1]) ** 2
    log_lik[..., 0] *= 6.0  # a row the posterior fits badly: large Pareto k
    return az.from_dict(
        posterior={"a": walk[..., 0], "b": walk[..., 1]}, log_likelihood={"obs": log_lik}
    )


@pytest.mark.parametrize("rows_per_chunk", [1, 7, 4096])
def test_blockwise_psis_loo_is_arviz_loo_and_the_loo_pit(rows_per_chunk):
    rng = np.random.default_rng(3)
    idata = _posterior_like(rng, chains=4, draws=300, rows=23)
    log_lik = idata.log_likelihood["obs"].values
    cdf = rng.uniform(size=log_lik.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = az.loo(idata, pointwise=True)
    got = psis_loo(log_lik, cdf, relative_efficiency(idata.posterior), rows_per_chunk)
    assert got.elpd_loo == pytest.approx(float(expected.elpd_loo), rel=1e-12)
    assert got.se == pytest.approx(float(expected.se), rel=1e-10)
    assert got.p_loo == pytest.approx(float(expected.p_loo), rel=1e-10)
    np.testing.assert_allclose(got.pareto_k, np.asarray(expected.pareto_k), atol=1e-12)
    assert got.pareto_k[0] > 0.7  # the planted heavy row is seen
    # the LOO-PIT from ArviZ's smoothed weights with the same relative efficiency (ArviZ's
    # loo_pit smooths with it too), written out here
    log_weights, _ = az.psislw(-log_lik.reshape(-1, 23).T, relative_efficiency(idata.posterior))
    weights = np.exp(log_weights) / np.exp(log_weights).sum(axis=1, keepdims=True)
    np.testing.assert_allclose(got.pit, np.sum(weights * cdf.reshape(-1, 23).T, axis=1))
    reff = relative_efficiency(idata.posterior)
    np.testing.assert_allclose(got.pit, loo_pit(log_lik.reshape(-1, 23), cdf.reshape(-1, 23), reff))


def test_leave_one_out_conditionals_hold_no_rows_by_rows_matrix():
    """At 20 000 rows a rows × rows float64 matrix is 3.2 GB; the program's scratch memory must
    stay linear in the rows (it held the identity matrix before)."""
    rows, columns = 20_000, 12
    args = (
        jnp.zeros(rows),
        jnp.zeros(rows),
        jnp.zeros((rows, columns)),
        jnp.ones(rows),
    )
    compiled = jax.jit(leave_one_out_conditionals).lower(*args).compile()
    scratch = compiled.memory_analysis().temp_size_in_bytes
    assert scratch < 256 * rows * 8, scratch  # linear; rows × rows would be 3.2e9


@pytest.mark.full
def test_leave_one_out_terms_by_blocks_of_draws_are_those_of_one_block(lya, monkeypatch):
    scene, measurements = lya
    model = build_model(scene, measurements)
    draws = prior_draws(model, 24, seed=5)
    sites = {k: v.reshape(2, 12, *v.shape[1:]) for k, v in draws.items() if k != "obs"}
    whole = results.loo_terms(model, sites)
    whole_joint = log_likelihood_draws(model, sites)
    columns = 4 + blocks.factor_columns(model.data.noise)
    monkeypatch.setattr(blocks, "CHUNK_VALUES", 5 * 42 * columns)  # blocks of 5, last padded
    assert blocks.draw_blocks(24, 42, columns) == 5
    by_blocks = results.loo_terms(model, sites)
    joint = log_likelihood_draws(model, sites)
    assert joint.shape == (2, 12)
    np.testing.assert_allclose(joint, whole_joint, rtol=1e-12)
    for a, b in zip(whole, by_blocks, strict=True):
        assert a.shape == (2, 12, 42)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300)


@pytest.mark.full
def test_repeated_draws_are_computed_once_and_their_terms_are_those_of_every_draw(lya):
    """A Laplace run's resampled draws repeat: the leave-one-out terms and the joint
    likelihood are computed on the distinct draws and spread back; the same values as draw by
    draw (a planted fault, the inverse map shuffled, must differ)."""
    scene, measurements = lya
    model = build_model(scene, measurements)
    draws = prior_draws(model, 6, seed=5)
    repeat = np.array([0, 3, 3, 1, 0, 5, 5, 5, 2, 4, 1, 3])
    sites = {k: v[repeat].reshape(2, 6, *v.shape[1:]) for k, v in draws.items() if k != "obs"}
    flat = results.flatten_draws(sites)
    distinct, inverse = blocks.distinct_draws(flat)
    assert len(next(iter(distinct.values()))) == 6 and inverse is not None
    calls = []

    def terms(block):
        calls.append(len(next(iter(block.values()))))
        return (np.asarray(block["alpha"]) * 2.0,)

    (doubled,) = blocks.over_draw_blocks(terms, flat, 42, 1)
    assert calls == [6]
    np.testing.assert_array_equal(doubled, 2.0 * flat["alpha"])
    separate = {k: v[repeat] for k, v in draws.items() if k != "obs"}
    one_by_one = np.stack(
        [
            log_likelihood_draws(model, {k: v[i : i + 1] for k, v in separate.items()})[0]
            for i in range(repeat.size)
        ]
    )
    joint = log_likelihood_draws(model, sites).reshape(-1)
    np.testing.assert_allclose(joint, one_by_one, rtol=1e-12)
    assert not np.allclose(joint[np.argsort(inverse)], one_by_one)


def test_posterior_nc_keeps_every_draw_of_a_small_run_and_bounded_values_of_a_table():
    assert results.thinned_draws(1000, 42, 4).size == 1000  # the bundled run: all
    vendor = results.thinned_draws(1000, 2043, 4)
    assert 4 * vendor.size * 2043 <= results.PREDICTIVE_VALUES
    assert vendor[0] == 0 and vendor[-1] == 999 and np.all(np.diff(vendor) > 0)
    table = results.thinned_draws(1000, 59_585, 4)
    assert table.size == results.PREDICTIVE_MIN_DRAWS
    small, large = np.zeros((4, 1000, 42)), np.zeros((4, 1000, 2043), np.float32)
    assert "log_likelihood" in results.stored_log_likelihood(small)
    assert results.stored_log_likelihood(large) == {}


@pytest.mark.full
def test_prior_draws_of_the_posterior_sites_are_the_same_draws_without_the_rows(lya):
    """The answer records draw 4000 prior draws: with every row's simulated ``obs`` that is
    4000 × rows values twice over (3.8 GB for a 60 000-row table); asked for the posterior's
    sites only, the draws are the same and no ``obs`` is made."""
    scene, measurements = lya
    model = build_model(scene, measurements)
    full = prior_draws(model, 40, seed=7)
    sites = frozenset({"brdf0", "repeatability", "sample_sd"})
    lean = prior_draws(model, 40, seed=7, sites=sites)
    assert "obs" in full and "obs" not in lean
    assert set(model.family.parameters) | sites == set(lean)
    for name, values in lean.items():
        np.testing.assert_array_equal(values, full[name])


def test_a_run_the_machine_cannot_hold_is_refused_in_one_line_before_it_samples():
    from brdf_infer.errors import BadInputError
    from brdf_infer.posterior._memory import check_memory, estimated_bytes

    # the bundled run adds a few tens of MiB: not refused unless the machine is out of memory
    assert 0 < estimated_bytes(42, 4000, 4, 12) < 192 * 2**20
    assert check_memory(42, 4000, 4, 12) > 0
    with pytest.raises(BadInputError, match=r"10000000 rows × 4000 draws need about .* GiB"):
        check_memory(10_000_000, 4000, 4, 20)


def test_the_report_summarises_a_long_table_per_incidence_angle(lya):
    """A whole table's rows are not listed in the report (60 000 HTML rows), one line per θi."""
    import dataclasses

    from brdf_infer.report._run_tables import DATA_TABLE_ROWS, data_table

    _, measurements = lya
    assert "<td>I</td>" in data_table(measurements)  # the bundled rows are listed
    copies = DATA_TABLE_ROWS // len(measurements) + 1
    long = dataclasses.replace(
        measurements,
        **{
            name: np.tile(getattr(measurements, name), copies)
            for name in ("series", "sample", "theta_i_deg", "theta_s_deg", "reflectance")
        },
        reflectance_err=None,
    )
    html = data_table(long)
    assert f"{len(long)} rows, too many to list" in html
    assert html.count("<tr>") == 1 + np.unique(measurements.theta_i_deg).size


def test_psis_loo_of_a_large_table_reads_a_quarter_of_the_draws(nuts_run):
    """From 1000 draws a chain the terms PSIS-LOO reads are thinned to LOO_MIN_DRAWS a chain
    on a whole table, not below 4000 draws on the 2 × 10³-row one; on the bundled run the
    elpd of every 4th draw is the elpd of all of them within its standard error's fifth
    (measured 0.30 apart, se 5.2), and posterior.nc keeps no terms of thinned draws."""
    keep = {rows: results.loo_draws(1000, rows, 4) for rows in (42, 1986, 59_585)}
    assert keep[42].size == keep[1986].size == 1000
    assert keep[59_585].size == results.LOO_MIN_DRAWS
    log_lik = nuts_run.idata.log_likelihood["obs"].values
    cdf = np.full_like(log_lik, 0.5)
    everything = psis_loo(log_lik, cdf, 1.0)
    quarter = psis_loo(log_lik[:, ::4], cdf[:, ::4], 1.0)
    assert abs(quarter.elpd_loo - everything.elpd_loo) < 0.2 * everything.se
    assert results.stored_log_likelihood(None) == {}


def test_the_pareto_k_limit_follows_the_draws_psis_loo_read(lya, nuts_run):
    """min(1 − 1/log₁₀ S, 0.7) (Vehtari et al. 2024, Sec. 3): the bundled run's draws (over
    2200) are judged at 0.7, the 1000 of a thinned table at 2/3; the count, the named rows and
    the verdict's words follow it, and a refit keeps it."""
    log_lik = nuts_run.idata.log_likelihood["obs"].values
    cdf = np.full_like(log_lik, 0.5)
    assert psis_loo(log_lik, cdf, 1.0).limit == 0.7
    every = log_lik.shape[1] // 250  # 250 a chain: 1000 draws
    thinned = psis_loo(log_lik[:, ::every], cdf[:, ::every], 1.0)
    assert thinned.limit == pytest.approx(2 / 3)
    assert thinned.with_exact({}).limit == thinned.limit
    # a row planted between the two limits counts for the thinned draws only
    planted = dataclasses.replace(thinned, pareto_k=np.full(thinned.pareto_k.size, 0.1))
    planted.pareto_k[5] = 0.68
    checks = predictive_checks(planted, lya[1])
    assert checks["pareto_k_limit"] == pytest.approx(2 / 3)
    assert checks["pareto_k_high"] == 1 and [r["row"] for r in checks["pareto_k_rows"]] == [5]
    as_if_all = predictive_checks(dataclasses.replace(planted, limit=0.7), lya[1])
    assert as_if_all["pareto_k_high"] == 0
