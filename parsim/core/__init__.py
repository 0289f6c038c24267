"""Jitted kernels: plain numpy arrays in, plain numpy arrays out.

No files, no printing, no mpi4py: the core never imports from the rest of parsim (the jitted
exchanges of :mod:`parsim.core.kernel_mpi` call the MPI library that the parallel layer binds).
"""
