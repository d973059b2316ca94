"""Two fold switches (Eq. 10): what the instrument measured (``[model] fold``, the likelihood)
and what the products describe (``[outputs] fold``: bands, TIS, exports); products default to
the physical, unfolded BRDF whatever the instrument measured, and say what they include.

Hand-checked numbers (2-D adaptive quadrature of the plain-Python model in tests/helpers.py,
tests/test_tis.py): uv-paper's TIS(85°) is 7.8987 % unfolded and 7.4650 % folded, a ratio of
1.0581; TIS(70°) 5.7720 and 5.6927 %, a ratio of 1.0139.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer.model import strumik_family, tis
from brdf_infer.model.params import PAPER_CONSTANTS, UV_PAPER, Params
from brdf_infer.posterior import posterior_bands
from brdf_infer.posterior._results import write_inference_data
from tests import independent_bsdf as oracle
from tests.helpers import run_cli
from tests.test_export import GOOD

COARSE = ["--azimuth-step", "15", "--radial-step", "5"]
UNFOLDED = "Eq. (10) folding: not included (physical BRDF, conservative for stray light)"
FOLDED = "Eq. (10) folding: included"


def json_of(capsys, *argv):
    code, out, err = run_cli(*argv, "--json", capsys=capsys)
    assert code == 0, err
    return json.loads(out)


def _draws_near_uv_paper(count: int = 64) -> Params:
    """uv-paper with a 1 % spread in BRDF0: bands whose median is uv-paper's own TIS."""
    scale = 1.0 + 0.01 * np.linspace(-1.0, 1.0, count)
    return Params(*(np.full(count, value) for value in UV_PAPER))._replace(
        brdf0=UV_PAPER.brdf0 * scale
    )


def test_bands_follow_the_fold_switch_and_say_which():
    """Planted fault: the TIS band folded whatever the scene said (as before issue 22)."""
    draws = _draws_near_uv_paper()
    physical = draws._asdict()
    plain = posterior_bands(strumik_family(False, PAPER_CONSTANTS), physical, [45.0])
    folded = posterior_bands(strumik_family(True, PAPER_CONSTANTS), physical, [45.0])
    assert plain["fold"] is False and folded["fold"] is True
    at = plain["tis"]["theta_i_deg"].index(85.0)
    assert 100 * plain["tis"]["median"][at] == pytest.approx(7.8987, abs=5e-4)
    assert 100 * folded["tis"]["median"][at] == pytest.approx(7.4650, abs=5e-4)
    # the in-plane BRDF band follows the same switch: at θs = 88° it is folded by 0.31031
    s = plain["brdf_inplane"]["theta_s_deg"].index(88.0)
    ratio = folded["brdf_inplane"]["median"][0][s] / plain["brdf_inplane"]["median"][0][s]
    assert ratio == pytest.approx(0.31031, rel=1e-4)


def test_a_run_is_unfolded_by_default_and_says_so(nuts_run, capsys):
    """The lya scene leaves [model] fold at false: bands.json, summary.json and ``tis --run``
    are of the physical BRDF. The fold removes forward scatter beyond ≈ 84° only: the run's
    median TIS(85°) is above the folded one by 4.5 % (measured on the default 4 × 1000-draw
    run: 8.130 vs 7.782 %; uv-paper: 5.8 %), TIS(70°) by 1.6 % (6.510 vs 6.406 %; uv-paper:
    1.4 %); asserted > 3 % and > 1 %, far above the Monte Carlo noise of a median ratio."""
    bands = json.loads((nuts_run.out / "bands.json").read_text())
    summary = json.loads((nuts_run.out / "summary.json").read_text())
    assert bands["fold"] is False and summary["fold"] is False
    argv = ["tis", "--run", str(nuts_run.out), "--theta-i", "70", "85"]
    default, folded = json_of(capsys, *argv), json_of(capsys, *argv, "--fold")
    assert default["fold"] is False and folded["fold"] is True
    for key in ("median", "lo95", "hi95"):
        for k, angle in enumerate((70.0, 85.0)):
            at = bands["tis"]["theta_i_deg"].index(angle)
            assert default[key][k] == pytest.approx(bands["tis"][key][at], rel=1e-12)
    excess = np.array(default["median"]) / np.array(folded["median"]) - 1.0
    assert excess[0] > 0.01 and excess[1] > 0.03
    assert summary["tis_70deg"]["median"] == pytest.approx(default["median"][0], rel=1e-12)
    code, out, _ = run_cli("tis", "--run", str(nuts_run.out), "--theta-i", "85", capsys=capsys)
    assert code == 0 and UNFOLDED in out


