"""Numba kernels: plain ndarrays and scalars in and out, nothing above numpy/numba.

Pipeline: bezier (basis tables) -> crossover, geometry (state -> control points
+ Jacobian) -> bending, contact (energies + gradients; contact's candidate search
in partition, its vectorisable pow in elementary, an optional Verlet list in
neighbours) -> cell (their composition).
"""
