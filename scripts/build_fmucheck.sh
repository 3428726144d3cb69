#!/bin/sh
# Build the FMU Compliance Checker (fmuCheck) with CMake and gcc, without network access.
#
#   scripts/build_fmucheck.sh CHECKER_SRC FMIL_SRC OUT_DIR     -> OUT_DIR/fmuCheck.linux64
#
# CHECKER_SRC: the sources of modelica-tools/FMUComplianceChecker (master, commit c704b98 was
# used); FMIL_SRC: FMI Library (modelon-community/fmi-library) at tag 2.0.3, the version the
# checker's CMakeLists.txt asks for:
#
#   git clone https://github.com/modelica-tools/FMUComplianceChecker CHECKER_SRC
#   git clone --branch 2.0.3 https://github.com/modelon-community/fmi-library FMIL_SRC
#
# The checker's CMake clones FMI Library itself (ExternalProject GIT_REPOSITORY); here the
# given FMIL_SRC is copied to where it expects it and the clone is replaced by no download.
# Needs cmake, make and gcc.  Its ME simulation is forward Euler with the step of -h.
set -eu

if [ $# -ne 3 ]; then
    echo "usage: $0 CHECKER_SRC FMIL_SRC OUT_DIR" >&2
    exit 2
fi
CHECKER=$1
FMIL=$2
OUT=$3
[ -f "$CHECKER/CMakeLists.txt" ] && grep -q "FMUCHK" "$CHECKER/CMakeLists.txt" || {
    echo "$0: $CHECKER: not the FMU Compliance Checker's sources (no CMakeLists.txt naming FMUCHK)" >&2; exit 2; }
[ -f "$FMIL/CMakeLists.txt" ] && [ -d "$FMIL/ThirdParty/Expat" ] || {
    echo "$0: $FMIL: not FMI Library's sources (no CMakeLists.txt and ThirdParty/Expat)" >&2; exit 2; }
for tool in cmake make gcc; do
    command -v "$tool" > /dev/null || { echo "$0: $tool not found" >&2; exit 2; }
done

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cp -r "$CHECKER" "$WORK/src"
rm -rf "$WORK/src/FMIL"
cp -r "$FMIL" "$WORK/src/FMIL"
# no download: the sources are in place
sed -i 's#GIT_REPOSITORY "https://github.com/modelon-community/fmi-library.git"#DOWNLOAD_COMMAND ""#; /GIT_TAG /d' \
    "$WORK/src/CMakeLists.txt"
mkdir -p "$WORK/build" "$OUT"
(cd "$WORK/build" && cmake -DFMUCHK_INSTALL_PREFIX="$WORK/install" ../src > "$WORK/cmake.log" 2>&1 \
    && make install > "$WORK/make.log" 2>&1) || {
    echo "$0: the build failed; the last lines of its log:" >&2
    tail -20 "$WORK/make.log" "$WORK/cmake.log" 2>/dev/null >&2
    exit 1
}
cp "$WORK/install/fmuCheck.linux64" "$OUT/"
echo "built $OUT/fmuCheck.linux64"
