"""GraspGuide host tools.

* :func:`graspguide.solve.solve` -- Algorithm 1 from the C++ core (float or double),
  through the compiled extension :mod:`graspguide.core._core`;
* ``graspguide solve`` -- the JSON Lines command line (:mod:`graspguide.cli`);
* :mod:`graspguide.core.reference` -- the independent float64 reference;
* :mod:`graspguide.core.scene_generators` -- seeded scene generators.
"""

__version__ = "0.1.0"
