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
        plot_pair,
        plot_rank,
        plot_trace,
        psens,
        psislw,
        rhat,
        summary,
    )
    from arviz.labels import MapLabeller
    from arviz.stats.ecdf_utils import ecdf_confidence_band

VERSION: str = _arviz.__version__  # written into posterior.nc's provenance

__all__ = [
    "VERSION",
    "InferenceData",
    "MapLabeller",
    "bfmi",
    "compare",
    "ecdf_confidence_band",
    "ess",
    "from_dict",
    "from_netcdf",
    "loo",
    "mcse",
    "plot_compare",
    "plot_energy",
    "plot_pair",
    "plot_rank",
    "plot_trace",
    "psens",
    "psislw",
    "rhat",
    "summary",
]
