"""The HTML report: self-contained, every image decodes, and a verdict that tells the truth."""

import base64
import html
import io
import json
from html.parser import HTMLParser

import matplotlib.image
import pytest

from brdf_infer.posterior import run_posterior
from brdf_infer.report import write_report
from tests.helpers import run_cli


class _Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.links, self.classes, self.headings, self._heading = [], [], [], [], False

    def handle_starttag(self, tag, attrs):
        attributes = dict(attrs)
        if tag == "img":
            self.images.append(attributes.get("src", ""))
        for key in ("href", "src"):
            if key in attributes and tag != "img":
                self.links.append(attributes[key])
        if "class" in attributes:
            self.classes.append(attributes["class"])
        self._heading = tag in ("h1", "h2", "h3")

    def handle_data(self, data):
        if self._heading:
            self.headings.append(data)
            self._heading = False


def parse(path):
    collector = _Collector()
    collector.feed(path.read_text())
    return collector


@pytest.fixture(scope="module")
def good_report(nuts_run, lya):
    """The report of the reduced run, with ray traces as ``brdf-infer run`` writes them."""
    from brdf_infer.model.params import UV_PAPER
    from brdf_infer.posterior import draws_params
    from brdf_infer.studies.raytrace import (
        raytrace_payload,
        raytrace_posterior_payload,
        thin_draws,
        write_traces,
    )

    draws = thin_draws(draws_params(nuts_run.idata.posterior), 8)
    traces = [
        raytrace_posterior_payload(*lya, draws, "posterior", rays=2048),
        raytrace_payload(*lya, UV_PAPER, "uv-paper", rays=2**14),
    ]
    write_traces(nuts_run.out, *lya, traces)
    return write_report(nuts_run.out, progress=lambda message: None)


def test_report_is_self_contained_and_every_image_decodes(good_report, nuts_run):
    path, _ = good_report
    page = parse(path)
    assert len(page.images) >= 9
    for source in page.images:
        assert source.startswith("data:image/png;base64,"), source[:40]
        pixels = matplotlib.image.imread(
            io.BytesIO(base64.b64decode(source.split(",", 1)[1])), format="png"
        )
        assert pixels.shape[0] > 100 and pixels.shape[1] > 100
    assert page.links == []  # nothing to fetch
    for png in (
        "trace",
        "rank",
        "pair",
        "energy",
        "predictive",
        "loo_pit",
        "pareto_k",
        "brdf_bands",
        "tis_band",
        "hemisphere",
        "raytrace",
        "detector_images",
    ):
        assert (nuts_run.out / "figures" / f"{png}.png").stat().st_size > 5000, png


def test_report_opens_with_the_verdict_then_the_sections(good_report, nuts_run):
    path, verdict = good_report
    page = parse(path)
    assert page.classes[0] == ("verdict pass" if verdict.ok else "verdict fail")
    # the verdict the run recorded, rendered as it stands (reduced settings: a Pareto k may
    # cross 0.7, row 45°/60°)
    assert verdict.as_json() == nuts_run.summary["verdict"]
    assert f"Verdict: {html.escape(verdict.text)}</strong>" in path.read_text()
    text = path.read_text()
    order = [
        text.index(h)
        for h in (
            "Verdict",
            '<div class="result">',
            "TIS(θi = 18°)",
            "TIS(θi = 70°)",  # the article's angle, as on stdout, though no row has θi = 70°
            "π·BRDF0 (near-normal",  # (the verdict's facts may name π·BRDF0 before)
            "In-plane BRDF at the scene",
            "The run",
            "ArviZ summary",
            "Diagnostics",
            "Fit against the data",
            "Error model",
            "Products",
            "Ray-tracing validation",
        )
    ]
    assert order == sorted(order)
    assert "R-hat ≤ 1.01" in text and "Pareto k" in text and "TIS [%]" in text
    assert "b2 = a2·90^(1+α)" in text  # the priors table names each prior's coordinate


def test_report_says_its_tis_is_of_the_physical_brdf(good_report):
    """The lya scene leaves [model] fold at false: right under the result, in the run table,
    the TIS and hemisphere captions and the TIS table the report says Eq. (10) is left out."""
    from brdf_infer.model import fold_statement

    text = good_report[0].read_text()
    statement = html.escape(fold_statement(False))
    under_result = text.index(statement, text.index('<div class="result">'))
    assert under_result < text.index("In-plane BRDF at the scene")
    assert text.count(statement) >= 5 and "Eq. (10) folding: included" not in text


def test_only_a_scene_compared_with_the_article_names_its_table_3():
    """The line under the result says how to include Eq. (10); the article's Table 3 is named
    only for a scene drawn beside the article's parameters (the bundled ones), not for yours."""
    from brdf_infer.report._results import fold_note

    bands = {"fold": False}
    assert "article&#x27;s Table 3 includes it" in fold_note(bands, article=True)
    mine = fold_note(bands, article=False)
    assert "Table 3" not in mine and "article" not in mine
    assert "to include it, set [model] fold = true" in mine


