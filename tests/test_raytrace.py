"""Ray-tracing validation of the series II setup (Sec. 6): estimators against Eq. (6) and
against each other, geometry against hand-computed values, the CLI contract."""

import json
import math
import textwrap
from dataclasses import replace

import jax
import numpy as np
import pytest

from brdf_infer.model.params import UV_PAPER
from brdf_infer.studies.raytrace import (
    TALLIES,
    build_setup,
    configurations,
    point_estimate,
    raytrace_posterior_payload,
    raytrace_series,
    thin_draws,
    trace_configuration,
    with_aperture,
)
from brdf_infer.studies.raytrace._trace import tally_moments
from tests.helpers import run_cli, run_on_forced_cpu_devices


def _config(lya, theta_i, delta):
    scene, measurements = lya
    return next(
        c
        for c in configurations(scene, measurements)
        if (c.theta_i_deg, c.delta_deg) == (theta_i, delta)
    )


def _thin_beam(scene):
    """A pencil beam: Eq. (6) holds exactly in the limit of a vanishing AD."""
    settings = replace(
        scene.raytrace,
        source_diameter_mm=1e-3,
        beam_apertures_mm=((4.8, 32.0), (16.0, 93.0), (0.01, 211.0)),
    )
    return replace(scene, raytrace=settings)


@pytest.mark.full
@pytest.mark.parametrize(("theta_i", "delta"), [(45.0, 0.0), (75.0, -15.0), (80.0, 5.0)])
def test_vanishing_detector_aperture_converges_to_the_point_estimate(lya, theta_i, delta):
    """dPs/Pi → BRDF·Ω·cos θs as d → 0; the difference is the BRDF's variation across AD
    (first order in d because of the cusp of Eq. (8) at φ = 180°)."""
    scene = _thin_beam(lya[0])
    configuration = _config(lya, theta_i, delta)
    errors = []
    for diameter in (2.0, 0.5, 0.1):
        small = with_aperture(scene, diameter)
        setup, limiting = build_setup(small)
        estimate = trace_configuration(
            configuration,
            UV_PAPER,
            setup,
            limiting,
            small.model.constants,
            2**16,
            jax.random.PRNGKey(3),
            fold=small.model.fold,
        )
        exact = point_estimate(configuration, UV_PAPER, small)
        errors.append(abs(estimate.simulated / exact - 1))
        assert estimate.mc_se / estimate.simulated < 1e-3
    assert errors[0] > 3.0 * errors[1] > 9.0 * errors[2]  # linear in d
    assert errors[2] < 1e-3


@pytest.mark.full
def test_naive_and_next_event_estimators_agree_within_monte_carlo_error(lya):
    scene = lya[0]
    setup, limiting = build_setup(scene)
    for theta_i, delta in ((45.0, 0.0), (80.0, -5.0)):
        configuration = _config(lya, theta_i, delta)
        values = {
            estimator: trace_configuration(
                configuration,
                UV_PAPER,
                setup,
                limiting,
                scene.model.constants,
                2**19,
                jax.random.PRNGKey(11),
                estimator,
            )
            for estimator in ("nee", "naive")
        }
        nee, naive = values["nee"], values["naive"]
        assert abs(nee.simulated - naive.simulated) < 4 * math.hypot(nee.mc_se, naive.mc_se)
        assert naive.mc_se > 20 * nee.mc_se  # the point of next-event estimation


@pytest.mark.slow  # 10^6 rays × 18 configurations; the suite checks the same from 2^17 rays
# (test_uv_paper_image_ratio_follows_table_2_as_figure_14_shows: the 1/√rays scaling)
def test_a_million_rays_give_below_one_percent_error_per_configuration(lya):
    result = raytrace_series(*lya, UV_PAPER, rays=1_000_000)
    assert result.rays == 1_000_000 and len(result.rows) == 18
    for row in result.rows:
        assert row["mc_se"] / row["simulated"] < 0.01, row
        assert row["image_ratio_se"] / row["image_ratio"] < 0.01, row


