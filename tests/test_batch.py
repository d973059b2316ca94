"""``brdf-infer batch``: one compiled program per model structure, run folders as ``posterior``
writes them, the scene axis sharded over devices with the same results as on one."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._arviz import az
from tests.helpers import run_cli, run_on_forced_cpu_devices

SMALL = ["--chains", "2", "--draws", "150", "--warmup", "150"]


def _scene(folder, name: str, rows_from=None) -> str:
    """A scene of the bundled rows (``rows_from``: another measurements CSV)."""
    from brdf_infer.scene import load_scene

    lya = load_scene("lya")
    csv = rows_from or lya.measurements_path
    path = folder / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\nmeasurements = "{csv.as_posix()}"\n'
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
        "[series.II]\naperture_diameter_mm = 7.5\naperture_distance_mm = 106.0\n"
    )
    return str(path)


def _scaled_rows(folder, factor: float):
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


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    """Two scenes of one structure (different data), one of fewer rows, and a broken one."""
    folder = tmp_path_factory.mktemp("batch")
    scenes = [
        _scene(folder, "a"),
        _scene(folder, "b", _scaled_rows(folder, 1.3)),
    ]
    (folder / "broken.toml").write_text(
        'name = "broken"\nmeasurements = "nowhere.csv"\n'
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
    )
    out = folder / "out"
    from brdf_infer.cli import main

    code = main(["batch", *scenes, str(folder / "broken.toml"), *SMALL, "--out", str(out)])
    assert code == 0
    return folder, out, json.loads((out / "batch.json").read_text())


def test_batch_json_contract_and_a_broken_scene_is_skipped(batch_run):
    _, out, payload = batch_run
    assert set(payload) >= {"scenes", "groups", "devices", "seconds"}
    assert payload["groups"] == 1 and payload["devices"] >= 1
    by_name = {Path(entry["source"]).stem: entry for entry in payload["scenes"]}
    assert set(by_name) == {"a", "b", "broken"}
    assert by_name["a"]["scene"] == "a"  # a scene that could not be read keeps its source
    broken = by_name["broken"]
    assert broken["error"] and "nowhere.csv" in broken["error"] and broken["out"] is None
    for name in ("a", "b"):
        entry = by_name[name]
        assert entry["error"] is None
        assert set(entry) >= {"out", "r_hat_max", "ess_min", "divergences", "tis"}
        assert set(entry["tis"]) == {"theta_i_deg", "median", "lo95", "hi95"}
        assert (out / name / "posterior.nc").is_file() and (out / name / "summary.json").is_file()
    # different data, different posteriors: b's rows are 1.3 × a's
    a, b = by_name["a"]["tis"], by_name["b"]["tis"]
    ratio = np.array(b["median"][20:80]) / np.array(a["median"][20:80])
    np.testing.assert_allclose(ratio, 1.3, rtol=0.1)


def test_a_batch_scene_has_the_draws_of_its_own_posterior_run(batch_run, tmp_path, capsys):
    folder, out, _ = batch_run
    single = tmp_path / "single"
    code, _, err = run_cli(
        "posterior", str(folder / "b.toml"), *SMALL, "--out", str(single), capsys=capsys
    )
    assert code == 0, err
    ours = az.from_netcdf(out / "b" / "posterior.nc").posterior
    theirs = az.from_netcdf(single / "posterior.nc").posterior
    for name in ("brdf0", "alpha", "theta_s0", "repeatability"):
        np.testing.assert_array_equal(np.asarray(ours[name]), np.asarray(theirs[name]))


def test_readers_of_run_folders_take_a_batch_scene(batch_run, capsys):
    _, out, payload = batch_run
    code, text, err = run_cli(
        "tis", "--run", str(out / "a"), "--theta-i", "70", "--json", capsys=capsys
    )
    assert code == 0, err
    entry = next(e for e in payload["scenes"] if e["scene"] == "a")
    at = entry["tis"]["theta_i_deg"].index(70.0)
    assert json.loads(text)["median"][0] == pytest.approx(entry["tis"]["median"][at], rel=1e-12)


def test_batch_of_only_broken_scenes_is_one_error_line(tmp_path, capsys):
    (tmp_path / "x.toml").write_text('name = "x"\n')
    code, out, err = run_cli(
        "batch", str(tmp_path / "x.toml"), "--out", str(tmp_path / "o"), capsys=capsys
    )
    assert code == 2 and out == "" and "no scene could be run" in err
    assert "Traceback" not in err and not (tmp_path / "o").exists()


_SHARDED = textwrap.dedent(
    """
    import sys
    import jax, numpy as np
    from brdf_infer.scene import load_scene
    from brdf_infer.posterior import NutsProgram, build_posterior_model, chain_keys
    from brdf_infer.posterior._nuts import stack_data
    scene = load_scene("lya")
    model = build_posterior_model(scene, scene.load_measurements())
    rows = model.data.rows
    datasets = stack_data([
        model.data._replace(rows=rows._replace(log_reflectance=rows.log_reflectance + shift))
        for shift in (0.0, 0.2, -0.1)
    ])
    program = NutsProgram(model, warmup=6)
    keys = np.stack([chain_keys(k, 1, 2)[0] for k in range(3)])
    output = program.run_many(datasets, keys, 4, mode="vmap")
    np.savez(sys.argv[1], devices=jax.device_count(), **output.sites)
    """
)


def test_sharded_over_two_forced_cpu_devices_gives_the_results_of_one(tmp_path):
    """Three data sets (padded to four) over two devices against one device: the same keys,
    the same draws to rounding. Only to rounding: the partitioned program is compiled apart,
    and a NUTS trajectory amplifies a last-bit difference, so over hundreds of iterations
    the chains of the two separate as under any change of compiler or hardware."""
    results = {}
    for count in (1, 2):
        target = tmp_path / f"draws_{count}.npz"
        run_on_forced_cpu_devices(_SHARDED, target, count)
        results[count] = dict(np.load(target))
        assert int(results[count]["devices"]) == count
    one, two = results[1], results[2]
    assert one["brdf0"].shape == two["brdf0"].shape == (3, 2, 4)
    for name in ("brdf0", "alpha", "a1", "theta_s0", "repeatability"):
        # measured: 1.2e-9 at most after these 10 iterations (last-bit differences, amplified)
        np.testing.assert_allclose(two[name], one[name], rtol=1e-7, atol=0)
    assert not np.allclose(one["brdf0"][0], one["brdf0"][1])  # the data sets differ


def test_vmapped_batch_of_one_scene(tmp_path, capsys):
    """``--mode vmap`` with a single scene (the path every accelerator takes): its one data
    set keeps one data-set axis (a batch of one failed on a GPU before)."""
    out = tmp_path / "out"
    code, _, err = run_cli(
        "batch",
        _scene(tmp_path, "only"),
        *SMALL,
        "--mode",
        "vmap",
        "--out",
        str(out),
        capsys=capsys,
    )
    assert code == 0, err
    entry = json.loads((out / "batch.json").read_text())["scenes"][0]
    assert entry["error"] is None and entry["divergences"] == 0
    assert np.isfinite(entry["r_hat_max"]) and len(entry["tis"]["median"]) > 0
