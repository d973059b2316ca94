"""The toolkit's private helpers, shared by its packages: nothing here is public API.

Results folders: ``outlock`` (one writer per results folder, and whether it is complete),
``atomic`` (atomic writes); the numerics: ``precision`` (the float64 guard) and ``cache`` (JAX's
persistent compilation cache), ``sharding`` (a batch axis over every device), ``units`` (degrees
and radians); ``shards`` (which scenes a shard of a batch runs); ``resources`` (the bundled data
files); ``design_target`` (a design target parsed without JAX, read by the scene and the
settings below ``design/``, which is why it is not in ``design/``); ``arviz`` (the one module
importing ArviZ).

A helper that one package alone uses lives in that package instead (``cli/_device.py``,
``cli/_outdir.py``, ``posterior/_compile_clock.py``, ``workflow/_studies.py``). The modules'
own names carry no underscore: the package's leading underscore already says private
(``tests/test_import_graph.py``: any module of ``brdf_infer`` may use them, nothing outside).
"""