@pytest.mark.full
def test_reference_beam_through_the_detector_aperture_matches_the_projected_beam(lya):
    """Point source: the beam at AD (470 mm) is the last beam aperture scaled by 470/211, so
    AD passes (r_AD / (r_A3·470/211))² of it."""
    scene = lya[0]
    settings = replace(scene.raytrace, source_diameter_mm=1e-6, detector_size_mm=(900.0, 900.0))
    setup, limiting = build_setup(replace(scene, raytrace=settings))
    sums, _ = tally_moments(
        jax.random.PRNGKey(0),
        45.0,
        45.0,
        UV_PAPER,
        setup,
        scene.model.constants,
        2**18,
        "nee",
        limiting,
    )
    fraction = float(sums[TALLIES.index("reference_detector")] / sums[TALLIES.index("beam")])
    expected = (3.75 / (2.315 * 470.0 / 211.0)) ** 2
    assert fraction == pytest.approx(expected, abs=4 * math.sqrt(expected * (1 - expected) / 2**18))


def test_the_sample_clips_the_footprint_at_grazing_incidence(lya):
    """At θi = 80° the ~8 mm beam spans ~46 mm on the 40 mm sample; a larger sample
    recovers the lost power, at 45° nothing changes."""
    scene = lya[0]
    for theta_i, delta, gain in ((80.0, 0.0, True), (45.0, 0.0, False)):
        configuration = _config(lya, theta_i, delta)
        values = []
        for size in (40.0, 100.0):
            settings = replace(scene.raytrace, sample_size_mm=(size, size))
            setup, limiting = build_setup(replace(scene, raytrace=settings))
            values.append(
                trace_configuration(
                    configuration,
                    UV_PAPER,
                    setup,
                    limiting,
                    scene.model.constants,
                    2**17,
                    jax.random.PRNGKey(5),
                ).simulated
            )
        ratio = values[1] / values[0]
        assert (ratio > 1.05) if gain else ratio == pytest.approx(1.0, abs=1e-9)


SIGMA_E_UV = 0.064  # the article's fit error at 121.6 nm, mean |ln(fitted/measured)| (Sec. 5.3)


@pytest.mark.full
def test_uv_paper_image_ratio_follows_table_2_as_figure_14_shows(lya):
    """Fig. 14 plots the measured raw reflectance of series II against the simulated image
    ratio (Sec. 6: both images averaged over the same rectangle on the light spot, then
    divided) and reports "general agreement"; the text gives no number. Made a number:

    - Shape: up to one common factor, the simulated image ratios follow Table 2 as closely as
      the article's fit of the same BRDF follows its data, σE = 6.4 % (mean |ln|). The mean
      |centred ln(image ratio/measured)| over the 18 configurations estimates that with a
      standard error of σE·√(π/2 − 1)/√18 = 0.18 σE (normal residuals), so it must stay below
      σE + 3 se = 0.098 (Monte Carlo adds < 1 % per configuration at 2^17 rays). A BRDF with
      a1 10 % lower or 20 % higher than the article's gives 0.14 and 0.12; uv-paper 0.079.
    - Level: our image ratio lies a factor 1.25 above Table 2 (docs/raytrace.md,
      docs/instruments.md), an offset the article's figure does not show: the article does not
      describe its simulated reference image beyond "the same rectangle", and the level of an
      image ratio depends on it (AD passes only part of the reference beam). Checked is our
      own known factor, to its Monte Carlo error: the mean ln over the 18 configurations has
      a standard error √(Σ seᵢ²)/18 from the rows' ``image_ratio_se`` (0.31 % at 2^17 rays;
      seeds 0–3 gave 1.244, 1.256, 1.247, 1.248), so it must lie within ln(1.255/1.25)
      (the factor's printing, 0.4 %) + 3 se ≈ 1.3 % of ln 1.25. The factor 1.5 this replaced
      passed anything from 0.67 to 1.5; planted by hand, a BRDF0 3 % high (1.281) fails now,
      as does a reference summed over the whole detector instead of the same rectangle.
    - The Eq. (6) curve of the same BRDF (``point_estimate``) scatters about Table 2 like the
      fit: rms ln below σE·√(π/2) + 3·that/√(2·18) = 0.080 + 0.040 = 0.12.
    - dPs/Pi (``simulated``) lies below the point estimate everywhere: the sample clips the
      beam at θi = 80° and the BRDF's cusp at φ = 180° (Eq. 8) is averaged over AD and the
      footprint; both only lower it.
    """
    result = raytrace_series(*lya, UV_PAPER, rays=2**17)
    # the scene's default 10^6 rays give below 1 % Monte Carlo error per configuration: the
    # standard errors at 2^17 rays, scaled by √(2^17/10^6) (the million: a slow test above)
    to_a_million = math.sqrt(2**17 / 1e6)
    for row in result.rows:
        assert row["mc_se"] / row["simulated"] * to_a_million < 0.01, row
        assert row["image_ratio_se"] / row["image_ratio"] * to_a_million < 0.01, row
    image = np.log([row["image_ratio"] / row["measured"] for row in result.rows])
    point = np.log([row["point_estimate"] / row["measured"] for row in result.rows])
    n = len(result.rows)
    assert n == 18
    shape_bound = SIGMA_E_UV * (1 + 3 * math.sqrt(math.pi / 2 - 1) / math.sqrt(n))
    assert np.mean(np.abs(image - image.mean())) < shape_bound, image
    relative_se = [row["image_ratio_se"] / row["image_ratio"] for row in result.rows]
    level_se = math.sqrt(sum(se**2 for se in relative_se)) / n
    assert 0.002 < level_se < 0.005, level_se  # the MC error the bound below is built from
    level_bound = math.log(1.255 / 1.25) + 3 * level_se
    assert abs(image.mean() - math.log(1.25)) < level_bound, (math.exp(image.mean()), level_bound)
    rms_bound = SIGMA_E_UV * math.sqrt(math.pi / 2) * (1 + 3 / math.sqrt(2 * n))
    assert np.sqrt(np.mean(point**2)) < rms_bound
    assert all(row["simulated"] < row["point_estimate"] for row in result.rows)


