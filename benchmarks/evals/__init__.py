"""Evaluations of the policies and of the thesis's claims: generalisation, transfer toward a
robot, stuck joints, RL vs RL + CS, paired reductions, the hard variants, both engines, and the
tables of the results that ``peghole`` commands write. Results: ``benchmarks/results/evals/``."""
