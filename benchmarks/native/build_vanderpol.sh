#!/bin/sh
# Build the Reference-FMUs' VanDerPol.fmu (FMI 2.0, co-simulation and model exchange) from the
# sources of a Reference-FMUs release: the floor of issue 24's speed target ("FMPy's floor, the
# Reference-FMUs' VanDerPol"), used by `python benchmarks/native_fmu.py --vanderpol OUT`.
#
# Usage: benchmarks/native/build_vanderpol.sh SRC_DIR OUT
#   SRC_DIR  VanDerPol/, src/ and include/ of the Reference-FMUs at tag v0.0.39, e.g.
#              git clone https://github.com/modelica/Reference-FMUs && cd Reference-FMUs
#              mkdir /tmp/vdp-src && git archive v0.0.39 VanDerPol src include | tar -x -C /tmp/vdp-src
#   OUT      the FMU to write, e.g. /tmp/VanDerPol.fmu
#
# What the Reference-FMUs' CMakeLists.txt does for one model with FMI_VERSION=2, in one compiler
# command: VanDerPol/model.c, src/fmi2Functions.c and src/cosimulation.c with -DFMI_VERSION=2
# -DDISABLE_PREFIX, the model's folder (config.h) and include/ on the include path, hidden
# visibility and a static libgcc; no -O flag (their Linux build sets no CMAKE_BUILD_TYPE, so
# its Makefiles add none: the released binaries are unoptimised, and so is this one).  The model
# description is VanDerPol/FMI2.xml as it is.  Needs a C compiler (CC, else cc) and zip or python3.
set -eu

if [ "$#" -ne 2 ]; then
    echo "usage: $0 SRC_DIR OUT  (SRC_DIR: VanDerPol/, src/, include/ of Reference-FMUs v0.0.39)" >&2
    exit 2
fi
src=$1
out=$2
for f in VanDerPol/model.c VanDerPol/config.h VanDerPol/FMI2.xml src/fmi2Functions.c src/cosimulation.c \
         include/model.h include/fmi2Functions.h; do
    if [ ! -f "$src/$f" ]; then
        echo "error: $src/$f not found: SRC_DIR must hold VanDerPol/, src/ and include/ of Reference-FMUs v0.0.39" >&2
        exit 2
    fi
done
case "$(uname -s)-$(uname -m)" in
    Linux-x86_64) platform=linux64; suffix=so ;;
    Darwin-*) platform=darwin64; suffix=dylib ;;
    *) echo "error: $(uname -s) $(uname -m): only linux64 and darwin64 are built by this script" >&2; exit 2 ;;
esac
cc=${CC:-cc}
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/binaries/$platform"

"$cc" -shared -fPIC -fvisibility=hidden -static-libgcc -Wall -Wextra -Wpedantic -Werror \
    -DFMI_VERSION=2 -DDISABLE_PREFIX -I "$src/include" -I "$src/VanDerPol" \
    -o "$stage/binaries/$platform/VanDerPol.$suffix" \
    "$src/VanDerPol/model.c" "$src/src/fmi2Functions.c" "$src/src/cosimulation.c" -lm

cp "$src/VanDerPol/FMI2.xml" "$stage/modelDescription.xml"
mkdir -p "$(dirname "$out")"
out_abs=$(cd "$(dirname "$out")" && pwd)/$(basename "$out")
rm -f "$out_abs"
if command -v zip >/dev/null 2>&1; then
    (cd "$stage" && zip -q -r "$out_abs" modelDescription.xml binaries)
else
    (cd "$stage" && python3 -m zipfile -c "$out_abs" modelDescription.xml binaries)
fi
echo "built $out_abs (VanDerPol, FMI 2.0, binaries/$platform)"
