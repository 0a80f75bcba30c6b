"""Screen checkpoints against the baseline on the same episodes (seed 20000)."""

import json
import sys

from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.policies import load_policy

run, steps, n = sys.argv[1], sys.argv[2].split(","), int(sys.argv[3])
bundles = [load_policy(f"{run}/checkpoints/step_{int(s):010d}") for s in steps]
env = bundles[0].make_env()
base = rollout(env, scripted_policy(env), n, seed=20000, progress=False).summary().as_dict()
print("baseline", json.dumps({k: round(v, 4) for k, v in base.items()}), flush=True)
for s, b in zip(steps, bundles, strict=True):
    p = (
        rollout(env, b.policy_fn(), n, seed=20000, params=b.params, progress=False)
        .summary()
        .as_dict()
    )
    red = 100 * (base["mean_fz_N"] - p["mean_fz_N"]) / base["mean_fz_N"]
    print(s, f"red {red:.1f} %", json.dumps({k: round(v, 4) for k, v in p.items()}), flush=True)
