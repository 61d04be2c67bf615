#!/usr/bin/env bash
# Compare sodyn with Pinocchio 4.1.0 (../shared/peer/pin_bench.cpp, the `pin_bench_native` build)
# on every robot of ../shared/models, interleaved and pinned to one core.
#
#   scripts/compare-pinocchio.sh                      # 7 rounds, 1 s per algorithm
#   ROUNDS=3 MAXSEC=0.5 MODELS="panda solo12" scripts/compare-pinocchio.sh
#
# For each round, for each model, for each algorithm pair: `sodyn bench` then
# `pin_bench_native` (A B A B ...; in even rounds Pinocchio first), both with `taskset -c $CPU`, the same options (--name,
# --nstates 1000, --seed, --max-seconds, ITERS) and the same timing method. The ratio sodyn/Pinocchio is computed within each round,
# then summarised as the median over rounds with its min-max spread
# (scripts/compare_pinocchio_table.py), so slow drifts of the shared machine's load cancel.
#
# Environment:
#   ROUNDS      rounds (default 7; at least 3 is advised)
#   MAXSEC      soft cap in seconds of timed wall time per algorithm and run (default 1)
#   ITERS       timed calls wanted per algorithm (default 20000; capped by MAXSEC)
#   CPU         core to pin to (default 1); empty disables pinning
#   MODELS      space-separated subset of the model names below (default: all)
#   SHARED      the shared directory (default: ../shared next to the repository)
#   PEER_VENV   Pinocchio venv (default /tmp/peer/venv)
#   PEER_BUILD  where pin_bench_native is (default /tmp/peer/build)
#   SODYN       the sodyn binary to time (default: target/release/sodyn, built first); given,
#               nothing is built (to compare two builds one right after the other)
#   OUT         directory for raw outputs and the table (default /tmp/sodyn-compare-<date>)
#   PNG         chart of the ratios to write (default: none; matplotlib is installed into
#               PEER_VENV if missing)
#   COMPARE     0 skips the comparison (default 1)
#   SCALING     1 also measures the 1 -> 2 thread scaling of the batched API (sodyn only,
#               not pinned, SCALING_ROUNDS runs (default ROUNDS) on SCALING_MODELS, default
#               "solo12 talos_full_v2", each alternating blocks of about 5 ms of
#               back-to-back 1- and 2-thread batched calls: --paired-threads 2); table in
#               scaling.md. Each round also measures the
#               machine's own 1 -> 2 CPU ceiling: the 1-thread batched calls run alone on CPU 0,
#               then as two independent processes at once (one on each CPU), then alone on CPU
#               1; ceiling = (sum of the two concurrent throughputs) / (mean of the lone ones)
#   SCALING_MAXSEC  soft cap in seconds per algorithm and run of the scaling and ceiling runs
#               (default 2: a round's paired speed-up is then a median over about 50-250 pairs
#               of blocks instead of about 10 with 0.25 s, so a short burst of interference
#               from the host moves it less)
#               Each scaling run is followed by a line "steal model=M pct=P": the steal time
#               of the machine's CPUs during it (/proc/stat), shown in scaling.md; meta.txt
#               gets the same for the comparison rounds.
#   SCALING_PIN 1 (default, with two or more CPUs) also runs each scaling round with the
#               threads pinned (--pin-cpus 0,1: BatchPool::with_cpus); second table
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/.." && pwd)"
SHARED="${SHARED:-$REPO/../shared}"
ROUNDS="${ROUNDS:-7}"
MAXSEC="${MAXSEC:-1}"
ITERS="${ITERS:-20000}"
CPU="${CPU-1}"
SEED="${SEED:-42}"
export PEER_VENV="${PEER_VENV:-/tmp/peer/venv}"
export PEER_BUILD="${PEER_BUILD:-/tmp/peer/build}"
OUT="${OUT:-/tmp/sodyn-compare-$(date +%F)}"
PIN_BIN="$PEER_BUILD/pin_bench_native"
SODYN_GIVEN="${SODYN:-}"
SODYN="${SODYN:-$REPO/target/release/sodyn}"
MODELS_DIR="$SHARED/models"

[ -d "$MODELS_DIR" ] || { echo "models not found: $MODELS_DIR (set SHARED)" >&2; exit 1; }

# 1. The peer benchmark (Pinocchio), built if missing.
if [ ! -x "$PIN_BIN" ]; then
  echo "[compare] $PIN_BIN missing: building it (setup.sh, then build.sh; several minutes)" >&2
  "$SHARED/peer/setup.sh"
  VARIANTS=native "$SHARED/peer/build.sh"
fi

# 2. sodyn, release build.
if [ -z "$SODYN_GIVEN" ]; then
  echo "[compare] cargo build --release" >&2
  (cd "$REPO" && cargo build --release --quiet)
fi
mkdir -p "$OUT"
# Run a private copy: a rebuild in the work tree during the run must not change the binary.
cp "$SODYN" "$OUT/sodyn"
SODYN="$OUT/sodyn"

