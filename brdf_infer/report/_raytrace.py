"""Figures of the ray-tracing validation (Figs. 13 and 14 of the paper); matplotlib only."""

from __future__ import annotations

import io

import matplotlib.pyplot as plt
import numpy as np

_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def png_options(dpi: int = 90) -> dict:
    """``savefig``'s keywords for a figure's PNG: zlib level 3 (a third faster to write than
    the default 6, 8 % larger)."""
    return {"format": "png", "dpi": dpi, "pil_kwargs": {"compress_level": 3}}


def figure_png(figure, dpi: int = 90) -> bytes:
    """The figure as PNG bytes (:func:`png_options`); closes it."""
    buffer = io.BytesIO()
    figure.savefig(buffer, **png_options(dpi))
    plt.close(figure)
    return buffer.getvalue()


def plot_raytrace(payloads: list[dict]) -> plt.Figure:
    """Measured against simulated raw reflectance per θi (like Fig. 14).

    Args:
        payloads: ``brdf-infer raytrace --json`` objects; the first one's measured values are
            drawn (circles with 1σ bars), every payload's simulated dPs/Pi (crosses, or a 95 %
            band where it has posterior draws), the first one's Eq. (6) point estimate and the
            image ratio of Eq. (2).
    """
    figure, (top, bottom) = plt.subplots(
        2, 1, figsize=(8, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]}
    )
    first = payloads[0]["rows"]
    angles = sorted({row["theta_i_deg"] for row in first})
    colour = dict(zip(angles, _COLOURS, strict=False))
    for theta_i in angles:
        rows = [row for row in first if row["theta_i_deg"] == theta_i]
        theta_s = np.array([row["theta_s_deg"] for row in rows])
        top.errorbar(
            theta_s,
            [row["measured"] for row in rows],
            yerr=[row["measured_err"] for row in rows],
            fmt="o",
            mfc="none",
            color=colour[theta_i],
            label=f"measured, θi = {theta_i:g}°",
        )
    markers = iter("x+1")
    for payload in payloads:
        marker = next(markers)
        for theta_i in angles:
            rows = [row for row in payload["rows"] if row["theta_i_deg"] == theta_i]
            theta_s = np.array([row["theta_s_deg"] for row in rows])
            simulated = np.array([row["simulated"] for row in rows])
            if "band" in rows[0]:
                low = np.array([row["band"]["lo95"] for row in rows])
                high = np.array([row["band"]["hi95"] for row in rows])
                top.fill_between(theta_s, low, high, color=colour[theta_i], alpha=0.2, lw=0)
            top.plot(theta_s, simulated, marker, color=colour[theta_i], ms=8, ls="")
            measured = np.array([row["measured"] for row in rows])
            bottom.plot(theta_s, simulated / measured, marker, color=colour[theta_i], ms=7, ls="")
        top.plot([], [], marker, color="k", ls="", label=f"simulated, {payload['params_source']}")
    for theta_i in angles:
        rows = [row for row in first if row["theta_i_deg"] == theta_i]
        theta_s = [row["theta_s_deg"] for row in rows]
        top.plot(theta_s, [row["point_estimate"] for row in rows], ":", color=colour[theta_i])
        top.plot(
            theta_s,
            [row["image_ratio"] for row in rows],
            "s",
            color=colour[theta_i],
            ms=3,
            alpha=0.6,
        )
    top.plot([], [], ":", color="k", label="point estimate BRDF·Ω·cos θs, Eq. (6)")
    top.plot([], [], "s", color="k", ms=3, alpha=0.6, label="image ratio over the signal square")
    top.set_yscale("log")
    top.set_ylabel("raw reflectance [-]")
    top.set_title(
        f"Series {payloads[0]['series']}: measured and ray-traced raw reflectance "
        f"({payloads[0]['rays']} rays per point)"
    )
    top.legend(fontsize=7, ncol=2)
    bottom.axhline(1.0, color="0.5", lw=0.8)
    bottom.set_ylabel("simulated / measured [-]")
    bottom.set_xlabel("detector angle θs = θi + δ [deg]")
    figure.tight_layout()
    return figure


def plot_detector_images(images: dict) -> plt.Figure:
    """Simulated detector images (like Fig. 13) and the reference image, with the signal
    rectangle of the image ratio outlined; power per pixel relative to the reference peak."""
    angles = images["theta_s_deg"]
    count = len(angles) + 1
    figure, axes = plt.subplots(count, 1, figsize=(7, 1.55 * count + 0.6), sharex=True)
    x, y = images["x_edges_mm"], images["y_edges_mm"]
    half = images["signal_half_size_mm"]
    scale = float(np.max(images["scattered"])) or 1.0
    panels = [
        (image / scale, f"θs = {theta_s:g}° (δ = {theta_s - images['theta_i_deg']:+g}°)")
        for image, theta_s in zip(images["scattered"], angles, strict=True)
    ]
    reference = images["reference"]
    panels.append((reference / (float(np.max(reference)) or 1.0), "reference (no sample)"))
    for axis, (data, title) in zip(np.atleast_1d(axes), panels, strict=True):
        mesh = axis.pcolormesh(x, y, data.T, cmap="inferno", shading="flat")
        axis.add_patch(
            plt.Rectangle((-half[0], -half[1]), 2 * half[0], 2 * half[1], fill=False, ec="c")
        )
        axis.set_aspect("equal")
        axis.set_ylabel("across [mm]")
        axis.set_title(title, fontsize=9)
        figure.colorbar(mesh, ax=axis, label="relative power [-]", pad=0.01)
    np.atleast_1d(axes)[-1].set_xlabel("in the plane of incidence [mm]")
    figure.suptitle(f"Simulated detector images, θi = {images['theta_i_deg']:g}° (cf. Fig. 13)")
    figure.tight_layout()
    return figure
