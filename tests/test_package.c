/* SPDX-License-Identifier: MIT */
/* Packaging: what a user of a clone or of `make install` relies on. The
 * repository stands alone and is licensed file by file; libeddy.so exports the
 * public API and nothing else under a versioned soname; the installed Lua
 * module and helpers are where the stock lua5.4 looks for them. */
#define _POSIX_C_SOURCE 200809L
#include "test.h"

#include <eddy.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char out[1 << 16];

/* No file of the project reads or cites anything beside the clone. The
 * needle is split so this file does not match itself. */
static void repository_stands_alone(void)
{
	char cmd[512];
	snprintf(cmd, sizeof cmd,
	         "grep -rIl -e '%s' Makefile README.md scripts src lua render scenes tests data docs .ci; true",
	         "\\.\\./"
	         "shared");
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(out[0] == '\0', "files citing a folder outside the repository:\n%s", out);
	CHECK(test_sh("test -s LICENSE && grep -q '^MIT License' LICENSE", out, sizeof out) == 0);
	CHECK(test_sh("test -s data/martin_moyce_1952_a2.25in.csv && test -s docs/validation.md", out, sizeof out) == 0);
}

/* Every source file carries its licence in its first lines. */
static void every_source_file_has_an_spdx_line(void)
{
	CHECK(test_sh("for f in Makefile scripts/*.sh .ci/run $(find src lua render tests scenes -name '*.[ch]' -o "
	              "-name '*.lua' -o -name '*.sh'); do head -n 3 \"$f\" | grep -q 'SPDX-License-Identifier: MIT' "
	              "|| echo \"$f\"; done",
	              out, sizeof out) == 0);
	CHECKF(out[0] == '\0', "files without an SPDX line:\n%s", out);
}

/* libeddy.so exports exactly the functions eddy.h declares: no internal
 * eddy__ helper, no symbol of a bundled library, and none missing. */
static void shared_library_exports_only_the_public_api(void)
{
	char cmd[1024];
	snprintf(cmd, sizeof cmd, "nm -D --defined-only %s/libeddy.so | awk '$2 ~ /^[TDBR]$/ {print $3}' | sort -u",
	         test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	int exported = 0;
	for (char *line = strtok(out, "\n"); line; line = strtok(NULL, "\n")) {
		exported++;
		CHECKF(strncmp(line, "eddy_", 5) == 0 && line[5] != '_', "libeddy.so exports '%s'", line);
	}
	CHECKF(exported > 50, "only %d symbols exported", exported);

	/* every declared function is there */
	snprintf(cmd, sizeof cmd,
	         "sed -n 's/^EDDY_API[^(]*[ *]\\(eddy_[a-z0-9_]*\\)(.*/\\1/p' src/eddy.h | sort -u > %s/api.txt && "
	         "nm -D --defined-only %s/libeddy.so | awk '{print $3}' | sort -u | comm -23 %s/api.txt - ; "
	         "wc -l < %s/api.txt",
	         test_build_dir(), test_build_dir(), test_build_dir(), test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	int declared = 0;
	char *last = strrchr(out, '\n');
	if (last) {
		*last = '\0';
		char *count = strrchr(out, '\n');
		declared = atoi(count ? count + 1 : out);
		if (count)
			*count = '\0';
		else
			out[0] = '\0';
	}
	CHECKF(declared > 50, "only %d EDDY_API declarations found in src/eddy.h", declared);
	CHECKF(out[0] == '\0', "declared in eddy.h but not exported:\n%s", out);

	snprintf(cmd, sizeof cmd, "readelf -d %s/libeddy.so | grep SONAME", test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	char soname[64];
	snprintf(soname, sizeof soname, "[libeddy.so.%d]", EDDY_VERSION_MAJOR);
	CHECK_HAS(out, soname);
}

/* make install: the stock interpreter finds the module and its helpers when
 * its default paths are taken under the prefix, and the installed command
 * runs an installed scene with its helpers. -o all: install what the caller
 * built, never rebuild any of it here (the cli suite's README example
 * installs from the same build at the same time). */
static void install_layout_serves_stock_lua(void)
{
	char cmd[4096];
	const char *b = test_build_dir();
	snprintf(cmd, sizeof cmd,
	         "{ set -e; stage=$(pwd)/%s/install-stage; rm -rf \"$stage\"; "
	         "make -s --no-print-directory -o all install BUILD=%s PREFIX=/usr/local DESTDIR=\"$stage\" >/dev/null; "
	         "p=$(lua5.4 -e 'io.write(package.path)' | sed \"s|/usr/local|$stage/usr/local|g\"); "
	         "c=$(lua5.4 -e 'io.write(package.cpath)' | sed \"s|/usr/local|$stage/usr/local|g\"); "
	         "LUA_PATH=\"$p\" LUA_CPATH=\"$c\" lua5.4 -e 'local e = require \"eddy\"; require \"eddy.view\"; "
	         "print(\"module\", e.version)'; "
	         "test -f \"$stage/usr/local/share/man/man1/eddy.1\"; "
	         "test -f \"$stage/usr/local/share/eddy/data/martin_moyce_1952_a2.25in.csv\"; "
	         "test -L \"$stage/usr/local/lib/libeddy.so.%d\"; "
	         "\"$stage/usr/local/bin/eddy\" run \"$stage/usr/local/share/eddy/scenes/bounce.lua\" --frames 1 "
	         "--quiet --out \"$stage/out\" && echo ran; }",
	         b, b, EDDY_VERSION_MAJOR);
#if defined(__SANITIZE_ADDRESS__)
	/* the module is built with ASan; the stock interpreter is not */
	const char *asan = getenv("ASAN_OPTIONS");
	char saved[512];
	snprintf(saved, sizeof saved, "%s", asan ? asan : "");
	setenv("LD_PRELOAD", "libasan.so.8", 1);
	setenv("ASAN_OPTIONS", "detect_leaks=0", 1);
#endif
	int rc = test_sh(cmd, out, sizeof out);
#if defined(__SANITIZE_ADDRESS__)
	unsetenv("LD_PRELOAD");
	if (asan)
		setenv("ASAN_OPTIONS", saved, 1);
	else
		unsetenv("ASAN_OPTIONS");
#endif
	CHECKF(rc == 0, "exit %d: %s", rc, out);
	char want[64];
	snprintf(want, sizeof want, "module\t%s", EDDY_VERSION_STRING);
	CHECK_HAS(out, want);
	CHECK_HAS(out, "ran");
}

void suite_package(void)
{
	RUN(repository_stands_alone);
	RUN(every_source_file_has_an_spdx_line);
	RUN(shared_library_exports_only_the_public_api);
	RUN(install_layout_serves_stock_lua);
}
