#!/bin/sh
# SPDX-License-Identifier: MIT
# Installs the Debian packages eddy needs, if any are missing. Prints what it
# installs; does nothing when all are present. Needs root (or sudo) only then.
#   sh scripts/deps.sh        what building, running and fuzzing need
#   sh scripts/deps.sh test   also what the tests use to read eddy's files back
#                             (VTK's own reader, python3-vtk9)
set -eu

PKGS="make gcc g++ pkg-config liblua5.4-dev lua5.4 libsuitesparse-dev libhypre-dev libopenmpi-dev libopenblas-dev libosmesa6-dev libpng-dev libstb-dev libassimp-dev libopenvdb-dev libtbb-dev libboost-dev graphviz gnuplot-nox clang libclang-rt-14-dev"
[ "${1:-}" = test ] && PKGS="$PKGS python3-vtk9"

missing=""
for p in $PKGS; do
	if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
		missing="$missing $p"
	fi
done
[ -z "$missing" ] && exit 0

echo "eddy: installing missing Debian packages:$missing"
if [ "$(id -u)" = 0 ]; then
	SUDO=""
elif command -v sudo >/dev/null 2>&1; then
	SUDO="sudo"
else
	echo "eddy: cannot install packages without root; run as root: apt-get install$missing" >&2
	exit 1
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# shellcheck disable=SC2086
$SUDO apt-get install -y -qq --no-install-recommends $missing
