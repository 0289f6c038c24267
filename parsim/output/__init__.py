"""Files a job writes: per-task HDF5 snapshots, the netCDF dataset, the resume state."""
