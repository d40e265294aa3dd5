"""Speed benchmarks: whole workloads timed against a reference implementation in the same run,
printed as side-by-side ratios (never timed unit tests). Run with `make bench`."""
