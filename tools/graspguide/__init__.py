"""GraspGuide host tools, by role:

* :mod:`graspguide.core` -- Algorithm 1 from the C++ core (:mod:`.core.solver` over the
  compiled :mod:`.core._core`, float or double), the independent float64 reference, the
  seeded scene generators, the vocabulary, rotations, unit checks and the JSON Lines
  requests of ``graspguide solve``;
* :mod:`graspguide.link` -- the serial link: codec, generated messages, transport (and
  the simulated device), the device client;
* :mod:`graspguide.study` -- scene and study-protocol files, pose sources, the virtual
  participant, the pose loop, the runner, records, demo, sweep and analysis;
* :mod:`graspguide.bench` -- the host benchmark;
* :mod:`graspguide.cli` -- the ``graspguide`` command: one table, one module a command.
"""

__version__ = "0.1.0"
