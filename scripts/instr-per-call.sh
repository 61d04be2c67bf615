#!/usr/bin/env bash
# Instructions per call of sodyn algorithms, by callgrind (repeatable on a loaded machine):
#   scripts/instr-per-call.sh MODEL_SPEC "algo1 algo2" [extra bench options...]
# e.g. scripts/instr-per-call.sh ../shared/models/talos_full_v2.urdf "crba id_fo" --floating-base
# Runs `sodyn bench --calls N` for N = 0 and N = $CALLS (default 200) and prints the difference / N.
set -euo pipefail
SPEC="$1"; ALGOS="$2"; shift 2
BIN="${SODYN_BIN:-$(cd "$(dirname "$0")/.." && pwd)/target/release/sodyn}"
CALLS="${CALLS:-200}"
count() {
  valgrind --tool=callgrind --callgrind-out-file=/dev/null "$BIN" bench --model "$SPEC" \
    --algos "$1" --states 50 --calls "$2" "${@:3}" 2>&1 >/dev/null | sed -n 's/.*Collected : //p'
}
for a in $ALGOS; do
  c0=$(count "$a" 0 "$@"); c1=$(count "$a" "$CALLS" "$@")
  echo "algo=$a instr_per_call=$(( (c1 - c0) / CALLS ))"
done
