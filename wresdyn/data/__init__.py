"""The data: excitation (eq. 2 foot paths by IK, multisines, chirps, kicks), the simulated "real"
robot that records it, the dataset file format and its migration, and the import of real robot logs."""
