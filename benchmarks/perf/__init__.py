"""Speed and cost of the engines: throughput sweeps, roofline and per-world cost estimates,
contact caps and the envs' reference rollouts. Results: ``benchmarks/results/perf/``."""
