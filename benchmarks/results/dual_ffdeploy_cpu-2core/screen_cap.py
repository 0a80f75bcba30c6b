"""The published dual checkpoint run with lateral feed-forward bounds other than its 2 N.

Provenance record of the session-9 screen (screen.json), not a maintained tool: run from the
repository root as ``python benchmarks/results/dual_ffdeploy_cpu-2core/screen_cap.py 0.5 2.0``
while the committed dual policy was the 2.8k checkpoint of ``dual_ffcap2`` deployed with its
training bound (2 N). 32 episodes of the screening seed 20000 (``train/publish_policy.py``'s
``SCREEN_SEED``), disjoint from the published evaluation's seed 0.
"""

import json
import sys

from peghole_mjx.envs.rollout import rollout
from peghole_mjx.policies import load_policy

b = load_policy("dual")
for cap in [float(x) for x in sys.argv[1:]]:
    env = b.make_env({"action.max_ff_xy_N": cap})
    r = rollout(env, b.policy_fn(), 32, params=b.params, seed=20000, progress=False)
    print(cap, json.dumps(r.summary().as_dict()), flush=True)
