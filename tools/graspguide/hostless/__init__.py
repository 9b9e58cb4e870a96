"""The host-less wearable from the host's side (docs/hostless.md): the study
plan as the device stores it (``plan_upload``), the device's results log downloaded in
the runner's folder format (``device_log``), and the simulated world that drives a
host-less run (``imu_world``, ``runner``). The modules are imported where used."""
