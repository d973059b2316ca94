"""Least squares and the paper's regression: the fits before (and beside) the posterior.

``lsq`` (least squares of every family) solves in the coordinates of ``_space`` and reweights its
rows in ``_reweighting``; ``quality`` is χ²/dof and the fit-quality statement; ``paper`` is the
paper's regression (Sec. 4.2) on the data selections of ``brdf_infer.tables.selections``.
"""
