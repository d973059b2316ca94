"""The physical prior's boundary (no coating with TIS ≥ 1 − margin) as the sampler meets it:
the whitened coordinates map ln BRDF0 below its bound (brdf_infer/model/_energy.py), so no
NUTS trajectory ends on a wall, the density stays the truncated posterior, and simulations draw
the same prior."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro.infer.util import log_density

import brdf_infer.posterior._model as model_module
from brdf_infer.model import (
    below_bound,
    conserves_energy,
    log_brdf0_bound,
    max_log_tis,
)
from brdf_infer.model._energy import ENERGY_NODES, ENERGY_THETA_I_DEG, LOG_TIS_LIMIT
from brdf_infer.model._tis import log_tis
from brdf_infer.model.params import (
    PAPER_CONSTANTS,
    PARAM_NAMES,
    UV_PAPER,
    Params,
    with_dphi_scale,
)
from brdf_infer.posterior import build_posterior_model
from brdf_infer.posterior._potential import FlatPotential

LINEAR_SITES = ("log_brdf0", "b1", "b2", "b3")
SHARED = {"alpha": 3.4, "t_s0": -0.13, "log_dphi_scale": 0.1, "sample_sd": 0.04}
SHARED["repeatability"] = 0.06
POINTS = (0.0, 30.0, 45.0, 60.0, 300.0)  # the first whitened coefficient of the test points


def _params(sites: dict) -> Params:
    return Params(*(jnp.asarray(sites[name]) for name in PARAM_NAMES))


def _raw_prior(model, count: int, seed: int) -> Params:
    """Draws of the scene's priors without the energy truncation."""
    from numpyro.infer import Predictive

    draws = Predictive(model, num_samples=count)(jax.random.PRNGKey(seed), mode="simulate")
    return _params(draws)


def _without_the_maps_jacobian(monkeypatch) -> None:
    """Planted fault: the map below the bound keeps its values but drops its log-Jacobian."""
    monkeypatch.setattr(
        model_module, "below_bound", lambda x, bound, s: (below_bound(x, bound, s)[0], 0.0)
    )


# ------------------------------------------------------------------ the bound and the map


@pytest.mark.full
def test_the_tis_is_proportional_to_brdf0_so_energy_conservation_bounds_ln_brdf0(lya):
    """max ln TIS = ln BRDF0 + (LOG_TIS_LIMIT − bound) for prior draws on both sides of the
    boundary, and the check keeps a coating exactly when ln BRDF0 ≤ bound."""
    params = _raw_prior(build_posterior_model(*lya), 400, seed=3)
    bound = np.asarray(log_brdf0_bound(params))
    log_brdf0 = np.log(np.asarray(params.brdf0))
    largest = np.asarray(max_log_tis(params))
    np.testing.assert_allclose(largest, log_brdf0 + LOG_TIS_LIMIT - bound, rtol=0, atol=1e-11)
    kept = np.asarray(conserves_energy(params))
    assert 0.2 < kept.mean() < 0.9  # both sides are drawn
    assert np.array_equal(kept, log_brdf0 <= bound)


