#!/usr/bin/env bash
# Kinematics for costs (frames, centre of mass, centroidal, configuration space): sodyn against
# Pinocchio 4.1.0 (scripts/pin_kin_bench.cpp, built by scripts/build-pin-kin.sh if missing),
# both in compiled code, interleaved and pinned to one core. The method is that of
# scripts/compare-pinocchio.sh: for each round, model and function, `sodyn bench --algos F`
# then `pin_kin_bench --algos F` (Pinocchio first in even rounds), both with `taskset -c $CPU`,
# the same --name, --nstates/--states 1000, --seed, --max-seconds, ITERS and --frame; the ratio
# sodyn / Pinocchio is taken within each round, then its median and min-max over the rounds
# (scripts/compare_kinematics_table.py). Both programs use the same algorithm names
# (pin_kin_bench.cpp's header lists the Pinocchio calls behind each).
#
#   scripts/compare-kinematics.sh                      # 5 rounds, 0.5 s per function
#   ROUNDS=3 MODELS="panda solo12" ALGOS="com,com_jacobian" scripts/compare-kinematics.sh
#
# Environment: ROUNDS (default 5), MAXSEC (0.5), ITERS (20000), CPU (1; empty: no pinning),
# SEED (42), MODELS (subset of the table below), ALGOS (comma-separated subset), SHARED
# (../shared), PEER_VENV (/tmp/peer/venv), PEER_BUILD (/tmp/peer/build), SODYN (default:
# target/release/sodyn, built first), OUT (/tmp/sodyn-kin-<date>).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/.." && pwd)"
SHARED="${SHARED:-$REPO/../shared}"
ROUNDS="${ROUNDS:-5}"
MAXSEC="${MAXSEC:-0.5}"
ITERS="${ITERS:-20000}"
CPU="${CPU-1}"
SEED="${SEED:-42}"
export PEER_VENV="${PEER_VENV:-/tmp/peer/venv}"
export PEER_BUILD="${PEER_BUILD:-/tmp/peer/build}"
OUT="${OUT:-/tmp/sodyn-kin-$(date +%F)}"
PIN_BIN="$PEER_BUILD/pin_kin_bench"
SODYN_GIVEN="${SODYN:-}"
SODYN="${SODYN:-$REPO/target/release/sodyn}"
MODELS_DIR="$SHARED/models"
[ -d "$MODELS_DIR" ] || { echo "models not found: $MODELS_DIR (set SHARED)" >&2; exit 1; }

if [ ! -x "$PIN_BIN" ]; then
  echo "[kin] $PIN_BIN missing: building it (several minutes)" >&2
  "$HERE/build-pin-kin.sh"
fi
if [ -z "$SODYN_GIVEN" ]; then
  echo "[kin] cargo build --release" >&2
  (cd "$REPO" && cargo build --release --quiet)
fi
mkdir -p "$OUT"
cp "$SODYN" "$OUT/sodyn"
SODYN="$OUT/sodyn"

# name | base | frame
MODEL_TABLE="
panda|fixed|panda_hand
solo12|ff|FL_FOOT
talos_full_v2|ff|left_sole_link
"
# Every function with a Pinocchio counterpart (same name on both sides).
DEFAULT_ALGOS="frame_placement,frame_jacobian_local,frame_jacobian_world,frame_jacobian_lwa,\
frame_velocity,frame_acceleration,frame_classical_acceleration,frame_velocity_derivatives,\
frame_velocity_derivatives_world,frame_acceleration_derivatives,\
frame_acceleration_derivatives_world,com,com_jacobian,com_velocity_derivatives,\
centroidal_momentum,centroidal_dynamics_derivatives,difference,d_integrate_q,d_integrate_v,\
d_difference_q0,d_difference_q1"
ALGOS="${ALGOS:-$DEFAULT_ALGOS}"

PIN=()
if [ -n "$CPU" ] && command -v taskset >/dev/null; then PIN=(taskset -c "$CPU"); fi
META="$OUT/meta.txt"
{
  echo "# sodyn vs Pinocchio, kinematics $(date -u +%FT%TZ)"
  echo "# cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //') ; nproc=$(nproc) ; pinned_to=${CPU:-none}"
  echo "# sodyn: $(cd "$REPO" && git rev-parse --short HEAD 2>/dev/null || echo '?')$(cd "$REPO" && git diff --quiet 2>/dev/null || echo ' (with uncommitted changes)') ; $(rustc --version)"
  echo "# pinocchio: $PIN_BIN"
  echo "# ROUNDS=$ROUNDS MAXSEC=$MAXSEC ITERS=$ITERS SEED=$SEED"
} > "$META"
cat "$META" >&2

for r in $(seq 1 "$ROUNDS"); do
  S="$OUT/sodyn-round$r.txt"
  P="$OUT/pin-round$r.txt"
  : > "$S"
  : > "$P"
  echo "# loadavg at start of round $r: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"
  while IFS='|' read -r name base frame; do
    [ -z "$name" ] && continue
    if [ -n "${MODELS:-}" ] && ! [[ " $MODELS " == *" $name "* ]]; then continue; fi
    urdf="$MODELS_DIR/$name.urdf"
    sargs=(bench --model "$urdf" --name "$name" --states 1000 --seed "$SEED"
           --max-seconds "$MAXSEC" --iters "$ITERS" --frame "$frame")
    pargs=("$urdf" "$base" "$ITERS" --name "$name" --nstates 1000 --seed "$SEED"
           --max-seconds "$MAXSEC" --frame "$frame")
    if [ "$base" = ff ]; then sargs+=(--floating-base); fi
    for a in ${ALGOS//,/ }; do
      echo "[kin] round $r/$ROUNDS $name: $a" >&2
      if [ $((r % 2)) = 1 ]; then
        "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$a" >> "$S"
        "${PIN[@]}" "$PIN_BIN" "${pargs[@]}" --algos "$a" >> "$P"
      else
        "${PIN[@]}" "$PIN_BIN" "${pargs[@]}" --algos "$a" >> "$P"
        "${PIN[@]}" "$SODYN" "${sargs[@]}" --algos "$a" >> "$S"
      fi
    done
  done <<< "$MODEL_TABLE"
done
echo "# loadavg at end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"
python3 "$HERE/compare_kinematics_table.py" "$OUT" | tee "$OUT/table.md"
echo "[kin] raw outputs and table.md in $OUT" >&2
