#!/usr/bin/env bash
# One command for an H100/H200 machine: install what the image lacks from carried
# wheels, then the throughput sweep (mjx-jax and mjx-warp, rect and dual in each collision
# representation, up to 16 384 worlds, and all-core MuJoCo C for the >= 5x target), the
# cost/roofline measures, the time-to-success benchmark and a full-profile training of each env,
# every stage under its own time budget so that the whole suite ends inside one 10-minute call
# with a 2-minute margin (SUITE_BUDGET_S, default 480 s). Result files go to $OUT (the device
# tool's folder) or benchmarks/results/perf/gpu_suite/.
#
#   bash benchmarks/perf/gpu_suite.sh            # on the GPU machine (see docs/throughput.md)
#   bash benchmarks/perf/gpu_suite.sh --tiny     # CPU smoke test: tiny sweep, no training
#   bash benchmarks/perf/gpu_suite.sh --dry-run  # print the stages and their budgets only
#
# Wheels: put them in .whl/ (device README recipe, --python-version 3.12): mujoco, mujoco-mjx,
# brax, ml-collections, tensorboardx, jaxopt, trimesh, coacd, mujoco-warp, and warp-lang split
# into parts (split -b 60M warp_lang-*.whl .whl/parts/warp_lang-<version>-...whl.part-) carried
# in calls that follow each other while the machine stays warm; the parts are joined here.
set -u
TINY=0
DRY=0
for a in "$@"; do
  case "$a" in
    --tiny) TINY=1 ;;
    --dry-run) DRY=1 ;;
    *) echo "gpu_suite.sh: unknown option $a (use --tiny or --dry-run)" >&2; exit 2 ;;
  esac
done
cd "$(dirname "$0")/../.."
if [ "$DRY" = 1 ] && [ -z "${OUT:-}" ]; then RES="$(mktemp -d)"; else
  RES="${OUT:-benchmarks/results/perf/gpu_suite}"; fi
mkdir -p "$RES"
BUDGET="${SUITE_BUDGET_S:-480}"
START=$(date +%s)
PY="${PYTHON:-python3}"
export PYTHONUNBUFFERED=1
LOG="$RES/gpu_suite.log"
: >"$LOG"

say() { echo "[gpu_suite] $*" | tee -a "$LOG"; }
left() { echo $((BUDGET - ($(date +%s) - START))); }

# stage NAME SHARE_PCT CMD...: run CMD with at most SHARE_PCT % of the budget (and never past it)
stage() {
  local name="$1" share="$2"
  shift 2
  local want=$((BUDGET * share / 100)) rest
  rest=$(left)
  [ "$want" -gt "$rest" ] && want=$rest
  if [ "$want" -le 5 ]; then
    say "$name: skipped (budget spent)"
    return 0
  fi
  say "$name: up to ${want} s: $*"
  [ "$DRY" = 1 ] && return 0
  local t0=$(date +%s)
  timeout --signal=INT --kill-after=10 "$want" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  say "$name: rc=$rc after $(( $(date +%s) - t0 )) s"
}

# ---------------------------------------------------------------- install from carried wheels
if [ -d .whl ] && [ "$DRY" = 0 ]; then
  if [ -d .whl/parts ]; then  # join split wheels (name.whl.part-aa, -ab, ...)
    for first in .whl/parts/*.whl.part-aa; do
      [ -e "$first" ] || continue
      whl="${first%.part-aa}"
      cat "$whl".part-* >".whl/$(basename "$whl")"
    done
  fi
  say "installing $(ls .whl/*.whl | wc -l) wheels into /tmp/site"
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl 2>&1 | tee -a "$LOG"
  export PYTHONPATH="/tmp/site:${PYTHONPATH:-}"
fi
export PYTHONPATH="$PWD:${PYTHONPATH:-}"
"$PY" - <<'EOF' 2>&1 | tee -a "$LOG"
import importlib.util
import jax
print("[gpu_suite] jax devices:", jax.devices())
for m in ("mujoco", "mujoco.mjx", "brax", "warp", "mujoco_warp"):
    print(f"[gpu_suite] {m}: {'yes' if importlib.util.find_spec(m.split('.')[0]) else 'MISSING'}")
EOF

# ---------------------------------------------------------------- stages
if [ "$TINY" = 1 ]; then
  stage throughput 60 "$PY" -m benchmarks.perf.throughput --engines mujoco-1t,mjx-warp \
    --scenes rect,dual --worlds 1 --min-time 0.2 --timeout 120 --out "$RES/throughput_tiny.csv" \
    --note "gpu_suite.sh --tiny (CPU smoke test)"
  say "time_to_success, training: skipped in --tiny"
else
  # the >= 8192-world targets first, the comparison rows after (a cut-off loses the least)
  stage throughput_targets 35 "$PY" -m benchmarks.perf.throughput --engines mjx-jax,mjx-warp \
    --scenes rect,dual --worlds 8192,16384 --min-time 3 --chunk 20 --timeout 150 \
    --out "$RES/throughput_gpu_targets.csv" --note "gpu_suite.sh: target rows"
  stage throughput_repr 12 "$PY" -m benchmarks.perf.throughput --engines mjx-jax,mjx-warp \
    --scenes dual-mesh,dual-cylinder --worlds 8192 --min-time 3 --chunk 20 --timeout 120 \
    --out "$RES/throughput_gpu_representations.csv" --note "gpu_suite.sh: representations"
  stage throughput_c 6 "$PY" -m benchmarks.perf.throughput --engines mujoco-c-rollout \
    --scenes rect,dual --worlds 1024 --min-time 3 --timeout 60 \
    --out "$RES/throughput_gpu_mujoco_c.csv" --note "gpu_suite.sh: all-core MuJoCo C"
  stage sweep 8 "$PY" -m benchmarks.perf.throughput --engines mjx-jax --scenes rect,dual \
    --worlds 1,64,1024,4096 --min-time 2 --chunk 20 --timeout 60 \
    --out "$RES/throughput_gpu_sweep.csv" --note "gpu_suite.sh: sweep"
  stage cost 4 "$PY" -m benchmarks.perf.cost --out "$RES/cost_gpu.json" --note "gpu_suite.sh"
  stage time_to_success 15 "$PY" -m benchmarks.baselines.time_to_success --profile full \
    --out /tmp/runs/tts_rect
  for env in RectExtract DualExtract; do
    stage "train_$env" 10 "$PY" train/train.py --env "$env" --profile full \
      --out "/tmp/runs/full_$env" --no-video --no-progress
    [ -f "/tmp/runs/full_$env/metrics.csv" ] && cp "/tmp/runs/full_$env/metrics.csv" \
      "$RES/train_full_${env}_metrics.csv"
  done
  [ -d benchmarks/results/baselines ] && cp benchmarks/results/baselines/train_rect_gpu-*.json "$RES/" 2>/dev/null
fi
say "done in $(( $(date +%s) - START )) s of ${BUDGET} s; results in $RES"
