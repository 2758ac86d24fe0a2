/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Replays the fuzzing seeds and every input that once found a bug
 * (tests/fuzz/regressions/) through the same harness make fuzz runs, so a
 * fixed crash stays fixed. A crash here takes the runner down: that fails the
 * run, loudly, under make asan too. */
#include "test.h"

#include <dirent.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int eddy_fuzz_one(const uint8_t *data, size_t size);

static int replay_dir(const char *dir)
{
	DIR *d = opendir(dir);
	if (!d)
		return -1;
	int n = 0;
	struct dirent *e;
	while ((e = readdir(d))) {
		if (e->d_name[0] == '.')
			continue;
		char path[1024];
		snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
		FILE *f = fopen(path, "rb");
		if (!f)
			continue;
		uint8_t buf[65536];
		size_t len = fread(buf, 1, sizeof buf, f);
		fclose(f);
		eddy_fuzz_one(buf, len);
		++n;
	}
	closedir(d);
	return n;
}

static void fuzz_inputs_replay_cleanly(void)
{
	int seeds = replay_dir("tests/fuzz/seeds");
	int regressions = replay_dir("tests/fuzz/regressions");
	CHECKF(seeds >= 10, "expected the fuzzing seeds in tests/fuzz/seeds (found %d)", seeds);
	/* among them the corrupted precompiled scenes, which the harness must
	 * refuse to load (it aborts if one is accepted) */
	CHECKF(regressions >= 5, "expected the regression inputs in tests/fuzz/regressions (found %d)", regressions);
}

void suite_fuzz(void) { RUN(fuzz_inputs_replay_cleanly); }