def test_the_largest_ln_tis_and_its_gradient_are_the_maximum_over_the_check_angles():
    """max_log_tis evaluates ln TIS again at the largest angle, its gradient through that one
    angle only: its value and gradient are those of the maximum over all check angles (the
    reference here), for parameter sets whose largest angle differs, one Δφ each."""
    rng = np.random.default_rng(5)
    count = 24
    base = np.array(UV_PAPER, float)
    fields = base[None, :] * np.exp(rng.normal(0.0, 0.3, (count, 6)))
    fields[:, 4] = rng.uniform(1.5, 6.0, count)  # alpha
    fields[:, 5] = rng.uniform(-10.0, 10.0, count)  # theta_s0 [deg]
    params = Params(*(jnp.asarray(column) for column in fields.T))
    constants = with_dphi_scale(PAPER_CONSTANTS, jnp.exp(rng.normal(0.0, 0.3, count)))

    def reference(params, constants):
        angles = jnp.asarray(ENERGY_THETA_I_DEG)
        return jnp.max(log_tis(angles, params, False, constants, ENERGY_NODES), axis=-1)

    values = reference(params, constants)
    largest = jnp.argmax(
        log_tis(jnp.asarray(ENERGY_THETA_I_DEG), params, False, constants, ENERGY_NODES), -1
    )
    assert len(np.unique(np.asarray(largest))) >= 3  # several largest angles are tried
    np.testing.assert_allclose(max_log_tis(params, constants), values, rtol=0, atol=1e-13)
    ours = jax.grad(lambda p, c: max_log_tis(p, c).sum(), argnums=(0, 1))(params, constants)
    theirs = jax.grad(lambda p, c: reference(p, c).sum(), argnums=(0, 1))(params, constants)
    for mine, expected in zip(jax.tree.leaves(ours), jax.tree.leaves(theirs), strict=True):
        np.testing.assert_allclose(mine, expected, rtol=1e-12, atol=1e-14)


