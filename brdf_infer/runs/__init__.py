"""The run folder: where a run's results live on disk, and the records they are written as.

``folder`` is the run folder's one owner: its file names, its atomic writers and its typed
readers (:class:`~brdf_infer.runs.folder.RunFolder`), and the package's one JSON reader;
``records`` types the records a posterior run passes on (``summary.json``, ``bands.json``).
Both sit low in the toolkit: the parameters read a user's JSON file through ``folder``, the
table screening writes into ``records``, so nothing here imports the model or the scene. (The
verdict on a run is in ``brdf_infer.verdict``, above the scene and the plausibility checks it
reads.)
"""
