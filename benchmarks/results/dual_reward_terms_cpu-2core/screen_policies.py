"""Screen checkpoints of several runs on the same episodes (seed 20000), policy only."""

import json
import sys

from peghole_mjx.envs.rollout import rollout
from peghole_mjx.policies import load_policy

n, base_fz = int(sys.argv[1]), float(sys.argv[2])
paths = sys.argv[3:]
env = None
for path in paths:
    b = load_policy(path)
    env = env or b.make_env()
    p = (
        rollout(env, b.policy_fn(), n, seed=20000, params=b.params, progress=False)
        .summary()
        .as_dict()
    )
    red = 100 * (base_fz - p["mean_fz_N"]) / base_fz
    print(path, f"red {red:.1f} %", json.dumps({k: round(v, 4) for k, v in p.items()}), flush=True)
