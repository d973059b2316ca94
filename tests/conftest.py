import brdf_infer  # noqa: F401  (float64 for every test)