# The robots timed: MODEL_TABLE (name|base|contact frames).
# shellcheck source=bench-models.sh
source "$HERE/bench-models.sh"
# sodyn algorithm <-> pin_bench algorithm; fd_so has no Pinocchio counterpart (timed against
# our own id_so, in one process: bench --ratio-to id_so).
PAIRS="rnea:rnea crba:crba aba:aba id_fo:computeRNEADerivatives fd_fo:computeABADerivatives
id_so:ComputeRNEASecondOrderDerivatives"
SODYN_ONLY="fd_so"
# With contacts (3-D point contacts at the frame origins; Pinocchio LOCAL 3-D contacts; our
# derivative timings include the forward solve, Pinocchio's forward call runs untimed).
CONTACT_PAIRS="kkt_fo:computeConstraintDynamicsDerivatives impact_fo:computeImpulseDynamicsDerivatives"
CONTACT_SODYN_ONLY="kkt_so,impact_so"

PIN=()
if [ -n "$CPU" ] && command -v taskset >/dev/null; then PIN=(taskset -c "$CPU"); fi

mkdir -p "$OUT"
META="$OUT/meta.txt"
{
  echo "# sodyn vs Pinocchio $(date -u +%FT%TZ)"
  echo "# cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //') ; nproc=$(nproc) ; pinned_to=${CPU:-none}"
  echo "# kernel: $(uname -r) ; loadavg at start: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# sodyn: $(cd "$REPO" && git rev-parse --short HEAD 2>/dev/null || echo '?')$(cd "$REPO" && git diff --quiet 2>/dev/null || echo ' (with uncommitted changes)') ; $(rustc --version)"
  echo "# pinocchio: pin_bench_native ($PIN_BIN)"
  echo "# ROUNDS=$ROUNDS MAXSEC=$MAXSEC ITERS=$ITERS SEED=$SEED"
} > "$META"
cat "$META" >&2

# Steal ticks and all ticks of the machine's CPUs so far (/proc/stat, Linux; "0 0" elsewhere):
# the time the host ran something else while a virtual CPU had work.
cpu_ticks() {
  awk '/^cpu /{t = 0; for (i = 2; i <= NF; i++) t += $i; print $9 + 0, t; found = 1}
       END {if (!found) print 0, 0}' /proc/stat 2>/dev/null || echo "0 0"
}
# Percentage of steal between two cpu_ticks readings "$1" and "$2".
steal_pct() {
  awk -v a="$1" -v b="$2" 'BEGIN {split(a, x, " "); split(b, y, " ");
    d = y[2] - x[2]; if (d > 0) printf "%.2f", 100 * (y[1] - x[1]) / d; else printf "nan"}'
}
RUN_T0="$(cpu_ticks)"

# One algorithm pair of round $r: sodyn first in odd rounds, Pinocchio first in even ones, so
# that whatever favours the first (or second) run of a pair falls on both programs equally.
run_pair() {
  if [ $((r % 2)) = 1 ]; then
    "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$1" >> "$S"
    "${PIN[@]}" "$PIN_BIN" "${pargs[@]}" --algos "$2" >> "$P"
  else
    "${PIN[@]}" "$PIN_BIN" "${pargs[@]}" --algos "$2" >> "$P"
    "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$1" >> "$S"
  fi
}

for r in $(seq 1 "$ROUNDS"); do
  [ "${COMPARE:-1}" = 0 ] && break
  S="$OUT/sodyn-round$r.txt"
  P="$OUT/pin-round$r.txt"
  : > "$S"
  : > "$P"
  echo "# loadavg at start of round $r: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"
  while IFS='|' read -r name base contacts; do
    [ -z "$name" ] && continue
    if [ -n "${MODELS:-}" ] && ! [[ " $MODELS " == *" $name "* ]]; then continue; fi
    urdf="$MODELS_DIR/$name.urdf"
    sargs=(bench --model "$urdf" --name "$name" --states 1000
           --seed "$SEED" --max-seconds "$MAXSEC" --iters "$ITERS")
    pargs=("$urdf" "$base" "$ITERS" --name "$name" --nstates 1000
           --seed "$SEED" --max-seconds "$MAXSEC")
    if [ "$base" = ff ]; then sargs+=(--floating-base); fi
    if [ -n "$contacts" ]; then sargs+=(--contacts "$contacts"); pargs+=(--contacts "$contacts"); fi
    # Interleaved per algorithm pair: the two runs of a pair are seconds apart.
    for pair in $PAIRS; do
      sa="${pair%%:*}"; pa="${pair#*:}"
      echo "[compare] round $r/$ROUNDS $name: sodyn $sa, pinocchio $pa" >&2
      run_pair "$sa" "$pa"
    done
    if [ -n "$contacts" ]; then
      for pair in $CONTACT_PAIRS; do
        sa="${pair%%:*}"; pa="${pair#*:}"
        echo "[compare] round $r/$ROUNDS $name: sodyn $sa, pinocchio $pa" >&2
        run_pair "$sa" "$pa"
      done
    fi
    # fd_so against id_so in one process, in alternating blocks (the paired fd_so / id_so).
    echo "[compare] round $r/$ROUNDS $name: sodyn $SODYN_ONLY against id_so" >&2
    "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$SODYN_ONLY" --ratio-to id_so >> "$S"
    if [ -n "$contacts" ]; then
      echo "[compare] round $r/$ROUNDS $name: sodyn $CONTACT_SODYN_ONLY" >&2
      "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$CONTACT_SODYN_ONLY" >> "$S"
    fi
  done <<< "$MODEL_TABLE"
