"""The studies beside the main posterior: what the answer depends on and whether it can be trusted.

``compare`` ranks model families by PSIS-LOO; ``sensitivity`` changes the error model's
assumptions one at a time; ``sbc`` is simulation-based calibration (its uniformity bands in
``uniformity``, which the report draws too); ``instrument_comparison`` and ``instrument_bias``
are the bundled data under each instrument model and the synthetic experiment on whether it
matters; ``synthetic`` makes synthetic measurements at a scene's geometry; ``raytrace`` is the
Monte Carlo ray tracer of the series II setup (Sec. 6), the independent check of the
instrument kernels.
"""
