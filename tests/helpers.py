"""Shared test utilities: dtype-aware comparisons, an independent reference model, the CLI."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from brdf_infer.cli import main

REPO = Path(__file__).resolve().parents[1]

# Every NUTS run of the lya structure in the suite warms up for the same number of iterations:
# a compiled NUTS program depends on the model's structure, the data's shape and the warmup
# length (NumPyro builds its adaptation schedule in Python), so runs that agree on these share
# one program, in a process and, through the persistent cache, across the test workers.
SUITE_WARMUP = 500
# 2000 draws: under the default error model the learned noise scales reach down to 0 (series
# II's values carry their own σ), and their tail ESS sits near the verdict's bar of 400 with
# fewer: over 30 seeds (a new seed is what another CPU's floating-point order amounts to), 4 ×
# 1000 draws gave a smallest tail ESS of 344-1268 (2 of 30 below 400: the suite would fail on
# such a machine), 4 × 2000 gave 870-2446 (mean 1560), R-hat at most 1.0039 and no divergent
# transition in 60 runs; the draws do not change the compiled program (the warmup does)
REDUCED_NUTS = {"chains": 4, "warmup": SUITE_WARMUP, "draws": 2000}


def lya_scene_text(measurements: Path | str, name: str = "lya") -> str:
    """The bundled ``lya`` scene's TOML named ``name`` with another measurements file: the
    same model structure as ``lya``, so the same compiled programs."""
    from benchmarks._batch import scene_text_with_measurements
    from brdf_infer.scene import load_scene

    return scene_text_with_measurements(load_scene("lya"), Path(measurements), name)


def assert_allclose(actual, desired, *, rtol: float | None = None, atol: float = 0.0) -> None:
    """``np.testing.assert_allclose`` with a float64 default of rtol = 1e-12."""
    actual = np.asarray(actual)
    assert actual.dtype in (np.float64, np.complex128, np.bool_, np.int64), actual.dtype
    np.testing.assert_allclose(actual, desired, rtol=1e-12 if rtol is None else rtol, atol=atol)


# Monte Carlo errors for tests that compare sampled quantities. A fixed seed does not make NUTS,
# emcee or anything built on their draws reproducible across CPUs (floating-point order moves a
# trajectory, and then the whole chain), so a bound on such a comparison is a number of its
# Monte Carlo standard errors, computed from the draws compared, never a fixed number.
MC_BOUND = 4.5  # standard errors of a difference: P(|z| > 4.5) = 7e-6 per comparison


def quantile_se(values, prob: float, ess: float) -> float:
    """The Monte Carlo standard error of the ``prob`` quantile of ``values`` from ``ess``
    effective draws: half the distance between the quantiles at prob ± √(prob(1 − prob)/ess),
    the order-statistic interval of a quantile (no density estimate needed)."""
    values = np.asarray(values, float).reshape(-1)
    step = math.sqrt(prob * (1.0 - prob) / ess)
    low, high = np.quantile(values, [max(prob - step, 0.0), min(prob + step, 1.0)])
    return float(high - low) / 2.0


def mcmc_quantile_se(draws, prob: float) -> float:
    """:func:`quantile_se` of MCMC draws (chains, draws): their ESS at that quantile
    (ArviZ's, autocorrelation across chains)."""
    from brdf_infer._internal import arviz as az

    draws = np.asarray(draws, float)
    ess = float(az.ess(draws, method="quantile", prob=prob))
    return quantile_se(draws, prob, ess)


def mcmc_mean_se(draws) -> float:
    """The Monte Carlo standard error of the mean of MCMC draws (chains, draws): sd / √ESS."""
    from brdf_infer._internal import arviz as az

    draws = np.asarray(draws, float)
    return float(np.std(draws) / math.sqrt(float(az.ess(draws))))


def log_sd_se(values, ess: float) -> float:
    """The Monte Carlo standard error of ln sd of ``values`` from ``ess`` effective draws:
    √((κ − 1) / (4 ess)), κ their kurtosis (1/√(2 ess) for a normal)."""
    values = np.asarray(values, float).reshape(-1)
    z = (values - values.mean()) / values.std()
    return math.sqrt((float(np.mean(z**4)) - 1.0) / (4.0 * ess))


def resampled_ess(kish: float, count: int) -> float:
    """The effective draws of ``count`` draws resampled from importance weights of Kish ESS
    ``kish``: the resampling's own noise adds 1/count to the variance factor 1/kish."""
    return 1.0 / (1.0 / kish + 1.0 / count)


def reference_brdf_inplane(theta_i: float, theta_s: float, p, fold: bool = False) -> float:
    """Eq. (7) (and Eq. 10) in plain Python floats, written from the paper independently."""
    if theta_s >= p.theta_s0:
        x = theta_s - p.theta_s0
        value = p.brdf0 * math.exp(
            p.a1 * theta_i * x + p.a2 * theta_i * x**p.alpha + p.a3 * theta_i**2 * x**p.alpha
        )
    else:
        value = p.brdf0
    if fold and theta_s >= 0:
        value *= (1.0 - math.erf(0.35 * (theta_s - 87.0))) / 2.0
    return value


def reference_brdf_hemisphere(
    theta_i: float, theta: float, phi: float, p, fold: bool = False
) -> float:
    """Eq. (8) (with Eq. 10 when ``fold``), plain Python, paper constants (c1 = −0.95,
    c2 = 90.5°)."""
    width = -0.95 * theta_i + 90.5
    distance = abs(phi - 180.0)
    weight = 1.0 - distance / width if distance < width else 0.0
    forward = reference_brdf_inplane(theta_i, theta, p, fold=fold)
    backward = reference_brdf_inplane(theta_i, -theta, p)
    return weight * forward + (1.0 - weight) * backward


def params_from_unit_scale(unit_vector, reference):
    """Params = reference × unit_vector: a well-scaled coordinate for finite differences.

    In paper units a2 ~ 1e-11 and a3 ~ 1e-12, so a finite-difference step must be relative.
    """
    return type(reference)(*(unit_vector * jnp.asarray(reference)))


def lya_scene_file(folder, name: str, rows_from=None) -> str:
    """The bundled scene named ``name``, of the rows in ``rows_from`` (another measurements
    CSV; default the bundled rows)."""
    from brdf_infer.scene import load_scene

    path = folder / f"{name}.toml"
    path.write_text(lya_scene_text(rows_from or load_scene("lya").measurements_path, name))
    return str(path)


def scaled_rows(folder, factor: float):
    """The bundled rows with every reflectance (and its σ) multiplied by ``factor``."""
    from brdf_infer.scene import load_scene

    lines = load_scene("lya").measurements_path.read_text().splitlines()
    header = lines[0].split(",")
    value, error = header.index("reflectance"), header.index("reflectance_err")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for k in (value, error):
            if cells[k]:
                cells[k] = f"{float(cells[k]) * factor:.6e}"
        out.append(",".join(cells))
    path = folder / f"rows_{factor:g}.csv"
    path.write_text("\n".join(out) + "\n")
    return path


def fewer_rows(folder, name: str, factor: float = 1.0):
    """The bundled rows without samples 5 and 6 and without series II above θi = 50° (23 of
    42 rows, 5 of 7 samples, 1 of 3 rotation settings), each reflectance × ``factor``."""
    lines = scaled_rows(folder, factor).read_text().splitlines()
    header = lines[0].split(",")
    series, sample, theta_i = (header.index(k) for k in ("series", "sample", "theta_i_deg"))
    kept = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        if cells[sample] in ("5", "6") or (cells[series] == "II" and float(cells[theta_i]) > 50):
            continue
        kept.append(line)
    path = folder / f"{name}.csv"
    path.write_text("\n".join(kept) + "\n")
    return path


def run_cli(*argv: str, capsys) -> tuple[int, str, str]:
    """Run ``brdf-infer ARGV`` in-process; returns (exit code, stdout, stderr)."""
    try:
        code = main(list(argv))
    except SystemExit as exit_:  # argparse usage errors
        code = exit_.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def run_cli_process(*argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m brdf_infer ARGV`` as a separate process."""
    return subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def run_on_forced_cpu_devices(
    script: str, argument: Path, devices: int, timeout: int = 900
) -> None:
    """Run ``python -c script argument`` in a fresh process whose JAX sees ``devices`` CPU
    devices (``--xla_force_host_platform_device_count``); fails the test on a non-zero exit."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    done = subprocess.run(
        [sys.executable, "-c", script, str(argument)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-2000:]


def record_mismatches(value, record_type, path: str = "") -> list[str]:
    """Where a JSON value departs from a typed record (``TypedDict``, nested; the records of
    ``brdf_infer.posterior``): a required key missing, a key not declared, a value of another
    type (``float`` takes an int, not a bool)."""
    import types
    import typing

    origin, args = typing.get_origin(record_type), typing.get_args(record_type)
    if typing.is_typeddict(record_type):
        if not isinstance(value, dict):
            return [f"{path}: not an object"]
        hints = typing.get_type_hints(record_type)
        found = [f"{path}.{key}: missing" for key in record_type.__required_keys__ - set(value)]
        found += [f"{path}.{key}: not declared" for key in value if key not in hints]
        for key, item in value.items():
            if key in hints:
                found += record_mismatches(item, hints[key], f"{path}.{key}")
        return found
    if origin in (typing.Union, types.UnionType):
        results = [record_mismatches(value, arg, path) for arg in args]
        return [] if any(not r for r in results) else results[0]
    if record_type is typing.Any:
        return []
    if record_type is type(None):
        return [] if value is None else [f"{path}: not null"]
    if record_type is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return [] if ok else [f"{path}: not a number"]
    if record_type in (int, str, bool):
        ok = isinstance(value, record_type) and (record_type is bool or not isinstance(value, bool))
        return [] if ok else [f"{path}: not {record_type.__name__}"]
    if (origin or record_type) is list:
        if not isinstance(value, list):
            return [f"{path}: not a list"]
        return [m for item in value for m in record_mismatches(item, args[0], path)] if args else []
    if (origin or record_type) is dict:
        if not isinstance(value, dict):
            return [f"{path}: not an object"]
        return [m for k, v in value.items() for m in record_mismatches(v, args[1], f"{path}.{k}")]
    raise TypeError(f"{path}: no check for {record_type!r}")


def series_ii_scene_file(folder, errors: str = ""):
    """A scene of series II of the bundled rows alone (18 rows, one physical sample) with
    ``errors`` as its ``[errors]`` lines; its file (``scene.toml`` in ``folder``)."""
    from brdf_infer.scene import load_scene

    lya = load_scene("lya")
    rows = lya.load_measurements()
    lines = ["series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"]
    for k in np.flatnonzero(rows.series == "II"):
        lines.append(
            f"II,{rows.sample[k]},{rows.theta_i_deg[k]:g},{rows.theta_s_deg[k]:g},"
            f"{rows.reflectance[k]:.6e},{rows.reflectance_err[k]:.6e}"
        )
    (folder / "rows.csv").write_text("\n".join(lines) + "\n")
    geometry = lya.series["II"]
    (folder / "scene.toml").write_text(
        'name = "series-ii"\nmeasurements = "rows.csv"\n[series.II]\n'
        f"aperture_diameter_mm = {geometry.aperture_diameter_mm}\n"
        f"aperture_distance_mm = {geometry.aperture_distance_mm}\n[errors]\n{errors}\n"
    )
    return folder / "scene.toml"
