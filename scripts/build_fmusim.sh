#!/bin/sh
# Build fmusim, the simulator of the Modelica Reference-FMUs, with gcc against Debian packages.
#
#   scripts/build_fmusim.sh SRC_DIR OUT_DIR        -> OUT_DIR/fmusim
#
# SRC_DIR holds the folders fmusim/, include/ and src/ of the Reference-FMUs at a version that
# still ships fmusim; v0.0.39 (commit c8d4e6d90fa14be49d7622badf30e38eebea5e0a) was used:
#
#   git clone https://github.com/modelica/Reference-FMUs && cd Reference-FMUs
#   git archive v0.0.39 fmusim include src LICENSE.txt | tar -x -C SRC_DIR
#   echo v0.0.39 > SRC_DIR/VERSION            # optional: what `fmusim --version` prints
#
# Needs gcc and (Debian 12 names; SUNDIALS 6.4 there, fmusim was written for 7):
#
#   apt-get install -y gcc pkg-config libxml2-dev zlib1g-dev libminizip-dev libsundials-dev
#
# Differences from upstream's CMake build, which compiles its own static libxml2, zlib
# (with minizip) and CVODE 7 first: the system's shared libraries instead; on SUNDIALS 6,
# SUN_COMM_NULL (new in 7) is defined as NULL, what SUNContext_Create took there;
# FMUSIM_VERSION is
# set (see below).  fmusim's own source is not changed.
# The FMUs of this project run in fmusim's co-simulation mode, which calls no CVODE code.
set -eu

if [ $# -ne 2 ]; then
    echo "usage: $0 SRC_DIR OUT_DIR   (SRC_DIR: the Reference-FMUs' fmusim/, include/ and src/)" >&2
    exit 2
fi
SRC=$1
OUT=$2
for d in fmusim include src; do
    if [ ! -d "$SRC/$d" ]; then
        echo "$0: $SRC/$d: no such folder (SRC_DIR must hold the Reference-FMUs' fmusim/, include/ and src/)" >&2
        exit 2
    fi
done
if [ ! -f "$SRC/fmusim/fmusim.c" ]; then
    echo "$0: $SRC/fmusim/fmusim.c is missing: Reference-FMUs after v0.0.39 no longer ship fmusim's sources" >&2
    exit 2
fi
CC=${CC:-gcc}
for pkg in libxml-2.0 minizip zlib; do
    if ! pkg-config --exists "$pkg"; then
        echo "$0: pkg-config does not know $pkg: apt-get install -y libxml2-dev zlib1g-dev libminizip-dev" >&2
        exit 2
    fi
done
if ! printf '#include <cvode/cvode.h>\n' | "$CC" -E - >/dev/null 2>&1; then
    echo "$0: <cvode/cvode.h> not found: apt-get install -y libsundials-dev" >&2
    exit 2
fi

# SUNDIALS 7 defines SUN_COMM_NULL; 6.x's SUNContext_Create takes a void* there.
COMM=""
if ! printf '#include <sundials/sundials_context.h>\n#ifndef SUN_COMM_NULL\n#error SUNDIALS 6\n#endif\n' \
        | "$CC" -E - >/dev/null 2>&1; then
    COMM="-DSUN_COMM_NULL=NULL"
fi
# fmusim --version prints FMUSIM_VERSION: from the environment, else SRC_DIR/VERSION's first word.
VERSION=${FMUSIM_VERSION:-$(head -n 1 "$SRC/VERSION" 2>/dev/null | cut -d' ' -f1)}
VERSION=${VERSION:-unknown}

mkdir -p "$OUT"
# The sources of upstream's fmusim/CMakeLists.txt (FMIBuildDescription.c is not in it).
# -Wno-incompatible-pointer-types: upstream passes T** for void** in 13 places (harmless on
# the platforms it supports; an error by default from GCC 14 on).
# shellcheck disable=SC2046
"$CC" -O2 -std=gnu11 -Wno-incompatible-pointer-types -o "$OUT/fmusim" \
    -I"$SRC/fmusim" -I"$SRC/include" $(pkg-config --cflags libxml-2.0 minizip zlib) \
    -DFMUSIM_VERSION="\"$VERSION\"" $COMM \
    $(ls "$SRC"/fmusim/*.c | grep -v '/FMIBuildDescription\.c$') \
    "$SRC/src/FMI.c" "$SRC/src/FMI1.c" "$SRC/src/FMI2.c" "$SRC/src/FMI3.c" \
    "$SRC/src/structured_variable_name.yy.c" "$SRC/src/structured_variable_name.tab.c" \
    -lsundials_cvode -lsundials_nvecserial -lsundials_sunmatrixdense -lsundials_sunlinsoldense \
    $(pkg-config --libs libxml-2.0 minizip zlib) -ldl -lm
"$OUT/fmusim" --version
echo "built $OUT/fmusim"
