"""The one module that imports ArviZ: every other module reaches it through this adapter,
imported as ``from brdf_infer._internal import arviz as az``, so that moving to ArviZ 1.x (which
replaced ``InferenceData`` by xarray's ``DataTree`` and moved ``loo``, ``psens``, ``from_dict``
and the plots into arviz-base, arviz-stats and arviz-plots) changes this file only.

The names below are everything the toolkit uses of ArviZ 0.x, with its signatures and return
types (``tests/test_arviz_adapter.py`` checks that nothing else is used, and that no other
module imports ``arviz``). ArviZ is imported without its import-time ``FutureWarning`` about
the coming refactor, which users of the command line cannot act on.
"""

import warnings

with warnings.catch_warnings():
    warnings.simplefilter("ignore", FutureWarning)
    import arviz as _arviz
    from arviz import (
        InferenceData,
        bfmi,
        compare,
        ess,
        from_dict,
        from_netcdf,
        loo,
        mcse,
        plot_compare,
        plot_energy,
        psens,
        psislw,
        rhat,
        summary,
    )

VERSION: str = _arviz.__version__  # written into posterior.nc's provenance

# ArviZ's statistics the same with numba installed (the peers extra brings it) as without:
# its numba paths compile on first use in every process (≈ 0.25 s of each report, for
# arrays of a few thousand draws) and round differently from the NumPy ones
_arviz.Numba.disable_numba()


def from_netcdf_groups(path, groups: tuple[str, ...]) -> InferenceData:
    """Only ``groups`` of the InferenceData in ``path``, loaded into memory: a third of
    :func:`from_netcdf`'s time for two of a run's six groups."""
    import xarray

    return InferenceData(
        **{group: xarray.load_dataset(path, group=group, engine="h5netcdf") for group in groups}
    )


__all__ = [
    "VERSION",
    "InferenceData",
    "bfmi",
    "compare",
    "ess",
    "from_dict",
    "from_netcdf",
    "from_netcdf_groups",
    "loo",
    "mcse",
    "plot_compare",
    "plot_energy",
    "psens",
    "psislw",
    "rhat",
    "summary",
]
