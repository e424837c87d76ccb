"""Applications on top of the core: the `dualarm` command, launcher, bags, reports, experiments, benchmarks."""
