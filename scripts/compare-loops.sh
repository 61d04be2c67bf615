#!/usr/bin/env bash
# sodyn against Pinocchio 4.1 on constrained dynamics with closed kinematic loops (two-frame
# constraints): scripts/compare_loops.py says what is timed and how.
#
#   scripts/compare-loops.sh [--rounds N] [--max-seconds S]
#
# Environment:
#   PEER_VENV   Pinocchio venv (default /tmp/peer/venv; ../shared/peer/setup.sh makes it)
#   PEER_BUILD  where pin_loop_bench and the Pinocchio twins of the built-ins go (default /tmp/peer/build)
#   PY          a Python with pin==4.1.0 and the sodyn package, to make and check the twins of
#               builtin:fourbar and builtin:delta (scripts/make_pin_loop_models.py)
#   CPU         core to pin to (default 1; empty: no pinning)
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/.." && pwd)"
export PEER_VENV="${PEER_VENV:-/tmp/peer/venv}"
export PEER_BUILD="${PEER_BUILD:-/tmp/peer/build}"
: "${PY:?set PY to a Python with pin==4.1.0 and sodyn installed}"
(cd "$REPO" && cargo build --release --quiet --bin sodyn)
[ -x "$PEER_BUILD/pin_loop_bench" ] || bash "$HERE/build-pin-kin.sh" pin_loop_bench
"$PY" "$HERE/make_pin_loop_models.py" "$PEER_BUILD/loop-models"
exec python3 "$HERE/compare_loops.py" --sodyn "$REPO/target/release/sodyn" \
  --pin "$PEER_BUILD/pin_loop_bench" --pin-models "$PEER_BUILD/loop-models" \
  --models "$REPO/../shared/models" --cpu "${CPU-1}" "$@"