def _run_with_attributes(nuts_run, folder: Path, **attributes) -> Path:
    """A copy of the suite's run folder whose posterior.nc carries ``attributes``."""
    idata = az.from_netcdf(nuts_run.out / "posterior.nc")
    idata.posterior.attrs.update(attributes)
    folder.mkdir()
    write_inference_data(idata, folder / "posterior.nc")
    (folder / "summary.json").write_text((nuts_run.out / "summary.json").read_text())
    return folder


def test_an_instrument_that_folds_leaves_the_products_physical(nuts_run, tmp_path, capsys):
    """A run whose likelihood folded ([model] fold = true: the instrument's readings fold near
    grazing) but whose products follow [outputs] fold = false: ``tis --run`` is of the physical
    BRDF, the run's own band; a run written before the two switches (no ``products_fold``)
    folded both, and still reads so."""
    run = _run_with_attributes(nuts_run, tmp_path / "instrument", fold=1, products_fold=0)
    argv = ["tis", "--run", str(run), "--theta-i", "85"]
    assert json_of(capsys, *argv)["fold"] is False
    older = _run_with_attributes(nuts_run, tmp_path / "older", fold=1)
    idata = az.from_netcdf(older / "posterior.nc")
    del idata.posterior.attrs["products_fold"]
    write_inference_data(idata, older / "posterior.nc")
    assert json_of(capsys, "tis", "--run", str(older), "--theta-i", "85")["fold"] is True


def test_a_run_whose_scene_folds_gives_folded_products(nuts_run, tmp_path, capsys):
    """The run's own products switch (its scene's [outputs] fold, stored with the draws) is
    what ``tis --run`` and ``export --run`` follow; ``--no-fold`` overrides it. Each draw's TIS
    with its own out-of-plane width."""
    run = _run_with_attributes(nuts_run, tmp_path / "folded_run", products_fold=1)
    idata = az.from_netcdf(run / "posterior.nc")
    physical = {
        name: np.asarray(idata.posterior[name]).reshape(-1)
        for name in strumik_family(dphi_free=True).parameters
    }
    argv = ["tis", "--run", str(run), "--theta-i", "85"]
    folded, plain = json_of(capsys, *argv), json_of(capsys, *argv, "--no-fold")
    assert folded["fold"] is True and plain["fold"] is False
    member = strumik_family(True, dphi_free=True)
    expected = np.median(np.exp(np.asarray(member.log_tis_draws(np.array([85.0]), physical))))
    assert folded["median"][0] == pytest.approx(expected, rel=1e-12)
    payload = json_of(
        capsys,
        "export",
        "--run",
        str(run),
        "--theta-i",
        "85",
        *COARSE,
        "--out",
        str(tmp_path / "x"),
    )
    assert payload["fold"] is True
    assert FOLDED in "\n".join(oracle.read_bsdf(payload["files"][1]["path"])["comments"])
    entry = json.loads((run / "exports.json").read_text())["exports"][0]
    assert entry["fold"] is True


@pytest.mark.parametrize("fold", [False, True])
def test_bsdf_export_says_whether_it_folds_and_that_it_is_no_measurement(tmp_path, capsys, fold):
    flags = ["--fold"] if fold else []
    argv = ["--params", "uv-paper", "--theta-i", "70", "85", *COARSE, "--out", str(tmp_path)]
    payload = json_of(capsys, "export", *argv, *flags)
    assert payload["fold"] is fold
    path = payload["files"][0]["path"]
    contents = oracle.read_bsdf(path)  # the independent reader still reads the file
    comments = contents["comments"]
    assert (FOLDED if fold else UNFOLDED) in "\n".join(comments)
    assert (UNFOLDED if fold else FOLDED) not in "\n".join(comments)
    assert any(line.startswith("not measured: the model above evaluated") for line in comments)
    model = next(line for line in comments if line.startswith("model:"))
    assert ("(10)" in model) is fold  # the model line names Eq. (10) only when folded
    first = next(line for line in Path(path).read_text().splitlines() if not line.startswith("#"))
    assert first == "Source Measured"  # the only Source value the format defines
    np.testing.assert_allclose(
        contents["tis"][0], np.asarray(tis(np.array([70.0, 85.0]), UV_PAPER, fold)), rtol=1e-10
    )
    code, out, _ = run_cli("export", "--check", path, "--json", capsys=capsys)
    assert code == 0 and json.loads(out)["tis"] == contents["tis"].tolist()


