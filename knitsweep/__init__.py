"""knitsweep: fast simulations of jammed stockinette knitted fabric.

Importing the package does no work: no MPI, no numba compilation, no file access.
"""

__version__ = "0.1.0"