def test_posterior_trace_has_a_band_around_its_median(lya, nuts_run):
    from brdf_infer.posterior import draws_params

    draws = thin_draws(draws_params(nuts_run.idata.posterior), 16)
    payload = raytrace_posterior_payload(*lya, draws, "posterior", rays=4096)
    assert payload["draws"] == 16
    for row in payload["rows"]:
        band = row["band"]
        assert band["lo95"] <= row["simulated"] <= band["hi95"]
        assert band["lo95"] < band["hi95"]


@pytest.mark.full
def test_cli_json_contract(capsys):
    code, out, err = run_cli("raytrace", "--json", "--rays", "4096", capsys=capsys)
    assert code == 0, err
    payload = json.loads(out)
    assert payload["rays"] == 4096 and payload["seconds"] > 0
    assert len(payload["rows"]) == 18
    for row in payload["rows"]:
        for key in ("theta_i_deg", "delta_deg", "simulated", "mc_se", "measured", "point_estimate"):
            assert isinstance(row[key], float) and math.isfinite(row[key]), key
    assert {(r["theta_i_deg"], r["delta_deg"]) for r in payload["rows"]} >= {
        (80.0, -15.0),
        (45.0, 15.0),
    }


@pytest.mark.full
def test_cli_writes_figures_and_warns_when_no_ray_arrives(tmp_path, capsys):
    code, _, err = run_cli(
        "raytrace", "--rays", "200", "--estimator", "naive", "--out", str(tmp_path), capsys=capsys
    )
    assert code == 0, err
    assert "warning: no ray reached the detector aperture" in err
    assert json.loads((tmp_path / "raytrace.json").read_text())["traces"][0]["rays"] == 200
    for name in ("raytrace.png", "detector_images.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # the images the report draws are the ones simulated, read back from the folder
    from brdf_infer.model.params import UV_PAPER
    from brdf_infer.scene import load_scene
    from brdf_infer.studies.raytrace import load_detector_images, simulate_images

    scene = load_scene("lya")
    expected = simulate_images(scene, scene.load_measurements(), UV_PAPER, seed=0)
    stored = load_detector_images(tmp_path)
    assert stored["theta_i_deg"] == expected["theta_i_deg"]
    assert stored["theta_s_deg"] == [float(t) for t in expected["theta_s_deg"]]
    for name in ("scattered", "reference", "x_edges_mm", "y_edges_mm", "signal_half_size_mm"):
        np.testing.assert_array_equal(stored[name], expected[name])
    assert load_detector_images(tmp_path / "nowhere") is None


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (("vis-532",), "no [raytrace] table"),
        (("--rays", "0"), "--rays must be at least 1"),
        (("--params", "no-such-set"), "neither a parameter set"),
    ],
)
def test_cli_bad_input_is_one_line_exit_2(argv, message, capsys):
    code, out, err = run_cli("raytrace", *argv, capsys=capsys)
    assert code == 2 and out == ""
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ("bogus = 1", "raytrace.bogus"),
        ('series = "III"', "raytrace.series"),
        ("sample_size_mm = [40.0]", "raytrace.sample_size_mm"),
        ("beam_apertures_mm = [[4.8, 400.0]]", "raytrace.beam_apertures_mm"),
        ("rays = 1.5", "raytrace.rays"),
        ("source_distance_mm = -1", "raytrace.source_distance_mm"),
    ],
)
def test_scene_raytrace_table_errors_name_the_key(tmp_path, table, field, capsys):
    from brdf_infer.scene import scene_file

    text = scene_file("lya").read_text().split("[raytrace]")[0]
    (tmp_path / "lya_measurements.csv").write_text(
        (scene_file("lya").parent / "lya_measurements.csv").read_text()
    )
    (tmp_path / "lya_tis_reference.csv").write_text(
        (scene_file("lya").parent / "lya_tis_reference.csv").read_text()
    )
    path = tmp_path / "bad.scene.toml"
    path.write_text(text + "[raytrace]\n" + table + "\n")
    code, _, err = run_cli("raytrace", str(path), "--rays", "64", capsys=capsys)
    assert code == 2 and field in err, err


