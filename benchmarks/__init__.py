"""Benchmarks and the tables built from their committed results (``benchmarks/results/``).

A package so that its scripts import each other without ``sys.path`` edits; run each from the
repository root as a module, e.g. ``python -m benchmarks.throughput --quick``.
"""
