"""Closed investigations, each a runnable record of how a conclusion was reached (smoke tests
only): pull speed, capsule fidelity, friction models, soft springs, contact diagnosis, force
sources, the dual hull in PyBullet, the R2 map, policy traces, and the float64 MuJoCo C replica
of the compliance experiment they share. Results: ``benchmarks/results/studies/``."""
