"""Studies: scene and study-protocol files, pose sources, the virtual participant, the
session loop and its records, the runner, demo, sweep and analysis."""
