"""Algorithm 1 on the host: the C++ core's binding (:mod:`._core`, :mod:`.solver`), the
independent float64 reference (:mod:`.reference`) and seeded scene generators."""
