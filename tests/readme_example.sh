#!/bin/sh
# SPDX-License-Identifier: MIT
# Builds the README's C example against the header, library and pkg-config
# file that `make install` puts under a staging prefix, then runs it.
set -eu
build=${1:-build}
stage="$(pwd)/$build/readme-stage"
rm -rf "$stage"
# -o all: install what the caller built, never rebuild it here (with this
# make's default flags it would relink a sanitizer build without them)
make -s --no-print-directory -o all install BUILD="$build" PREFIX="$stage" >/dev/null
# the first ```c block after the marker line in README.md
awk '/<!-- readme-c-example -->/ { armed = 1; next }
     armed && /^```c/ { inside = 1; next }
     inside && /^```/ { exit }
     inside { print }' README.md > "$stage/example.c"
[ -s "$stage/example.c" ] || { echo "no C example found in README.md" >&2; exit 1; }
PKG_CONFIG_PATH="$stage/lib/pkgconfig" cc -std=c11 -Wall -Wextra -Werror ${EDDY_EXAMPLE_CFLAGS:-} \
	"$stage/example.c" -o "$stage/example" \
	$(PKG_CONFIG_PATH="$stage/lib/pkgconfig" pkg-config --cflags --libs --static eddy)
LD_LIBRARY_PATH="$stage/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" "$stage/example"
