"""Screen a dual checkpoint on the first 64 episodes of seed 0 against the saved 256-slices.

Provenance record of the session-7 screen (screen.json), not a maintained tool: run from the
repository root with runs/dual_eval holding the 256-episode slices of `peghole evaluate dual
--batch 256 --parts runs/dual_eval`.
"""

import sys

import numpy as np

from peghole_mjx.envs.rollout import rollout
from peghole_mjx.policies import load_policy

b = load_policy(sys.argv[1])
env = b.make_env(None)
res = rollout(env, b.policy_fn(), 64, seed=0, params=b.params, progress=False).summary()
base = np.load("runs/dual_eval/baseline/episodes_0000000_0000256.npz")
# (parts folders are named policy-<params sha>-<env config sha> since session 9)
cur = np.load("runs/dual_eval/policy-09a79aa70208/episodes_0000000_0000256.npz")
fb, fc = base["mean_fz_N"][:64].mean(), cur["mean_fz_N"][:64].mean()
print(sys.argv[1], res)
print(
    f"new {res.mean_fz_N:.4f} N ({100 * (fb - res.mean_fz_N) / fb:+.1f} %), committed {fc:.4f} N "
    f"({100 * (fb - fc) / fb:+.1f} %), baseline {fb:.4f} N on episodes 0-63"
)
