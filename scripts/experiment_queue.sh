#!/usr/bin/env bash
# The paper's experiment, run by run (docs/results.md, "Status of the runs"): train each run with the cpu preset,
# evaluate and diagnose it with the paper's protocol (scripts/experiment_tables.py --run-missing: `morfic reproduce
# --preset cpu`'s steps for this run, skipped where the store holds them, its critic scored on the frozen film actor's
# rollouts, evaluated and diagnosed at 1.0 m/s too), copy its result tables under docs/results/, regenerate
# docs/results.md's tables, claims and figures (scripts/results_tables.py) and ship it as a results-only bundle
# (artifacts/bundles/results/<run>.tar: its evals' and diagnoses' tables without weights, logs, rendered figures or
# other runs' curves; `morfic store import` it, then `morfic report runs/<run>`, which draws the figures) and a
# weights-only one (~7 MiB: import it on top to evaluate or diagnose the run again): a seed-0 run's at
# artifacts/bundles/<run>.tar (what `reproduce --preset shipped` imports), any other seed's at
# artifacts/bundles/weights/<run>.tar.
#
# Usage: scripts/experiment_queue.sh [--stop-at HH:MM] [--last-start HH:MM] [--train-at COMMIT] VARIANT:SEED ...
#   e.g.  MORFIC_STORE=/work/stores/exp nohup scripts/experiment_queue.sh --stop-at 23:05 concat:0 actor-only:0 \
#           > queue.log 2>&1 &
#
# --stop-at (UTC) is for a machine that goes away: at that time a training still running gets Ctrl-C (it finishes
# its iteration and checkpoints), its full bundle (with the trainer state, so `morfic train --resume` continues it
# bit-identically elsewhere) goes to artifacts/bundles/partial/<run>.tar, and the queue stops. Commit what it wrote.
# A Ctrl-C to the training from outside (`kill -INT` of its `morfic train`) does the same: an unfinished run is
# never evaluated or shipped.
# --last-start (UTC): no training starts (or resumes) at or after that time; the queue stops there instead, so a
# run that could not finish before --stop-at is not begun (its partial bundle, ~25 MiB with the trainer state, would
# stay in git history). A finished run is still evaluated and shipped.
# --train-at COMMIT: train with the training code of COMMIT (a git worktree of it under .train-worktrees/, put first
# on PYTHONPATH; the run records that commit as meta.git_commit) and evaluate, diagnose and ship with this checkout's.
# For seeds added to an experiment whose training code has since changed (docs/results.md, "One code for all runs").
# Runs are done strictly one after another: two CPU-heavy jobs on 2 cores slow each other. Two queues may run side by
# side (each with its own store, from one checkout): their trainings share the cores well (1.3-1.4x the throughput
# of one, docs/results.md "Retrained seeds"), their evaluations do not (4-5x slower each), and both write
# docs/results/ and docs/results.md. So a run's evaluation-to-shipping stage holds an exclusive lock
# (flock on $MORFIC_QUEUE_LOCK, default ${TMPDIR:-/tmp}/morfic-experiment-queue.lock): a second queue waits there.
set -euo pipefail
cd "$(dirname "$0")/.."
STOP_AT=""
LAST_START=""
TRAIN_AT=""
while [ $# -gt 0 ]; do
  case "$1" in
    --stop-at) STOP_AT=${2:?--stop-at takes a time HH:MM (UTC)}; shift 2 ;;
    --last-start) LAST_START=${2:?--last-start takes a time HH:MM (UTC)}; shift 2 ;;
    --train-at) TRAIN_AT=${2:?--train-at takes a commit}; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    -*) echo "Error: unknown option '$1'; see scripts/experiment_queue.sh --help" >&2; exit 1 ;;
    *) break ;;
  esac
done
declare -A DAY_SHIFT=()
for t in "$STOP_AT" "$LAST_START"; do
  [ -n "$t" ] || continue
  at=$(date -u -d "$t" +%s 2>/dev/null) || { echo "Error: '$t' is not a time; give HH:MM (UTC)" >&2; exit 1; }
  # a time more than 12 h before the queue starts means tomorrow (a session that crosses midnight UTC)
  if [ $(( $(date -u +%s) - at )) -gt 43200 ]; then DAY_SHIFT["$t"]=86400; else DAY_SHIFT["$t"]=0; fi
