#!/usr/bin/env bash
# The GPU check (docs/gpu.md, "Running the GPU check"): on a machine with CUDA, in one go and in under
# 10 minutes of wall time, with a timeout on every step so that one hung step does not eat the budget:
#
#   1. warp-vs-cpu parity on CUDA (tests/sim/test_warp_backend.py: the template, all seven robots, the env);
#   2. morfic bench env --backend warp --device cuda --envs 1024,4096,8192;
#   3. morfic bench train --preset paper --device cuda --iterations 5;
#   4. up to 5 minutes of morfic train --preset paper --device cuda (what the budget leaves, less 50 s),
#      stopped with SIGINT (the run writes a checkpoint and exits), exported as a bundle (store export --latest);
#
# and writes every figure as JSON under $OUT (at most 8 files, flat: summary.json, parity.json,
# bench_env.json, bench_train.json, train.json, checkpoint.tar, gpu_check.log).
#
# Usage (from the repository root):
#   bash scripts/gpu_check.sh stash    copy the wheel parts carried in .gpu/p*/ to $WORK/parts and exit
#   bash scripts/gpu_check.sh install  stash, join and verify the parts, pip install the wheels (no index)
#   bash scripts/gpu_check.sh run      install, then check (the last device call)
#   bash scripts/gpu_check.sh check    the check alone, with the packages this Python already has
#
# Knobs (environment; defaults are the GPU check's):
#   MORFIC_GPU_CHECK_DEVICE     cuda | cpu (cpu: warp's CPU device, a dry run of the same steps)   [cuda]
#   MORFIC_GPU_CHECK_ENVS       bench env counts                                          [1024,4096,8192]
#   MORFIC_GPU_CHECK_STEPS      bench env timed steps                                                [50]
#   MORFIC_GPU_CHECK_PRESET     bench train and train preset                                      [paper]
#   MORFIC_GPU_CHECK_ITERATIONS bench train timed iterations                                          [5]
#   MORFIC_GPU_CHECK_TRAIN_S    seconds of training before SIGINT (less if the budget is short)     [300]
#   MORFIC_GPU_CHECK_TRAIN_SET  extra --set overrides of the training run, space-separated     [save_interval=25]
#   MORFIC_GPU_CHECK_PARITY_K   pytest -k expression of the parity step           [parity or same_code]
#   MORFIC_GPU_CHECK_OTHER_K    pytest -k expression of more warp tests, e.g. "not parity and not same_code" (empty: none) []
#   MORFIC_GPU_CHECK_WARMUP     1: compile MuJoCo Warp's modules in parallel before the timed steps     [1]
#   MORFIC_GPU_CHECK_BUDGET_S   wall-time budget of the check, install included; later steps shrink  [575]
#   MORFIC_GPU_CHECK_WORK       scratch folder (parts, wheels, site, store)                 [/tmp/morfic-gpu]
#   MORFIC_GPU_CHECK_PIP_ARGS   extra pip install arguments (a rehearsal on another Python)            []
#   MORFIC_GPU_CHECK_CARRIED    the folder holding the carried part folders p1 .. pN                  [.gpu]
#   MORFIC_GPU_CHECK_SKIP       steps to skip, space-separated (a rerun), e.g. "warmup parity bench_env"  []
#   OUT                         where the results go (the device tool sets it)            [$WORK/out]
#   PYTHON                      the interpreter                                               [python3]
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
WORK=${MORFIC_GPU_CHECK_WORK:-/tmp/morfic-gpu}
OUT=${OUT:-$WORK/out}
PY=${PYTHON:-python3}
DEVICE=${MORFIC_GPU_CHECK_DEVICE:-cuda}
ENVS=${MORFIC_GPU_CHECK_ENVS:-1024,4096,8192}
STEPS=${MORFIC_GPU_CHECK_STEPS:-50}
PRESET=${MORFIC_GPU_CHECK_PRESET:-paper}
ITERATIONS=${MORFIC_GPU_CHECK_ITERATIONS:-5}
TRAIN_S=${MORFIC_GPU_CHECK_TRAIN_S:-300}
TRAIN_SET=${MORFIC_GPU_CHECK_TRAIN_SET:-save_interval=25}
PARITY_K=${MORFIC_GPU_CHECK_PARITY_K:-parity or same_code}
OTHER_K=${MORFIC_GPU_CHECK_OTHER_K:-}
WARMUP=${MORFIC_GPU_CHECK_WARMUP:-1}
BUDGET_S=${MORFIC_GPU_CHECK_BUDGET_S:-575}
PIP_ARGS=${MORFIC_GPU_CHECK_PIP_ARGS:-}
CARRIED=${MORFIC_GPU_CHECK_CARRIED:-.gpu}
SKIP=${MORFIC_GPU_CHECK_SKIP:-}
START=$(date +%s)
DEADLINE=$((START + BUDGET_S))
RESERVE_S=50  # kept for the end: the run's last iteration and checkpoint after SIGINT, the export, the summary
# GitPython (imported by rsl-rl) refuses to import without a git binary unless told to be quiet
export PYTHONUNBUFFERED=1 MORFIC_STORE="$WORK/store" GIT_PYTHON_REFRESH=${GIT_PYTHON_REFRESH:-quiet}
mkdir -p "$WORK" "$OUT"
LOG="$OUT/gpu_check.log"

