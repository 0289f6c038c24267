"""Jitted kernels: plain numpy arrays in, plain numpy arrays out.

No MPI, no files, no printing: the core never imports from the rest of parsim.
"""