@pytest.mark.full
def test_configurations_traced_together_are_those_traced_alone(lya):
    """The configuration axis (one vmapped call per chunk) keeps each configuration's own
    random stream: the same estimates as tracing it alone, to rounding."""
    scene, measurements = lya
    together = raytrace_series(scene, measurements, UV_PAPER, rays=3000, seed=4)
    setup, limiting = build_setup(scene)
    key = jax.random.PRNGKey(4)
    for index, configuration in enumerate(configurations(scene, measurements)[:5]):
        alone = trace_configuration(
            configuration,
            UV_PAPER,
            setup,
            limiting,
            scene.model.constants,
            3000,
            jax.random.fold_in(key, index),
            fold=scene.model.fold,
        )
        row = together.rows[index]
        assert row["simulated"] == pytest.approx(alone.simulated, rel=1e-12)
        assert row["image_ratio"] == pytest.approx(alone.image_ratio, rel=1e-12)


_SHARDED_TRACE = textwrap.dedent(
    """
    import sys, json
    import jax
    import brdf_infer
    from brdf_infer.model.params import UV_PAPER
    from brdf_infer.studies.raytrace import raytrace_series
    from brdf_infer.scene import load_scene

    brdf_infer.use_float64()
    scene = load_scene("lya")
    result = raytrace_series(scene, scene.load_measurements(), UV_PAPER, rays=3000, seed=2)
    rows = [[r["simulated"], r["image_ratio"]] for r in result.rows]
    json.dump({"devices": jax.device_count(), "rows": rows}, open(sys.argv[1], "w"))
    """
)


@pytest.mark.full
def test_configuration_axis_sharded_over_two_forced_cpu_devices(tmp_path):
    """All 18 configurations in one call, nine on each of two devices: the values of one
    device (which traces them a few at a time)."""
    results = {}
    for count in (1, 2):
        target = tmp_path / f"trace_{count}.json"
        run_on_forced_cpu_devices(_SHARDED_TRACE, target, count)
        results[count] = json.loads(target.read_text())
        assert results[count]["devices"] == count
    np.testing.assert_allclose(results[2]["rows"], results[1]["rows"], rtol=1e-12)
