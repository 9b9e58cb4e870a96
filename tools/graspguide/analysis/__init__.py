"""Statistics over run records: the paper's tables, its tests and Figure 4."""
