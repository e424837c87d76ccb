"""Applications on top of the core: the `dualarm` command, launcher, the rclpy tool verbs (topic, param, bag record), bags, reports, experiments, benchmarks."""
