"""Host benchmarks: the core's frame and QP against peer solvers (``graspguide bench``)."""
