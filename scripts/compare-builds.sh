#!/usr/bin/env bash
# Compare two builds of sodyn with each other: the speed of NEW against OLD, algorithm by
# algorithm on the robots of compare-pinocchio.sh, interleaved and pinned to one core.
#
#   scripts/compare-builds.sh OLD [NEW]                # two git revisions; NEW defaults to HEAD
#   scripts/compare-builds.sh 293cc5a .                # "." = the work tree, uncommitted changes included
#   ROUNDS=3 MAXSEC=0.2 MODELS="panda solo12" scripts/compare-builds.sh 293cc5a
#   OLD_BIN=/tmp/a/sodyn NEW_BIN=target/release/sodyn scripts/compare-builds.sh   # two binaries
#
# Each revision is checked out in a detached git worktree under /tmp (removed afterwards) and
# built with `cargo build --release --bin sodyn`, both into one target directory so that the
# dependencies are compiled once (a commit built before is not built again: TARGET_DIR). The
# binaries are copied into OUT and run from there.
#
# For each round, for each model, for each algorithm: `sodyn bench --algos A` of one binary
# right after the other's (old first in odd rounds, new first in even ones), both with
# `taskset -c $CPU` and the options of compare-pinocchio.sh (--name, --states 1000, --seed,
# --max-seconds, --iters). The quotient new/old of the two median times is taken within each
# round, so that the shared machine's drifts and speed states cancel; scripts/compare_builds_table.py
# then prints, per model and algorithm, the median of the per-round quotients, and per algorithm
# and overall the median of those cells (below 1: the new build is faster).
#
# Environment:
#   ROUNDS      rounds (default 5; at least 3 is advised)
#   MAXSEC      soft cap in seconds of timed wall time per algorithm and run (default 0.25)
#   ITERS       timed calls wanted per algorithm (default 20000; capped by MAXSEC)
#   CPU         core to pin to (default 1); empty disables pinning
#   MODELS      space-separated subset of the model names of scripts/bench-models.sh (default: all)
#   ALGOS       algorithms timed on every model (default "rnea crba aba id_fo fd_fo id_so fd_so";
#               empty: none)
#   CONTACT_ALGOS  algorithms timed on the models with contact frames, with --contacts
#               (default "kkt_fo impact_fo kkt_so impact_so"; empty: none)
#   BENCH_ARGS  further options of both `sodyn bench` runs (e.g. "--simd avx2")
#   SHARED      the shared directory (default: ../shared next to the repository)
#   OLD_BIN, NEW_BIN  binaries to time instead of building OLD, NEW
#   TARGET_DIR  cargo target directory of the builds (default target/compare-builds: the first
#               run compiles the dependencies there); TARGET_DIR/by-commit/<hash>/sodyn keeps
#               each commit's binary, which later runs reuse instead of building
#   WORKTREES   where the worktrees go (default /tmp); KEEP_WORKTREES=1 keeps them
#   OUT         directory for the binaries, raw outputs and the table
#               (default /tmp/sodyn-builds-<old>-<new>-<date>)
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/.." && pwd)"
SHARED="${SHARED:-$REPO/../shared}"
ROUNDS="${ROUNDS:-5}"
MAXSEC="${MAXSEC:-0.25}"
ITERS="${ITERS:-20000}"
CPU="${CPU-1}"
SEED="${SEED:-42}"
ALGOS="${ALGOS-rnea crba aba id_fo fd_fo id_so fd_so}"
CONTACT_ALGOS="${CONTACT_ALGOS-kkt_fo impact_fo kkt_so impact_so}"
TARGET_DIR="${TARGET_DIR:-$REPO/target/compare-builds}"
WORKTREES="${WORKTREES:-/tmp}"
MODELS_DIR="$SHARED/models"
read -r -a EXTRA <<< "${BENCH_ARGS:-}"

usage() { sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
case "${1:-}" in -h|--help) usage ;; esac
[ -d "$MODELS_DIR" ] || { echo "models not found: $MODELS_DIR (set SHARED)" >&2; exit 1; }

OLD="${1:-}"
NEW="${2:-HEAD}"
if [ -z "${OLD_BIN:-}" ] && [ -z "$OLD" ]; then usage; fi

# "<short hash>" of a revision, "<short hash>+dirty" for a work tree with changes.
label() {
  if [ "$1" = . ]; then
    echo "$(git -C "$REPO" rev-parse --short HEAD)$(git -C "$REPO" diff --quiet HEAD || echo +dirty)"
  else
    git -C "$REPO" rev-parse --short "$1^{commit}"
  fi
}
OLD_LABEL="${OLD_BIN:+bin}"; OLD_LABEL="${OLD_LABEL:-$(label "$OLD")}"
NEW_LABEL="${NEW_BIN:+bin}"; NEW_LABEL="${NEW_LABEL:-$(label "$NEW")}"
OUT="${OUT:-/tmp/sodyn-builds-$OLD_LABEL-$NEW_LABEL-$(date +%F)}"
mkdir -p "$OUT"

ADDED=()
cleanup() {
  if [ "${KEEP_WORKTREES:-0}" != 1 ]; then
    for d in "${ADDED[@]}"; do git -C "$REPO" worktree remove --force "$d" || true; done
  fi
}
trap cleanup EXIT

