"""The results store: one layer below both the service that writes results and the
report that reads them (signac's data store: the workflow never reaches into files).

* ``format``: the HDF5 schema, the paths beside a results file, record <-> group;
* ``journal``: the write-ahead journal of checksummed per-task entries;
* ``read``: readers of results files plus their journals (deduplicated by task id);
* ``sealed``: every row and the root once more as self-checksummed frames, which a
  scan of the raw bytes finds in a file cut short (docs/crash-safety.md);
* ``writer``: the master's writer with shadow checkpoints and the file lock;
* ``salvage``: what is intact in a damaged file, for ``knitsweep recover``;
* ``sweep_file``: one sweep as a CSV table or a small HDF5 file (``knitsweep sweep``);
* ``provenance``: the run environment recorded in a file's root attributes.

Nothing here imports the service, the report or the numerical layers; h5py loads on
first use, so a light command that only reads stays light.
"""