def test_a_scene_without_a_reference_draws_no_reference(lya, tmp_path):
    """Captions and legends describe what is drawn: no reference curve, no reference words."""
    import dataclasses

    from brdf_infer.report._figures import brdf_bands

    scene, measurements = lya
    bare = dataclasses.replace(
        scene, outputs=dataclasses.replace(scene.outputs, reference_params=None)
    )
    bands = {"brdf_inplane": json.loads(json.dumps(_tiny_band()))}
    figure = brdf_bands(bands, bare, measurements)
    labels = [t.get_text() for t in figure.axes[0].get_legend().get_texts()]
    assert not any("reference" in label or "paper" in label for label in labels), labels


def _tiny_band() -> dict:
    import numpy as np

    theta_s = list(np.arange(-90.0, 90.5, 1.0))
    values = [[0.01] * len(theta_s)]
    return {
        "theta_i_deg": [45.0],
        "theta_s_deg": theta_s,
        **{k: values for k in ("median", "lo68", "hi68", "lo95", "hi95")},
    }


@pytest.mark.full
def test_deliberately_bad_run_lists_its_failures(lya, tmp_path, capsys):
    # warmup as in the shared reduced run, so its compiled program is reused; 20 draws fail;
    # no refits of the error-model variants (20 draws: every k̂ > 0.7, three more samplers)
    run_posterior(*lya, chains=1, warmup=500, draws=20, out=tmp_path, progress=False, refit=False)
    code, out, err = run_cli("report", str(tmp_path), "--json", capsys=capsys)
    assert code == 0, err
    verdict = json.loads(out)["verdict"]
    assert not verdict["ok"] and any("ESS" in line for line in verdict["lines"]), verdict
    assert verdict["text"].startswith("; ".join(verdict["lines"]))  # then the facts, if any
    page = parse(tmp_path / "report.html")
    assert page.classes[0] == "verdict fail"
    assert "do not trust" in (tmp_path / "report.html").read_text()


