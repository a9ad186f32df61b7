"""The 2-D linkage: a genome decoded into a linkage, its batched kinematics (numba kernels),
fitness, descriptors, physical checks, the linkage document and the plain reference.

Pure numerics (numpy, numba): it imports nothing of the 3-D robot (`sim.robot`)."""
