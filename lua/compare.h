/* SPDX-License-Identifier: MIT */
/* The `eddy compare` command (lua/compare.c, driver in lua/eddy/compare.lua). */
#ifndef EDDY_COMPARE_H
#define EDDY_COMPARE_H

/* argv[1] is "compare". Returns the exit status: 0 every method ran and
 * everything was written, 1 a method failed (everything else still written)
 * or the comparison itself failed, 2 bad usage, 128 + N stopped by signal N
 * (SIGINT, SIGTERM) with what ran written. */
int eddy_compare_main(int argc, char **argv);

#endif
