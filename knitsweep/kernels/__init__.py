"""Numba kernels: plain ndarrays and scalars in and out, nothing above numpy/numba.

Pipeline: bezier (basis tables) -> geometry (state -> control points + Jacobian)
-> bending, contact (energies + gradients) -> cell (their composition).
"""
