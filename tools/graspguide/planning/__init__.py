"""Planning a study by simulation: sweeps of virtual participants over the conditions."""