@pytest.mark.full
@pytest.mark.usefixtures("width_refit_off")  # 20 draws: every variant's k̂ > 0.7
def test_a_run_started_with_a_relative_scene_path_is_read_from_any_directory(
    tmp_path, capsys, monkeypatch
):
    """``posterior`` started in the scene's folder with a relative path; ``report RUN_DIR``
    and ``tis --run RUN_DIR`` from another working directory (the run names its scene file
    by an absolute path)."""
    import shutil

    from brdf_infer.scene import scene_file

    data = tmp_path / "data"
    data.mkdir()
    for name in ("lya.scene.toml", "lya_measurements.csv", "lya_tis_reference.csv"):
        shutil.copy(scene_file("lya").parent / name, data / name)
    monkeypatch.chdir(data)
    # chains and warmup as in the deliberately bad run above: its compiled program is reused
    argv = ["--chains", "1", "--warmup", "500", "--draws", "20", "--out", "run"]
    code, _, err = run_cli("posterior", "lya.scene.toml", *argv, capsys=capsys)
    assert code == 0, err
    scene_path = data / "lya.scene.toml"  # edited after the run: the report is of the run's
    scene_path.write_text(
        scene_path.read_text().replace('description = "', 'description = "EDITED LATER ', 1)
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    run = data / "run"
    code, out, err = run_cli("report", str(run), capsys=capsys)
    assert code == 0, err
    assert out.startswith("verdict: ") and (run / "report.html").is_file()
    page = (run / "report.html").read_text()
    assert "Acktar Magic Black" in page and "EDITED LATER" not in page
    code, out, err = run_cli("tis", "--run", str(run), "--theta-i", "70", "--json", capsys=capsys)
    assert code == 0, err
    assert 0 < json.loads(out)["median"][0] < 1
    assert not list(elsewhere.iterdir())  # nothing written where the readers ran


def test_report_of_a_folder_without_a_run_is_a_clear_error(tmp_path, capsys):
    code, out, err = run_cli("report", str(tmp_path), capsys=capsys)
    assert code == 2 and out == "" and "no posterior.nc here" in err


def test_report_shows_the_exports_of_its_run(nuts_run, tmp_path, capsys):
    """A copy of the reduced run, exported as .BSDF and ABg, gets an Export section with the
    table plot and the ABg table."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(nuts_run.out, run)
    (run / "exports.json").unlink(missing_ok=True)  # exports other tests made of the shared run
    for argv in (
        ["--theta-i", "0", "30", "60", "80", "--azimuth-step", "15", "--radial-step", "5"],
        ["--format", "abg", "--theta-i", "20", "70", "--draws", "2"],
    ):
        out = tmp_path / argv[1]
        code, _, err = run_cli("export", "--run", str(run), *argv, "--out", str(out), capsys=capsys)
        assert code == 0, err
    entries = json.loads((run / "exports.json").read_text())["exports"]
    assert [e["format"] for e in entries] == ["zemax-bsdf", "abg"]
    write_report(run, progress=lambda message: None)
    text = (run / "report.html").read_text()
    assert "<h2>Export</h2>" in text and "rms ln error" in text
    export = text[text.index("<h2>Export</h2>") :]
    assert export.count("Eq. (10) folding: not included (physical BRDF") >= 3  # entries, plot
    assert (run / "figures" / "export.png").stat().st_size > 0


def test_report_shows_a_model_comparison_written_into_its_run(nuts_run, tmp_path):
    """``compare --out RUN`` leaves compare.json in the run; the report then has a model
    comparison section with the table (best first) and the figure."""
    import shutil

    from brdf_infer.studies.compare import COMPARE_FILE

    run = tmp_path / "run"
    shutil.copytree(nuts_run.out, run)
    band = {"median": 0.06, "lo95": 0.05, "hi95": 0.07}
    models = [
        {"name": "strumik2024", "elpd_loo": 33.8, "se": 5.4, "d_elpd": 0.0, "dse": 0.0},
        {"name": "abg", "elpd_loo": -114.8, "se": 7.7, "d_elpd": 148.6, "dse": 9.8},
    ]
    for model, weight in zip(models, (1.0, 0.0), strict=True):
        model.update(
            weight=weight, p_loo=6.0, pareto_k_max=0.4, pareto_k_max_after_refit=0.4, tis70=band
        )
    # the case: a ranked family with R-hat 1.04 and ESS 124
    models[0].update(
        r_hat_max=1.002, ess_bulk_min=1800.0, divergences=0, sampler_ok=True, sampler_failures=[]
    )
    failures = ["R-hat 1.040 > 1.01", "bulk ESS 124 < 400"]
    models[1].update(
        r_hat_max=1.04,
        ess_bulk_min=124.0,
        divergences=0,
        sampler_ok=False,
        sampler_failures=failures,
    )
    (run / COMPARE_FILE).write_text(json.dumps({"models": models, "seconds": 1.0}))
    write_report(run, progress=lambda message: None)
    text = (run / "report.html").read_text()
    assert "<h2>Model comparison (PSIS-LOO)</h2>" in text
    assert "Best: <b>strumik2024</b>" in text and "148.6 ± 9.8" in text
    assert text.index("<td>strumik2024</td>") < text.index("<td>abg</td>")
    assert "<td>1.040</td><td>124</td>" in text and "<td>1.002</td><td>1800</td>" in text
    assert text.count("rank not to be trusted") == 1
    assert "R-hat 1.040 &gt; 1.01, bulk ESS 124 &lt; 400" in text


def test_report_draws_the_pareto_k_its_run_recorded_and_computes_none(nuts_run, tmp_path):
    """The run records every row's Pareto k (equal to ArviZ's PSIS-LOO recomputed here); the
    report reads it, and a run written before it was recorded is reported without the figure."""
    import shutil

    import numpy as np

    from brdf_infer._internal import arviz as az
    from brdf_infer.verdict import PARETO_K_LIMIT

    loo = nuts_run.summary["predictive"]
    k = np.asarray(az.loo(nuts_run.idata, pointwise=True).pareto_k)
    assert loo["pareto_k"] == pytest.approx(k.tolist(), rel=1e-12)
    assert loo["pareto_k_high"] == int(np.sum(k > PARETO_K_LIMIT))
    run = tmp_path / "run"
    shutil.copytree(nuts_run.out, run, ignore=shutil.ignore_patterns("figures", "report.html"))
    summary = json.loads((run / "summary.json").read_text())
    del summary["predictive"]["pareto_k"]
    (run / "summary.json").write_text(json.dumps(summary))
    write_report(run, progress=lambda message: None)
    text = (run / "report.html").read_text()
    assert f"{loo['elpd_loo']:.2f} ± {loo['se']:.2f}" in text
    assert not (run / "figures" / "pareto_k.png").exists()


@pytest.mark.full
@pytest.mark.parametrize("models", [1, 2])
def test_the_loo_pit_figure_keeps_its_titles_inside(models):
    """The title over one panel (the run alone) wraps instead of running off the figure."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from brdf_infer.report._noise import loo_pit_comparison

    rng = np.random.default_rng(0)
    pits = {name: (rng.uniform(size=42), 0.5) for name in ["generative", "spread"][:models]}
    figure = loo_pit_comparison(pits)
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer = canvas.get_renderer()
    titles = [*figure.texts, *(axis.title for axis in figure.axes)]
    assert any("calibration" in text.get_text() for text in titles)
    for text in titles:
        box = text.get_window_extent(renderer)
        assert box.x0 >= 0 and box.x1 <= figure.bbox.width, text.get_text()
