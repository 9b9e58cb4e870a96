"""Gravity estimation from an IMU on the hand (docs/hostless.md): ``synthetic`` makes IMU streams
from the virtual participant's hand trajectories, ``compare`` runs the device's estimator
(the C++ of ``graspguide_cue/gravity_estimator.h``, through ``_core``) and the two
independent references, VQF and x-io Fusion, on them. SIMULATED streams, never human data.
"""
