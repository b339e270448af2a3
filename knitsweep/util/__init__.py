"""Small helpers every layer may use, each module named for what it does:

* ``plain_values``: plain Python values from numpy's, HDF5's and dataclasses' (records,
  journal entries, tables, JSON);
* ``forking``: helper processes forked to read or draw in parallel (how many may run,
  the signals they take);
* ``safe_files``: bounded reads of input files, atomic writes that never go through a
  symbolic link, and the output checks every command makes before any compute.

They know nothing of stitches, settings or files' contents; only ``errors`` is below them.
"""