done
echo "# loadavg at end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"
echo "# steal during the comparison rounds: $(steal_pct "$RUN_T0" "$(cpu_ticks)") % of the CPUs' time" >> "$META"

# 3. Optional: thread scaling of the batched API (both cores, so not pinned).
if [ "${SCALING:-0}" = 1 ]; then
  SMAXSEC="${SCALING_MAXSEC:-2}"
  echo "# SCALING_ROUNDS=${SCALING_ROUNDS:-$ROUNDS} SCALING_MAXSEC=$SMAXSEC" >> "$META"
  for r in $(seq 1 "${SCALING_ROUNDS:-$ROUNDS}"); do
    F="$OUT/scaling-round$r.txt"
    FP="$OUT/scaling-pinned-round$r.txt"
    : > "$F"
    if [ "$(nproc)" -ge 2 ] && [ "${SCALING_PIN:-1}" = 1 ]; then : > "$FP"; fi
    for name in ${SCALING_MODELS:-solo12 talos_full_v2}; do
      base="$(grep "^$name|" <<< "$MODEL_TABLE" | cut -d'|' -f2)"
      fb=(); [ "$base" = ff ] && fb=(--floating-base)
      # The batched calls on 1 and 2 threads alternate within one run (--paired-threads), so
      # each pair of consecutive calls sees the same machine state.
      echo "[compare] scaling round $r/${SCALING_ROUNDS:-$ROUNDS} $name threads=1,2 paired" >&2
      echo "# loadavg=$(cut -d' ' -f1 /proc/loadavg)" >> "$F"
      t0="$(cpu_ticks)"
      "$SODYN" bench --model "$MODELS_DIR/$name.urdf" "${fb[@]}" --name "$name" \
        --paired-threads 2 --algos rnea,id_fo,fd_fo,batch_rnea,batch_id_fo,batch_fd_fo \
        --max-seconds "$SMAXSEC" --seed "$SEED" >> "$F"
      echo "steal model=$name pct=$(steal_pct "$t0" "$(cpu_ticks)")" >> "$F"
      # The same with the threads pinned: the caller to CPU 0, the helper to CPU 1.
      if [ "$(nproc)" -ge 2 ] && [ "${SCALING_PIN:-1}" = 1 ]; then
        echo "[compare] scaling round $r/${SCALING_ROUNDS:-$ROUNDS} $name threads=1,2 paired, pinned" >&2
        t0="$(cpu_ticks)"
        "$SODYN" bench --model "$MODELS_DIR/$name.urdf" "${fb[@]}" --name "$name" \
          --paired-threads 2 --pin-cpus 0,1 --algos rnea,id_fo,fd_fo,batch_rnea,batch_id_fo,batch_fd_fo \
          --max-seconds "$SMAXSEC" --seed "$SEED" >> "$FP"
        echo "steal model=$name pct=$(steal_pct "$t0" "$(cpu_ticks)")" >> "$FP"
      fi
      # The ceiling: two independent single-threaded processes, one per CPU.
      if command -v taskset >/dev/null && [ "$(nproc)" -ge 2 ]; then
        C="$OUT/ceiling-round$r.txt"
        one=("$SODYN" bench --model "$MODELS_DIR/$name.urdf" "${fb[@]}" --name "$name" \
          --threads 1 --algos batch_rnea,batch_id_fo,batch_fd_fo --max-seconds "$SMAXSEC" \
          --seed "$SEED")
        taskset -c 0 "${one[@]}" | sed 's/^model=/run=alone0 model=/' >> "$C"
        taskset -c 0 "${one[@]}" > "$OUT/.t0" & taskset -c 1 "${one[@]}" > "$OUT/.t1"; wait
        sed 's/^model=/run=together0 model=/' "$OUT/.t0" >> "$C"
        sed 's/^model=/run=together1 model=/' "$OUT/.t1" >> "$C"
        taskset -c 1 "${one[@]}" | sed 's/^model=/run=alone1 model=/' >> "$C"
        rm -f "$OUT/.t0" "$OUT/.t1"
      fi
    done
  done
  python3 "$HERE/compare_pinocchio_table.py" --scaling "$OUT" | tee "$OUT/scaling.md"
fi
[ "${COMPARE:-1}" = 0 ] && exit 0

# 4. Table (and chart).
PY=python3
TABLE_ARGS=("$OUT")
if [ -n "${PNG:-}" ]; then
  PY="$PEER_VENV/bin/python"
  TABLE_ARGS+=(--png "$PNG")
  "$PY" -c "import matplotlib" 2>/dev/null || "$PEER_VENV/bin/pip" install --quiet matplotlib
fi
"$PY" "$HERE/compare_pinocchio_table.py" "${TABLE_ARGS[@]}" | tee "$OUT/table.md"
echo "[compare] raw outputs and table.md in $OUT" >&2