say() { echo "[gpu_check $(($(date +%s) - START))s] $*" | tee -a "$LOG"; }

stash() {  # the parts carried in this call -> $WORK/parts (kept while the machine stays warm)
  mkdir -p "$WORK/parts"
  local found=0
  for d in "$CARRIED"/p*/; do
    [ -d "$d" ] || continue
    cp -f "$d"* "$WORK/parts/" && found=1  # what a call carries replaces what an earlier attempt left
  done
  [ "$found" = 1 ] || say "no $CARRIED/p*/ folder in this call's working tree (nothing carried?)"
  say "parts on this machine: $(cd "$WORK/parts" && ls morfic-wheels.tar.* 2>/dev/null | tr '\n' ' ')"
}

install() {
  stash
  local sums="$WORK/parts/PARTS.sha256"
  if [ ! -f "$sums" ]; then
    say "Error: no PARTS.sha256 among the carried parts; run scripts/gpu_wheels.sh here and carry .gpu/p1 .. .gpu/pN"
    exit 1
  fi
  if [ -f "$WORK/site/.installed" ] && cmp -s "$sums" "$WORK/site/.installed"; then
    say "wheels already installed in $WORK/site (same parts)"
  else
    local missing
    missing=$(cd "$WORK/parts" && while read -r _ f; do [ -f "$f" ] || echo "$f"; done < PARTS.sha256)
    if [ -n "$missing" ]; then
      say "Error: part(s) missing: $(echo "$missing" | tr '\n' ' ')— the machine was given back between calls (warm only ~30 s); make the calls again from call 1 (docs/gpu.md)"
      exit 1
    fi
    (cd "$WORK/parts" && sha256sum -c --quiet PARTS.sha256) || { say "Error: a part is damaged (sha256); carry it again"; exit 1; }
    rm -rf "$WORK/wheels"
    (cd "$WORK/parts" && cat $(awk '{print $2}' PARTS.sha256)) | tar -xf - -C "$WORK" || { say "Error: joining the parts failed"; exit 1; }
    (cd "$WORK/wheels" && sha256sum -c --quiet SHA256SUMS) || { say "Error: a wheel is damaged (sha256)"; exit 1; }
    rm -rf "$WORK/site"
    # shellcheck disable=SC2086
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade $PIP_ARGS \
      --target "$WORK/site" "$WORK"/wheels/*.whl 2>&1 | tee -a "$LOG"
    [ "${PIPESTATUS[0]}" = 0 ] || { say "Error: pip install of the carried wheels failed"; exit 1; }
    cp "$sums" "$WORK/site/.installed"
    say "installed $(ls "$WORK"/wheels/*.whl | wc -l) wheels into $WORK/site"
  fi
  export PYTHONPATH="$WORK/site:$ROOT${PYTHONPATH:+:$PYTHONPATH}"
}

record() {  # step rc seconds timeout_s status
  printf '{"step": "%s", "rc": %s, "seconds": %s, "timeout_s": %s, "status": "%s"}\n' "$@" >> "$WORK/steps.jsonl"
}

# step NAME TIMEOUT_S STDOUT_FILE CMD...: run CMD with a timeout (cut to the budget left), stdout to the
# file, stderr to the log; a failed step leaves no stdout file and the check goes on.
step() {
  local name=$1 limit=$2 out=$3
  shift 3
  local left=$((DEADLINE - $(date +%s)))
  if [[ " $SKIP " == *" $name "* ]]; then
    say "$name: skipped (MORFIC_GPU_CHECK_SKIP)"
    record "$name" null 0 0 skipped
    return 1
  fi
  if [ "$left" -lt 20 ]; then
    say "$name: skipped (budget spent)"
    record "$name" null 0 0 skipped
    return 1
  fi
  [ "$limit" -gt "$left" ] && limit=$left
  say "$name: start (timeout ${limit}s): $*"
  local t0 rc dt
  t0=$(date +%s%N)
  timeout -k 15 "$limit" "$@" > "$out.part" 2>> "$LOG"
  rc=$?
  dt=$(awk -v a="$t0" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f", (b - a) / 1e9 }')
  if [ "$rc" = 0 ]; then
    mv "$out.part" "$out"
    record "$name" "$rc" "$dt" "$limit" ok
  else
    { echo "--- $name: stdout of the failed step ---"; cat "$out.part"; } >> "$LOG" 2>/dev/null
    rm -f "$out.part"
    record "$name" "$rc" "$dt" "$limit" "$([ "$rc" = 124 ] || [ "$rc" = 137 ] && echo timeout || echo failed)"
  fi
  say "$name: rc=$rc in ${dt}s"
  return "$rc"
}

check() {
  rm -rf "$WORK/store" "$WORK/steps.jsonl" "$WORK"/*.xml "$WORK/info.json" "$WORK/warmup.json"
  rm -f "$OUT"/summary.json "$OUT"/parity.json "$OUT"/bench_*.json "$OUT"/train.json "$OUT"/checkpoint.tar
  say "device=$DEVICE envs=$ENVS preset=$PRESET train=${TRAIN_S}s budget=${BUDGET_S}s python=$("$PY" -V 2>&1)"
  step info 60 "$WORK/info.log" "$PY" scripts/gpu_check.py info "$WORK/info.json"
  local dev_args=(--backend warp --device "$DEVICE") train_args=(--device "$DEVICE")
  # warp's CPU device: train names the backend (--device cuda implies warp)
  [ "$DEVICE" = cpu ] && train_args=(--device cpu --set env.sim.backend=warp)
  local warp_dev=$DEVICE
  [ "$DEVICE" = cuda ] && warp_dev=cuda:0
  if [ "$WARMUP" = 1 ]; then
    step warmup 150 "$WORK/warmup.log" "$PY" scripts/gpu_check.py warmup "$warp_dev" "$WORK/warmup.json"
  fi

  # the parity tests first, then the file's other tests in a second pytest: a timeout in the second (whose
  # JUnit report pytest writes at its end only) loses nothing of the first
  local pytest_args=(tests/sim/test_warp_backend.py -m "slow or not slow" -p no:cacheprovider -q -rA
                     -o junit_family=xunit1)
  "$PY" -c "import pytest_timeout" 2>/dev/null && pytest_args+=(--timeout 120)
  export MORFIC_WARP_TEST_DEVICE=$DEVICE
  step parity 150 "$WORK/parity.log" "$PY" -m pytest "${pytest_args[@]}" -k "$PARITY_K" \
    --junitxml "$WORK/parity.xml"
  cat "$WORK/parity.log" >> "$LOG" 2>/dev/null
  local reports=("$WORK/parity.xml")
  if [ -n "$OTHER_K" ]; then
    step warp_tests 90 "$WORK/warp_tests.log" "$PY" -m pytest "${pytest_args[@]}" -k "$OTHER_K" \
      --junitxml "$WORK/warp_tests.xml"
    cat "$WORK/warp_tests.log" >> "$LOG" 2>/dev/null
    reports+=("$WORK/warp_tests.xml")
  fi
  "$PY" scripts/gpu_check.py parity "$OUT/parity.json" "${reports[@]}" | tee -a "$LOG"

  step bench_env 120 "$OUT/bench_env.json" "$PY" -m morfic_cli bench env "${dev_args[@]}" --envs "$ENVS" \
    --steps "$STEPS" --format json
  step bench_train 150 "$OUT/bench_train.json" "$PY" -m morfic_cli bench train "${dev_args[@]}" --preset "$PRESET" \
    --iterations "$ITERATIONS" --format json

  local left=$((DEADLINE - $(date +%s) - RESERVE_S)) train_s=$TRAIN_S sets=()
  [ "$left" -lt "$train_s" ] && train_s=$left
  for kv in $TRAIN_SET; do sets+=(--set "$kv"); done
  if [ "$train_s" -ge 30 ]; then
    # SIGINT after train_s: the run finishes its iteration, writes a checkpoint and exits 0 (--preserve-status);
    # KILL 45 s later if it has not. The step's own limit is the KILL's.
    step train $((train_s + 50)) "$OUT/train.json" timeout --preserve-status -s INT -k 45 "$train_s" \
      "$PY" -m morfic_cli train --preset "$PRESET" "${train_args[@]}" --name gpu-check "${sets[@]}" --format json
  else
    say "train: skipped (${train_s}s left before the reserve)"
    record train null 0 0 skipped
  fi
  if step export 30 "$WORK/export.log" "$PY" -m morfic_cli store export runs/gpu-check --latest \
      --out "$OUT" --name checkpoint; then
    step show 30 "$WORK/bundle.json" "$PY" -m morfic_cli store show runs/gpu-check --format json
  fi
  MORFIC_GPU_CHECK_DEVICE=$DEVICE "$PY" scripts/gpu_check.py summary "$WORK" "$OUT" > "$WORK/summary.log" 2>> "$LOG" \
    || say "summary failed (see the log)"
  say "done in $(($(date +%s) - START))s; files under $OUT: $(cd "$OUT" && ls | tr '\n' ' ')"
  "$PY" - "$OUT/summary.json" <<'EOF'
import json, sys
try:
    doc = json.load(open(sys.argv[1]))
except (OSError, ValueError) as exc:
    sys.exit(f"no summary: {exc}")
for name, s in doc["steps"].items():
    print(f"  {name:12s} {s['status']:8s} {float(s['seconds'] or 0):7.1f} s")
print(json.dumps({"parity": {k: doc["parity"][k] for k in ("ok", "passed", "failed", "skipped")}
                  if doc["parity"] else None, "figures": doc["figures"]}, indent=1))
EOF
}

case "${1:-}" in
  stash) stash ;;
  install) install ;;
  run) install && check ;;
  check) check ;;
  *) echo "usage: bash scripts/gpu_check.sh stash|install|run|check (see the header)" >&2; exit 2 ;;
esac