# Build revision $1 (or the work tree, ".") and copy its binary to $2. The binary of a commit
# is kept in $TARGET_DIR/by-commit/<hash>/ and reused by later runs: the two revisions share
# the target directory, so cargo rebuilds the sodyn crate at each switch.
build() {
  local rev="$1" dest="$2" src sha=""
  if [ "$rev" = . ]; then
    src="$REPO"
  else
    sha="$(git -C "$REPO" rev-parse "$rev^{commit}")"
    if [ -x "$TARGET_DIR/by-commit/$sha/sodyn" ]; then
      echo "[builds] $(label "$rev"): $TARGET_DIR/by-commit/$sha/sodyn, built before" >&2
      cp "$TARGET_DIR/by-commit/$sha/sodyn" "$dest"
      return
    fi
    src="$WORKTREES/sodyn-rev-${sha:0:12}"
    if [ ! -d "$src" ]; then
      git -C "$REPO" worktree add --detach --quiet "$src" "$sha"
      ADDED+=("$src")
    fi
  fi
  echo "[builds] cargo build --release --bin sodyn in $src ($(label "$rev"))" >&2
  # Removed first: a build that left no binary must fail here, not time the other revision.
  rm -f "$TARGET_DIR/release/sodyn"
  (cd "$src" && CARGO_TARGET_DIR="$TARGET_DIR" cargo build --release --quiet --bin sodyn)
  cp "$TARGET_DIR/release/sodyn" "$dest"
  if [ -n "$sha" ]; then
    mkdir -p "$TARGET_DIR/by-commit/$sha"
    cp "$TARGET_DIR/release/sodyn" "$TARGET_DIR/by-commit/$sha/sodyn"
  fi
}

# The binaries, each a private copy in OUT (a rebuild elsewhere must not change them).
if [ -n "${OLD_BIN:-}" ]; then cp "$OLD_BIN" "$OUT/sodyn-old"; else build "$OLD" "$OUT/sodyn-old"; fi
if [ -n "${NEW_BIN:-}" ]; then cp "$NEW_BIN" "$OUT/sodyn-new"; else build "$NEW" "$OUT/sodyn-new"; fi
BIN_OLD="$OUT/sodyn-old"
BIN_NEW="$OUT/sodyn-new"

# shellcheck source=bench-models.sh
source "$HERE/bench-models.sh"

PIN=()
if [ -n "$CPU" ] && command -v taskset >/dev/null; then PIN=(taskset -c "$CPU"); fi

META="$OUT/meta.txt"
{
  echo "# sodyn $NEW_LABEL (new) against $OLD_LABEL (old) $(date -u +%FT%TZ)"
  echo "# old: ${OLD_BIN:-$OLD} ; new: ${NEW_BIN:-$NEW}"
  echo "# cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //') ; nproc=$(nproc) ; pinned_to=${CPU:-none}"
  echo "# kernel: $(uname -r) ; loadavg at start: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "# ROUNDS=$ROUNDS MAXSEC=$MAXSEC ITERS=$ITERS SEED=$SEED BENCH_ARGS=${BENCH_ARGS:-}"
  echo "# ALGOS=$ALGOS ; CONTACT_ALGOS=$CONTACT_ALGOS"
} > "$META"
cat "$META" >&2

# One algorithm of round $r on both binaries, old first in odd rounds and new first in even
# ones. A run that fails (an algorithm the old build lacks) is noted in meta.txt and skipped.
run_one() {
  local algo="$1" first second
  if [ $((r % 2)) = 1 ]; then first=old; second=new; else first=new; second=old; fi
  for side in "$first" "$second"; do
    local bin="$BIN_OLD"; [ "$side" = new ] && bin="$BIN_NEW"
    "${PIN[@]}" "$bin" "${sargs[@]}" --algos "$algo" >> "$OUT/$side-round$r.txt" 2>> "$OUT/$side.err" \
      || echo "# round $r $name $algo: the $side binary failed (status $?; $OUT/$side.err)" >> "$META"
  done
}

for r in $(seq 1 "$ROUNDS"); do
  : > "$OUT/old-round$r.txt"
  : > "$OUT/new-round$r.txt"
  echo "# loadavg at start of round $r: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"
  while IFS='|' read -r name base contacts; do
    [ -z "$name" ] && continue
    if [ -n "${MODELS:-}" ] && ! [[ " $MODELS " == *" $name "* ]]; then continue; fi
    sargs=(bench --model "$MODELS_DIR/$name.urdf" --name "$name" --states 1000
           --seed "$SEED" --max-seconds "$MAXSEC" --iters "$ITERS" "${EXTRA[@]}")
    if [ "$base" = ff ]; then sargs+=(--floating-base); fi
    algos="$ALGOS"
    if [ -n "$contacts" ]; then sargs+=(--contacts "$contacts"); algos="$algos $CONTACT_ALGOS"; fi
    [ -z "${algos// /}" ] && continue
    echo "[builds] round $r/$ROUNDS $name: $algos" >&2
    for algo in $algos; do run_one "$algo"; done
  done <<< "$MODEL_TABLE"
done
echo "# loadavg at end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$META"

python3 "$HERE/compare_builds_table.py" "$OUT" | tee "$OUT/table.md"
echo "[builds] binaries, raw outputs and table.md in $OUT" >&2
