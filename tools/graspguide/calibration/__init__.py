"""Per-finger perceptual calibration (`graspguide calibrate`, docs/calibration.md): a
detection threshold per thimble by an adaptive staircase (:mod:`staircase`), intensity
matching to a reference finger (:mod:`matching`), the procedure on a device with the
operator's or a virtual observer's answers (:mod:`session`, :mod:`operator`,
:mod:`virtual_observer`), and the stored result (:mod:`calibration_file`)."""
