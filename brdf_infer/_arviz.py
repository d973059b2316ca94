"""ArviZ, imported without its import-time FutureWarning about a coming refactor (which
users of the command line cannot act on)."""

import warnings

with warnings.catch_warnings():
    warnings.simplefilter("ignore", FutureWarning)
    import arviz as az

__all__ = ["az"]