@pytest.mark.full
def test_the_map_below_the_bound_is_smooth_increasing_and_finite_everywhere():
    """y = bound − s·softplus((bound − x)/s): x within s·e^(−(bound − x)/s) far below, below
    the bound everywhere, increasing, its log-slope the log of its derivative (forward
    differences inside, autodiff everywhere), no NaN in values or gradients at any x."""
    s, bound = 0.1, -2.0
    x = jnp.concatenate(
        [
            jnp.array([-1e300, -1e6, -50.0]),
            jnp.linspace(bound - 5.0, bound + 5.0, 201),  # holds the bound itself
            jnp.array([50.0, 1e6, 1e300]),
        ]
    )
    y, log_slope = below_bound(x, bound, s)
    slope = jax.vmap(jax.grad(lambda v: below_bound(v, bound, s)[0]))(x)
    slope_of_bound = jax.vmap(jax.grad(lambda b, v: below_bound(v, b, s)[0]), (None, 0))(bound, x)
    log_slope_gradient = jax.vmap(jax.grad(lambda v: below_bound(v, bound, s)[1]))(x)
    both_of_scale = jax.grad(lambda c, v: sum(below_bound(v, bound, c)))
    slope_of_scale = jax.vmap(both_of_scale, (None, 0))(s, x)
    for values in (y, log_slope, slope, slope_of_bound, log_slope_gradient, slope_of_scale):
        assert not np.any(np.isnan(np.asarray(values)))
    assert np.all(np.asarray(y) <= bound) and np.all(np.diff(np.asarray(y)) >= 0)
    assert np.all(np.asarray(y)[x < bound + 3.0] < bound)  # strictly, up to 30 s above it
    np.testing.assert_allclose(np.exp(log_slope), slope, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(slope + slope_of_bound, 1.0, rtol=0, atol=1e-12)
    far = np.asarray(x) < bound - 1.0
    deviation = np.abs(np.asarray(y - x))[far]
    # (and float64's rounding of x, |x| < 10 here, 1e-300 and 1e6 apart)
    closeness = s * np.exp((np.asarray(x)[far] - bound) / s) + 1e-14 * np.abs(np.asarray(x)[far])
    assert np.all(deviation <= closeness)
    assert float(below_bound(jnp.asarray(bound), bound, s)[0]) == pytest.approx(
        bound - s * math.log(2)
    )
    assert float(below_bound(jnp.asarray(bound), bound, s)[1]) == pytest.approx(-math.log(2))
    # the log-slope against forward differences of y inside the map's bend
    inside = jnp.linspace(bound - 1.0, bound + 1.0, 41)
    step = 1e-6
    ahead = below_bound(inside + step, bound, s)[0]
    numeric = (ahead - below_bound(inside, bound, s)[0]) / step
    np.testing.assert_allclose(np.exp(below_bound(inside, bound, s)[1]), numeric, rtol=1e-4)


@pytest.mark.full
def test_every_point_the_sampler_can_reach_is_a_coating_that_conserves_energy(lya):
    """Points of the whitened model's flat space, its whitened coefficients near and far
    (±5, ±1000) and the other coordinates within ±5: every one constrains to a coating the
    check keeps; near ones have a finite potential and gradient. (Far out the bound can put ln
    BRDF0 below −745, where BRDF0 underflows to 0 and the likelihood's value or gradient is
    NaN, as the direct model's is at such a ln BRDF0: not the map's, whose own gradient is
    finite there.)"""
    model = build_posterior_model(*lya)
    flat = FlatPotential(model)
    rng = np.random.default_rng(4)
    points = rng.uniform(-5.0, 5.0, (400, flat.dimension))
    positions = flat.unravel(jnp.arange(flat.dimension, dtype=float))["linear_std"]
    points[200:, np.asarray(positions).astype(int)] *= 200.0  # the whitened coefficients
    constrain = jax.jit(jax.vmap(lambda z: flat.constrain(z, model.data)))
    sites = constrain(jnp.asarray(points))
    widths = with_dphi_scale(PAPER_CONSTANTS, sites["dphi_scale"])  # each point's own Δφ
    assert bool(jnp.all(conserves_energy(_params(sites), widths)))
    value_and_grad = jax.jit(jax.vmap(jax.value_and_grad(lambda z: flat.potential(z, model.data))))
    values, gradients = value_and_grad(jnp.asarray(points[:200]))
    assert np.all(np.isfinite(np.asarray(values))) and np.all(np.isfinite(np.asarray(gradients)))
    unit = Params(*(jnp.ones(400) if n == "brdf0" else sites[n] for n in PARAM_NAMES))
    bound_gradient = jax.vmap(jax.grad(lambda p: log_brdf0_bound(p)))(unit)
    assert all(np.all(np.isfinite(np.asarray(g))) for g in bound_gradient)


@pytest.mark.full
@pytest.mark.parametrize("planted", [False, True], ids=["as built", "map without Jacobian"])
def test_the_whitened_density_is_the_truncated_posterior_at_and_beyond_the_bound(
    lya, monkeypatch, planted
):
    """log p(u) of the whitened model = log p(c(u)) of the direct model (the scene's priors
    truncated at the boundary, times the likelihood) + ln|det ∂c/∂u| (forward-mode), at points
    whose unmapped ln BRDF0 lies below, at and far beyond its bound; dropping the map's
    log-Jacobian (planted) breaks it beyond the bound by more than 1."""
    if planted:
        _without_the_maps_jacobian(monkeypatch)
    whitened = build_posterior_model(*lya)
    direct = build_posterior_model(*lya, reparametrise=False)

    def coefficients(u):
        _, trace = log_density(whitened, (), {}, {**SHARED, "linear_std": u})
        return jnp.stack([trace[name]["value"] for name in LINEAR_SITES])

    @jax.jit
    def densities(u):
        values = dict(zip(LINEAR_SITES, coefficients(u), strict=True))
        log_whitened = log_density(whitened, (), {}, {**SHARED, "linear_std": u})[0]
        log_direct = log_density(direct, (), {}, {**SHARED, **values})[0]
        return log_whitened, log_direct, jnp.linalg.slogdet(jax.jacfwd(coefficients)(u))[1]

    errors = []
    for first in POINTS:  # u₀ moves ln BRDF0 up to and past its bound
        log_whitened, log_direct, log_jacobian = densities(jnp.array([first, -1.2, 0.4, 2.0]))
        assert np.isfinite(float(log_direct))  # every mapped point is inside the support
        errors.append(float(log_whitened - log_direct - log_jacobian))
    if planted:
        assert max(abs(e) for e in errors) > 1.0, errors
    else:
        np.testing.assert_allclose(errors, 0.0, rtol=0, atol=1e-8)


@pytest.mark.full
def test_the_test_points_lie_below_at_and_beyond_the_bound_before_the_map(lya, monkeypatch):
    """The points of the density test cover the boundary: unmapped (the map an identity),
    their ln BRDF0 lies below its bound for u₀ ≤ 30 and beyond it for u₀ ≥ 60."""
    monkeypatch.setattr(model_module, "below_bound", lambda x, bound, s: (x, 0.0))
    whitened = build_posterior_model(*lya)
    distances = []
    for first in POINTS:
        point = {**SHARED, "linear_std": jnp.array([first, -1.2, 0.4, 2.0])}
        _, trace = log_density(whitened, (), {}, point)
        sites = {name: trace[name]["value"] for name in PARAM_NAMES}
        distances.append(float(log_brdf0_bound(_params(sites)) - trace["log_brdf0"]["value"]))
    assert distances[0] > 1.0 and distances[1] > 0.0, distances
    assert distances[-2] < 0.0 and distances[-1] < -10.0, distances


# ------------------------------------------------------------------ the bundled posterior


def test_the_map_leaves_the_bundled_posterior_as_it_was(nuts_run, lya, monkeypatch):
    """At every draw of the bundled posterior the map moves ln BRDF0 by less than 1e-7 and
    its log-Jacobian is above −1e-6 (measured on the suite's 4000 draws: 3.8e-12 and
    −3.7e-11 at most), so the sampler's coordinates there are the whitening's alone (the
    density is the truncated posterior wherever they are); every draw conserves energy."""
    model = build_posterior_model(*lya)
    posterior = nuts_run.idata.posterior
    names = ("alpha", "t_s0", "log_dphi_scale", "sample_sd", "repeatability", "linear_std")
    sites = {
        name: jnp.asarray(posterior[name]).reshape(-1, *posterior[name].shape[2:]) for name in names
    }
    seen = {}

    def spy(x, bound, s):
        y, log_slope = below_bound(x, bound, s)
        seen.update(moved=y - x, log_slope=log_slope)
        return y, log_slope

    monkeypatch.setattr(model_module, "below_bound", spy)

    def at(point):
        log_density(model, (), {}, point)
        return seen["moved"], seen["log_slope"]

    moved, log_slope = jax.jit(jax.vmap(at))(sites)
    assert float(jnp.max(jnp.abs(moved))) < 1e-7
    assert float(jnp.min(log_slope)) > -1e-6
    # each draw at its own out-of-plane width
    widths = with_dphi_scale(PAPER_CONSTANTS, jnp.asarray(posterior["dphi_scale"].values))
    params = _params({n: posterior[n].values for n in PARAM_NAMES})
    assert bool(jnp.all(conserves_energy(params, widths)))


# ------------------------------------------------------------------ sampling at the boundary


NUTS_SEEDS = range(4)  # seeds of the sampler on the same data


def _divergences(model, seeds) -> np.ndarray:
    """Divergent transitions of NUTS with the default settings (4 chains, 1000 warmup, 1000
    draws; ``brdf-infer posterior``'s) through the run's own program, one count per seed of
    ``seeds``: the chains of all seeds side by side, each with its own key, as separate runs
    would draw them."""
    from brdf_infer.posterior._nuts import NutsProgram, chain_keys

    program = NutsProgram(model, warmup=1000)
    keys = jnp.concatenate([chain_keys(seed, 1, 4)[0] for seed in seeds])
    output = program.run(model.data, keys, 1000)
    return np.asarray(output.stats["diverging"]).reshape(len(seeds), -1).sum(axis=1)


@pytest.mark.slow
@pytest.mark.parametrize("planted", [False, True], ids=["as built", "hard boundary"])
def test_a_one_sample_scene_samples_with_rare_divergences_at_the_boundary(
    tmp_path, monkeypatch, planted
):
    """The 20-row, one-sample single-series scene (data simulated at the UV parameters, seed
    15, whose posterior reaches TIS 0.9 at its edge), NUTS with default settings from four
    seeds. Measured over sampler seeds 0–15 (2026-11-29, 16 runs, 64,000 transitions): with
    the map 6 divergent transitions, at most 2 a run and none in 10 of the 16 runs; with the
    hard boundary planted (the map an identity: the factor's −∞ beyond the bound, as before the
    map) 260, 8–23 a run. Over seeds 0–3: at most 8 with the map (a Poisson count of mean
    6 × 4/16 = 1.5 exceeds 8 with probability 2·10⁻⁵), at least 24 with the hard boundary
    (measured 73; four runs of 16 ± 4.5 each sum to 65 ± 9, and 24 lies 4.5 sd below)."""
    from brdf_infer.model.params import UV_PAPER
    from brdf_infer.scene import load_scene
    from brdf_infer.studies.synthetic import write_geometry_scene

    if planted:
        monkeypatch.setattr(model_module, "below_bound", lambda x, bound, s: (x, 0.0))
    scene = load_scene(write_geometry_scene(tmp_path, "single-series", UV_PAPER, seed=15))
    model = build_posterior_model(scene, scene.load_measurements())
    divergences = _divergences(model, NUTS_SEEDS)
    if planted:
        assert divergences.sum() >= 24, divergences
    else:
        assert divergences.sum() <= 8, divergences


def _weak_data_scene(folder) -> object:
    """The single-series geometry with σ 100 times each value: the whitening is then the
    priors' own standardisation, and the prior alone is easy to sample."""
    from brdf_infer.scene import load_scene
    from brdf_infer.studies.synthetic import GEOMETRIES

    header = "series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"
    rows = [f"A,{m},{ti:g},{ts:g},1e-3,1e-1" for m, ti, ts in GEOMETRIES["single-series"]]
    (folder / "rows.csv").write_text("\n".join([header, *rows]) + "\n")
    (folder / "scene.toml").write_text(
        'name = "weak"\nmeasurements = "rows.csv"\n'
        "[series.A]\naperture_diameter_mm = 7.5\naperture_distance_mm = 110.0\n"
    )
    return load_scene(folder / "scene.toml")


@pytest.mark.slow
@pytest.mark.parametrize("planted", [False, True], ids=["as built", "map without Jacobian"])
def test_the_samplers_prior_is_the_prior_simulations_draw(tmp_path, monkeypatch, planted):
    """NUTS on the whitened model with its likelihood hidden samples the model's prior; its
    largest check value ln TIS and its ln BRDF0 (4 × 1000 draws, every 10th) against 4000
    draws of :func:`brdf_infer.posterior.prior_draws` (rejection, as SBC and the studies draw
    their truths): the same distribution (two-sample KS, p > 0.001; measured p 0.52 and
    0.997), and a planted map without its log-Jacobian fails it (measured p 5e-324 and 1e-84).
    (The prior alone presses a third of its mass against the boundary: NUTS diverged 48 times
    in these 8000 iterations with the map, 2612 with the hard boundary, 0 without the physical
    prior.)"""
    from numpyro import handlers
    from numpyro.infer import MCMC, NUTS
    from scipy import stats

    from brdf_infer.posterior import prior_draws

    if planted:
        _without_the_maps_jacobian(monkeypatch)
    scene = _weak_data_scene(tmp_path)
    model = build_posterior_model(scene, scene.load_measurements())
    sampler = MCMC(
        NUTS(handlers.block(model, hide=["obs"]), dense_mass=True),
        num_warmup=1000,
        num_samples=1000,
        num_chains=4,
        chain_method="sequential",
        progress_bar=False,
    )
    sampler.run(jax.random.PRNGKey(0), model.data)
    by_chain = sampler.get_samples(group_by_chain=True)
    sampled = {k: v[:, ::10].reshape(-1, *v.shape[2:]) for k, v in by_chain.items()}
    simulated = prior_draws(model, 4000, 1, frozenset(PARAM_NAMES))
    p_values = [
        stats.ks_2samp(
            np.asarray(max_log_tis(_params(sampled))),
            np.asarray(max_log_tis(_params(simulated))),
        ).pvalue,
        stats.ks_2samp(np.log(sampled["brdf0"]), np.log(simulated["brdf0"])).pvalue,
    ]
    if planted:
        assert min(p_values) < 1e-10, p_values
    else:
        assert min(p_values) > 1e-3, p_values