done
[ $# -gt 0 ] || { echo "Error: name at least one run as VARIANT:SEED, e.g. concat:0" >&2; exit 1; }
[ -n "${MORFIC_STORE:-}" ] || { echo "Error: set MORFIC_STORE to the experiment store (kept between runs)" >&2; exit 1; }
TRAIN_ENV=()
if [ -n "$TRAIN_AT" ]; then
  commit=$(git rev-parse --verify --quiet "$TRAIN_AT^{commit}") \
    || { echo "Error: --train-at '$TRAIN_AT' is not a commit of this repository; give a hash or tag (git log)" >&2; exit 1; }
  tree=".train-worktrees/${commit:0:12}"
  [ -d "$tree" ] || git worktree add --detach "$tree" "$commit" >/dev/null
  TRAIN_ENV=(env "PYTHONPATH=$PWD/$tree${PYTHONPATH:+:$PYTHONPATH}")
  echo "== training code: $commit ($tree); evaluation code: $(git rev-parse HEAD)"
fi
RESULTS=docs/results
BUNDLES=artifacts/bundles
LOCK=${MORFIC_QUEUE_LOCK:-${TMPDIR:-/tmp}/morfic-experiment-queue.lock}
exec 9>>"$LOCK" || { echo "Error: cannot open the queue lock $LOCK; set MORFIC_QUEUE_LOCK to a writable file" >&2; exit 1; }
mkdir -p "$RESULTS" "$BUNDLES" "$BUNDLES/partial" "$BUNDLES/results" "$BUNDLES/weights"

run_state() {  # what the store holds of runs/$1: missing, unfinished, finished, or results-only (finished, no weights)
  local doc
  doc=$(morfic store show "runs/$1" -f json 2>/dev/null) || { echo missing; return; }
  python3 -c "import json,sys; d=json.loads(sys.argv[1]); done=d['meta'].get('finished')
print('unfinished' if not done else 'results-only' if 'model.pt' in d.get('omitted_files', {}) else 'finished')" "$doc"
}

seconds_until() {  # seconds until the next time $1 (UTC; past midnight when the queue starts late), or a large number when $1 is empty
  [ -n "$1" ] || { echo 999999; return; }
  echo $(( $(date -u -d "$1" +%s) + DAY_SHIFT["$1"] - $(date -u +%s) ))
}
seconds_left() { seconds_until "$STOP_AT"; }

export_partial() {  # an unfinished run's full bundle (with its trainer state) under artifacts/bundles/partial/
  morfic store export "runs/$1" --latest --out artifacts/bundles/partial --force
  echo "== partial run exported: artifacts/bundles/partial/$1.tar (resume: morfic store import it, then" \
       "morfic train --resume runs/$1)"
}

for item in "$@"; do
  [[ "$item" =~ ^[a-z][a-z0-9_-]*:[0-9]+$ ]] || { echo "Error: '$item' is not VARIANT:SEED (e.g. concat:1)" >&2; exit 1; }
done
for item in "$@"; do
  name="${item%:*}-cpu-s${item#*:}"
  if [ "$(run_state "$name")" = results-only ]; then
    echo "Error: runs/$name in $MORFIC_STORE was imported from a results-only bundle (no weights): the queue can" \
         "neither train nor evaluate it. To retrain it, use a store without $BUNDLES/results/$name.tar" \
         "(docs/results.md, \"Retrained seeds\"); to evaluate it again, import its weights bundle" \
         "($BUNDLES/weights/$name.tar) and run scripts/experiment_tables.py $name --run-missing" >&2
    exit 1
  fi
done
for item in "$@"; do
  variant=${item%:*}; seed=${item#*:}; name="$variant-cpu-s$seed"
  if [ "$(seconds_left)" -le 0 ]; then echo "== $(date -u +%T) stop time reached before $name"; exit 0; fi
  state=$(run_state "$name")
  if [ "$state" != finished ]; then
    if [ "$(seconds_until "$LAST_START")" -le 0 ]; then
      echo "== $(date -u +%T) last start time $LAST_START passed: $name is not begun; the queue stops"; exit 0
    fi
    if [ "$state" = unfinished ]; then
      args=(--resume "runs/$name")
    else
      args=(--variant "$variant" --preset cpu --seed "$seed" --name "$name")
    fi
    echo "== $(date -u +%T) train $name (${args[*]})"
    "${TRAIN_ENV[@]}" morfic train "${args[@]}" -q & pid=$!
    while kill -0 "$pid" 2>/dev/null; do
      if [ "$(seconds_left)" -le 0 ]; then
        echo "== $(date -u +%T) stop time: Ctrl-C to $name, it checkpoints"
        kill -INT "$pid"; wait "$pid" || true
        export_partial "$name"
        exit 0
      fi
      sleep "${MORFIC_QUEUE_POLL_S:-20}"  # how often the stop time is checked (tests poll faster)
    done
    wait "$pid"
    if [ "$(run_state "$name")" != finished ]; then  # a Ctrl-C from outside: it checkpointed and exited 0
      echo "== $(date -u +%T) $name stopped before its last iteration: not evaluated; the queue stops"
      export_partial "$name"
      exit 0
    fi
  fi
  if ! flock -n 9; then
    echo "== $(date -u +%T) $name waits for another queue's evaluation (lock $LOCK)"
    flock 9
  fi
  echo "== $(date -u +%T) evaluate and diagnose $name"
  # through a temporary file: a failed eval leaves the last walk.json as it was (and no temporary file)
  morfic eval "runs/$name" --robots go2 --command-vx 1.0 --envs 16 --steps 250 -f json -q > "$RESULTS/$name-walk.json.tmp" \
    || { rm -f "$RESULTS/$name-walk.json.tmp"; exit 1; }
  mv "$RESULTS/$name-walk.json.tmp" "$RESULTS/$name-walk.json"
  # the paper's protocol for this run alone (`morfic reproduce --preset cpu`'s configs; the variant's other seeds are
  # not re-evaluated), its critic scored on the frozen film actor's rollouts, the tables copied with their ids
  python scripts/experiment_tables.py "$name" --run-missing --out "$RESULTS"
  # seed 0's weights go where `reproduce --preset shipped` imports them, other seeds' under weights/
  weights_dir="$BUNDLES/weights"; [ "$seed" = 0 ] && weights_dir="$BUNDLES"
  shipped="$BUNDLES/results/$name.tar and $weights_dir/$name.tar"
  morfic store export "runs/$name" --results-only --out "$BUNDLES/results" --force
  morfic store export "runs/$name" --latest --without-trainer-state --out "$weights_dir" --force
  rm -f "$BUNDLES/partial/$name.tar"
  # after the export, so that the generated bundle weight counts this run's bundle
  python scripts/results_tables.py --write docs/results.md --figures docs/img
  echo "== $(date -u +%T) done $name: $RESULTS/$name-{walk.json,eval.csv,eval-1.0.csv,calibration.csv," \
       "calibration-1.0.csv,curve.csv,artifacts.json}," \
       "docs/results.md's tables and claims, docs/img/results-*.png and $shipped"
  flock -u 9
done
