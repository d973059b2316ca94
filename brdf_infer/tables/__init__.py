"""The measurement tables: reading, validating and selecting the rows every fit starts from.

``measurements`` is the measurement table, one validated row per measurement;
``bsdf_measurements`` reads rows from a tabular .BSDF file, whose format itself (reader, writer,
specular frame) is ``bsdf_file``, below both its reader and the exports; ``screening`` says what
reading a table leaves out (zero cells, dropouts), each by a stated rule with its count;
``selections`` names the data selections of the paper's regression.
"""
