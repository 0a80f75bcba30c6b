"""Simulated experiments of the thesis (compliance-centre extraction, Sec 2.5 and 3.4)."""