@pytest.mark.full
def test_abg_export_says_whether_it_folds(tmp_path, capsys):
    argv = ["--params", "uv-paper", "--format", "abg", "--theta-i", "0", "40", "80"]
    payload = json_of(capsys, "export", *argv, "--fold", "--out", str(tmp_path))
    stored = json.loads((tmp_path / "abg.json").read_text())
    assert payload["fold"] is True and stored["fold"] is True and FOLDED in stored["folding"]
    folded = np.asarray(tis(np.array([0.0, 40.0, 80.0]), UV_PAPER, True))
    np.testing.assert_allclose([r["tis_model"] for r in stored["rows"]], folded, rtol=1e-12)


def _fake_lambertian_run(folder):
    """A run folder of ``lambertian`` written by hand (no Eq. 10 in that family)."""
    folder.mkdir(parents=True)
    idata = az.from_dict(posterior={"tis": np.linspace(0.02, 0.03, 20).reshape(2, -1)})
    idata.posterior.attrs.update(
        {"model": "lambertian", "constants": json.dumps(PAPER_CONSTANTS._asdict())}
    )
    idata.to_netcdf(folder / "posterior.nc")
    (folder / "summary.json").write_text(json.dumps({"scene": "lya"}))
    return folder


def test_another_family_has_no_eq10_to_fold(tmp_path, capsys):
    run = _fake_lambertian_run(tmp_path / "lambertian")
    out = tmp_path / "out"
    for argv in (["tis", "--run", str(run)], ["export", "--run", str(run), "--out", str(out)]):
        code, stdout, err = run_cli(*argv, "--fold", capsys=capsys)
        assert code == 2 and stdout == "" and "has no Eq. (10)" in err and "--fold" in err, err
    assert not out.exists()
    payload = json_of(capsys, "tis", "--run", str(run), "--theta-i", "30", "--no-fold")
    assert payload["fold"] is False and payload["model"] == "lambertian"


@pytest.mark.parametrize("source", ["Source Measured", "Source  Measured", "Source Analytic"])
def test_check_reads_other_tools_files_whatever_their_source_says(tmp_path, capsys, source):
    """Our files write the one value the format defines; ``export --check`` reads any (a tool
    may write another value or two spaces, as some converters do)."""
    path = tmp_path / "theirs.bsdf"
    path.write_text(GOOD.replace("Source Measured", source))
    payload = json_of(capsys, "export", "--check", str(path))
    assert payload["tis"] == [[0.31830989]]


@pytest.mark.parametrize("command", ["run", "posterior"])
def test_a_runs_two_fold_switches_each_override_their_own_scene_key(command):
    """``--fold`` sets the products' switch ([outputs] fold) alone, ``--likelihood-fold`` the
    instrument's ([model] fold) alone; neither leaves the scene's keys as they are."""
    from brdf_infer.cli import build_parser
    from brdf_infer.cli._options import with_product_switches
    from brdf_infer.scene import load_scene

    scene = load_scene("lya")
    assert (scene.model.fold, scene.outputs.fold) == (False, False)
    parse = build_parser().parse_args
    products = with_product_switches(scene, parse([command, "lya", "--fold"]))
    assert (products.model.fold, products.outputs.fold) == (False, True)
    likelihood = with_product_switches(scene, parse([command, "lya", "--likelihood-fold"]))
    assert (likelihood.model.fold, likelihood.outputs.fold) == (True, False)
    assert with_product_switches(scene, parse([command, "lya"])) == scene
    with pytest.raises(SystemExit):
        parse([command, "lya", "--fold", "--no-fold"])
