"""The run records: what a run writes and every reader reads back (trials, sessions,
events), with their file names and their crash-safe append."""
