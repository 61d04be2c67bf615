#!/usr/bin/env bash
# Build scripts/pin_kin_bench.cpp (Pinocchio 4.1 kinematics timings), or another harness of
# scripts/ (pin_loop_bench: the constrained dynamics with loops), against the headers and
# shared libraries of the PyPI wheels in $PEER_VENV, with the flags of ../shared/peer/build.sh
# (its `native` variant: Pinocchio's templates instantiated here, -O3 -march=native).
#
#   scripts/build-pin-kin.sh                   # -> $PEER_BUILD/pin_kin_bench (default /tmp/peer/build)
#   scripts/build-pin-kin.sh pin_loop_bench    # -> $PEER_BUILD/pin_loop_bench
#
# As build.sh explains: the wheel's libraries are built without AVX, so Eigen's alignment there
# is 16 bytes and its aligned_malloc is plain malloc; a Model filled inside libpinocchio_parsers
# and freed here must agree, hence EIGEN_MAX_ALIGN_BYTES=16, EIGEN_MAX_STATIC_ALIGN_BYTES=16 and
# EIGEN_MALLOC_ALREADY_ALIGNED=1 (AVX/FMA code is still generated, with unaligned loads).
# The other defines mirror lib/cmake/pinocchio/pinocchioTargets.cmake. A few minutes on 2 cores.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
PEER_VENV="${PEER_VENV:-/tmp/peer/venv}"
OUT_DIR="${PEER_BUILD:-/tmp/peer/build}"
CXX="${CXX:-g++}"
NAME="${1:-pin_kin_bench}"
[ -f "$HERE/$NAME.cpp" ] || { echo "no $HERE/$NAME.cpp" >&2; exit 1; }

PY="$PEER_VENV/bin/python"
SITE="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
PREFIX="$SITE/cmeel.prefix"
LIB="$PREFIX/lib"
INC="$PREFIX/include"
[ -f "$INC/pinocchio/config.hpp" ] || { echo "pinocchio headers not found in $INC (../shared/peer/setup.sh)" >&2; exit 1; }
if [ -f "$INC/eigen3/Eigen/Core" ]; then
  EIGEN_INC="$INC/eigen3"
elif [ -f /usr/include/eigen3/Eigen/Core ]; then
  EIGEN_INC=/usr/include/eigen3
else
  echo "Eigen headers not found (../shared/peer/setup.sh)" >&2; exit 1
fi
[ -f "$INC/urdfdom_headers/urdf_model/model.h" ] || { echo "urdfdom_headers missing (../shared/peer/setup.sh)" >&2; exit 1; }

INCLUDES=(
  -I"$INC" -I"$INC/pinocchio/deprecated" -I"$EIGEN_INC"
  -I"$INC/urdfdom" -I"$INC/urdfdom_headers"
)
DEFINES=(
  -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30
  -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_FUSION_INVOKE_MAX_ARITY=12
  -DPINOCCHIO_WITH_COLLISION
  -DCOAL_BACKWARD_COMPATIBILITY_WITH_HPP_FCL -DCOAL_HAS_OCTOMAP -DCOAL_HAVE_OCTOMAP
  -DOCTOMAP_MAJOR_VERSION=1 -DOCTOMAP_MINOR_VERSION=10 -DOCTOMAP_PATCH_VERSION=0
  -DPINOCCHIO_WITH_URDFDOM -DPINOCCHIO_URDFDOM_HEADERS_MAJOR_VERSION=3
  -DPINOCCHIO_URDFDOM_HEADERS_MINOR_VERSION=0 -DPINOCCHIO_URDFDOM_HEADERS_PATCH_VERSION=0
  -DEIGEN_MAX_ALIGN_BYTES=16 -DEIGEN_MAX_STATIC_ALIGN_BYTES=16 -DEIGEN_MALLOC_ALREADY_ALIGNED=1
)
OPT=(-std=c++17 -O3 -march=native -DNDEBUG -w)
LINK=(
  -L"$LIB" -Wl,-rpath,"$LIB"
  -lpinocchio_parsers -lpinocchio_default
  -lurdfdom_model -lboost_filesystem -lboost_serialization
)
mkdir -p "$OUT_DIR"
echo "building $OUT_DIR/$NAME ..." >&2
"$CXX" "${OPT[@]}" "${DEFINES[@]}" "${INCLUDES[@]}" "$HERE/$NAME.cpp" \
  -o "$OUT_DIR/$NAME.tmp" "${LINK[@]}"
mv "$OUT_DIR/$NAME.tmp" "$OUT_DIR/$NAME"
echo "done: $OUT_DIR/$NAME" >&2
