"""The report's table of the ray traces a run wrote (Sec. 6; read by
:func:`brdf_infer.studies.raytrace.load_traces`)."""

from __future__ import annotations

from brdf_infer.report import _html


def raytrace_table(traces: list[dict]) -> str:
    header = ["θi [deg]", "δ [deg]", "measured [-]"]
    for trace in traces:
        header += [f"simulated, {trace['params_source']} [-]", "simulated / measured"]
    header += ["point estimate Eq. (6) [-]", "image ratio [-]"]
    table = []
    for k, row in enumerate(traces[0]["rows"]):
        cells = [f"{row['theta_i_deg']:g}", f"{row['delta_deg']:+g}", f"{row['measured']:.3e}"]
        for trace in traces:
            other = trace["rows"][k]
            text = f"{other['simulated']:.3e} ± {other['mc_se']:.1e}"
            if "band" in other:
                text += f" (95 %: {other['band']['lo95']:.2e}–{other['band']['hi95']:.2e})"
            cells += [text, f"{other['simulated'] / row['measured']:.3f}"]
        cells += [f"{row['point_estimate']:.3e}", f"{row['image_ratio']:.3e}"]
        table.append(cells)
    note = (
        f"<p>{traces[0]['rays']} rays per configuration ({traces[0]['estimator']} estimator). "
        "Simulated = power scattered through the detector aperture over the incident power, "
        "the quantity Eq. (6) converts; image ratio = scattered over reference image summed "
        "over the signal square, as the paper's Eq. (2) processes the CCD images.</p>"
    )
    return note + _html.table(header, table)
