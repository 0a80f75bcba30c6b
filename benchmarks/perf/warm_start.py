"""A command's start with and without the persistent compilation cache.

Runs ``peghole evaluate POLICY --episodes 16`` (or the command given after ``--``) ``--runs``
times in fresh processes that share one new, empty cache folder: run 1 compiles and fills the
cache, the later runs load from it (``PEGHOLE_JAX_CACHE``; a ``JAX_COMPILATION_CACHE_DIR`` of
the caller's is removed from the child's environment). For each run it records, from the
process start:

* ``first_batch_s``: the first output of the policy rollout's progress bar (``policy
  rollout: ``), i.e. its first batch has started and run its first chunk of 25 env steps;
* ``longest_silence_s``: the longest time with no new output on stderr (labelled phases and
  bars print at least every few seconds while they run);
* ``wall_s`` and the exit status.

The figure compared with a target is ``warm_first_batch_median_s``, the median of the runs with
a filled cache (three by default): one run alone moves by seconds with the machine's load (the
load average at the start is recorded).

Run ``python -m benchmarks.perf.warm_start`` (about 4 minutes on a 2-core CPU); writes
``benchmarks/results/perf/warm_start_<engine>_<device>.json``. ``--engine mujoco`` adds
``--engine mujoco --cross`` to the command (the CPU engine, whose host-callback graphs JAX
does not cache: only the pure-JAX half of its reset loads from the cache).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import PERF_RESULTS, cpu_label, load_average, out_file, rel, table
from peghole_mjx.files.provenance import provenance

#: the output that marks the first rollout batch as started: its progress bar (the compile
#: phase's label before it reads "... of the policy rollout (first run only ...)")
FIRST_BATCH = b"policy rollout: "


def time_run(argv: list[str], env: dict[str, str], echo: bool = False) -> dict:
    """Run ``argv`` and time its stderr: first rollout bar, longest silence, wall, status.
    ``echo``: pass the child's stderr (its labelled phases and bars) through to ours."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    assert proc.stderr is not None
    seen, first, last, silence = b"", None, t0, 0.0
    while chunk := os.read(proc.stderr.fileno(), 65536):
        now = time.perf_counter()
        silence, last = max(silence, now - last), now
        if echo:
            sys.stderr.buffer.write(chunk)
            sys.stderr.flush()
        seen = (seen + chunk)[-4096:]
        if first is None and FIRST_BATCH in seen:
            first = now - t0
    rc = proc.wait()
    wall = time.perf_counter() - t0
    return {
        "returncode": rc,
        "first_batch_s": None if first is None else round(first, 2),
        "longest_silence_s": round(max(silence, wall - (last - t0)), 2),
        "wall_s": round(wall, 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.perf.warm_start", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("--policy", default="rect", help="policy to evaluate (default: rect)")
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument(
        "--runs", type=int, default=4, help="runs sharing one cache, the first cold (default: 4)"
    )
    ap.add_argument("--engine", choices=("trained", "mujoco"), default="trained")
    ap.add_argument(
        "--out", type=out_file, default=None, help="result JSON (default: per engine and device)"
    )
    args = ap.parse_args(argv)
    if args.runs < 1 or args.episodes < 1:
        ap.error("--runs and --episodes must be >= 1")
    out = args.out or PERF_RESULTS / f"warm_start_{args.engine}_{cpu_label()}.json"
    cache = Path(tempfile.mkdtemp(prefix="peghole_warm_start_cache_"))
    work = Path(tempfile.mkdtemp(prefix="peghole_warm_start_out_"))
    cmd = ["peghole", "evaluate", args.policy, "--episodes", str(args.episodes)]
    if args.engine == "mujoco":
        cmd += ["--engine", "mujoco", "--cross"]
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env["PEGHOLE_JAX_CACHE"] = str(cache)
    runs = []
    try:
        for i in range(args.runs):
            print(f"run {i + 1}/{args.runs}: {' '.join(cmd)}", file=sys.stderr, flush=True)
            exe = [shutil.which("peghole") or "peghole", *cmd[1:], "--out", str(work / str(i))]
            timed = time_run(exe, env, echo=True)
            row = {"run": i + 1, "cache": "empty" if i == 0 else "filled", **timed}
            print(f"  {row}", file=sys.stderr, flush=True)
            runs.append(row)
    finally:
        shutil.rmtree(cache, ignore_errors=True)
        shutil.rmtree(work, ignore_errors=True)
    doc = {
        **provenance(),
        "load_average": load_average(),
        "command": " ".join(cmd),
        "first_batch_marker": FIRST_BATCH.decode(),
        "runs": runs,
        "warm_first_batch_median_s": _median(
            [r["first_batch_s"] for r in runs[1:] if r["first_batch_s"] is not None]
        ),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {out}")
    return 0 if all(r["returncode"] == 0 for r in runs) else 1


def _median(values: list[float]) -> float | None:
    return round(float(statistics.median(values)), 2) if values else None


@table("warm_start")
def warm_start_table() -> str:
    """One row per committed run (command, cache state, first batch, silence, wall), then the
    median first batch of the runs with a filled cache."""
    lines = [
        "| command | run | cache | first rollout batch (s) | longest silence (s) | wall (s) "
        "| device, date | result file |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for path in sorted(PERF_RESULTS.glob("warm_start_*.json")):
        doc = json.loads(path.read_text())
        for r in doc["runs"]:
            lines.append(
                f"| `{doc['command']}` | {r['run']} | {r['cache']} | {r['first_batch_s']} "
                f"| {r['longest_silence_s']} | {r['wall_s']} | {doc['device']}, "
                f"{doc['date'][:10]} | [{path.name}]({rel(path)}) |"
            )
        median = doc.get("warm_first_batch_median_s")
        if median is not None:
            lines.append(
                f"| `{doc['command']}` | median of runs 2-{len(doc['runs'])} | filled "
                f"| **{median}** | | | {doc['device']}, {doc['date'][:10]} "
                f"| [{path.name}]({rel(path)}) |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
