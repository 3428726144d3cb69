#!/bin/sh
# Build the Reference-FMUs' VanDerPol.fmu (co-simulation and model exchange) from the sources of
# a Reference-FMUs release: the floor of issue 24's speed target ("FMPy's floor, the
# Reference-FMUs' VanDerPol"), used by `python benchmarks/native_fmu.py --vanderpol OUT` (FMI 2.0)
# and `--vanderpol3 OUT` (FMI 3.0, the floor of the FMI 3.0 tables).
#
# Usage: benchmarks/native/build_vanderpol.sh [--fmi 2|3] SRC_DIR OUT
#   --fmi    the FMI version to build: 2 (the default) or 3
#   SRC_DIR  VanDerPol/, src/ and include/ of the Reference-FMUs at tag v0.0.39, e.g.
#              git clone https://github.com/modelica/Reference-FMUs && cd Reference-FMUs
#              mkdir /tmp/vdp-src && git archive v0.0.39 VanDerPol src include | tar -x -C /tmp/vdp-src
#   OUT      the FMU to write, e.g. /tmp/VanDerPol.fmu (FMI 2.0) or /tmp/VanDerPol3.fmu (FMI 3.0)
#
# What the Reference-FMUs' CMakeLists.txt (v0.0.39) does for one model, in one compiler command:
# VanDerPol/model.c, src/fmi<V>Functions.c and src/cosimulation.c with -DFMI_VERSION=<V>
# -DDISABLE_PREFIX (target_compile_definitions), the model's folder (config.h) and include/ on
# the include path (target_include_directories), -Wall -Wextra -Wpedantic -Werror, hidden
# visibility (the fmi<V>* functions are exported by their headers' attribute) and a static
# libgcc (GNU); no -O flag (their Linux build sets no CMAKE_BUILD_TYPE, so its Makefiles add
# none: the released binaries are unoptimised, and so is this one).  The model description is
# VanDerPol/FMI<V>.xml as it is.  The binary's folder (FMI_PLATFORM): FMI 2.0's linux64 /
# darwin64, FMI 3.0's <architecture>-<system> (x86_64-linux, aarch64-linux, x86_64-darwin,
# aarch64-darwin).  Not taken: the sources/ folder their FMU also carries (model.c, config.h,
# model.h, cosimulation.h, the FMI layer; for FMI 3.0 buildDescription.xml), as the benchmark
# only runs the binary; and their cmake -E tar zip (zip or python3's zipfile here).
# Needs a C compiler (CC, else cc) and zip or python3.
set -eu

usage="usage: $0 [--fmi 2|3] SRC_DIR OUT  (SRC_DIR: VanDerPol/, src/, include/ of Reference-FMUs v0.0.39)"
fmi=2
if [ "$#" -ge 1 ] && [ "$1" = "--fmi" ]; then
    if [ "$#" -lt 2 ]; then
        echo "error: --fmi needs a version, 2 or 3" >&2
        echo "$usage" >&2
        exit 2
    fi
    fmi=$2
    shift 2
fi
case "$fmi" in
    2|3) ;;
    *) echo "error: --fmi $fmi: the FMI version must be 2 or 3" >&2; exit 2 ;;
esac
if [ "$#" -ne 2 ]; then
    echo "$usage" >&2
    exit 2
fi
src=$1
out=$2
if [ "$fmi" = 2 ]; then
    headers="include/fmi2Functions.h include/fmi2FunctionTypes.h include/fmi2TypesPlatform.h"
else
    headers="include/fmi3Functions.h include/fmi3FunctionTypes.h include/fmi3PlatformTypes.h"
fi
for f in VanDerPol/model.c VanDerPol/config.h "VanDerPol/FMI$fmi.xml" "src/fmi${fmi}Functions.c" src/cosimulation.c \
         include/model.h include/cosimulation.h $headers; do
    if [ ! -f "$src/$f" ]; then
        echo "error: $src/$f not found: SRC_DIR must hold VanDerPol/, src/ and include/ of Reference-FMUs v0.0.39" >&2
        exit 2
    fi
done
system=$(uname -s)
machine=$(uname -m)
if [ "$fmi" = 2 ]; then
    case "$system-$machine" in
        Linux-x86_64) platform=linux64; suffix=so ;;
        Darwin-*) platform=darwin64; suffix=dylib ;;
        *) echo "error: $system $machine: only linux64 and darwin64 are built by this script for FMI 2.0" >&2; exit 2 ;;
    esac
else
    case "$machine" in
        x86_64|amd64) arch=x86_64 ;;
        aarch64|arm64) arch=aarch64 ;;
        *) echo "error: $system $machine: only x86_64 and aarch64 are built by this script for FMI 3.0" >&2; exit 2 ;;
    esac
    case "$system" in
        Linux) platform=$arch-linux; suffix=so ;;
        Darwin) platform=$arch-darwin; suffix=dylib ;;
        *) echo "error: $system $machine: only Linux and Darwin are built by this script for FMI 3.0" >&2; exit 2 ;;
    esac
fi
cc=${CC:-cc}
if ! command -v "$cc" >/dev/null 2>&1; then
    echo "error: no C compiler '$cc' (set CC)" >&2
    exit 2
fi
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/binaries/$platform"

"$cc" -shared -fPIC -fvisibility=hidden -static-libgcc -Wall -Wextra -Wpedantic -Werror \
    -DFMI_VERSION="$fmi" -DDISABLE_PREFIX -I "$src/include" -I "$src/VanDerPol" \
    -o "$stage/binaries/$platform/VanDerPol.$suffix" \
    "$src/VanDerPol/model.c" "$src/src/fmi${fmi}Functions.c" "$src/src/cosimulation.c" -lm

cp "$src/VanDerPol/FMI$fmi.xml" "$stage/modelDescription.xml"
mkdir -p "$(dirname "$out")"
out_abs=$(cd "$(dirname "$out")" && pwd)/$(basename "$out")
rm -f "$out_abs"
if command -v zip >/dev/null 2>&1; then
    (cd "$stage" && zip -q -r "$out_abs" modelDescription.xml binaries)
else
    (cd "$stage" && python3 -m zipfile -c "$out_abs" modelDescription.xml binaries)
fi
echo "built $out_abs (VanDerPol, FMI $fmi.0, binaries/$platform)"
