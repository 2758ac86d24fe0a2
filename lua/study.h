/* SPDX-License-Identifier: MIT */
/* The `eddy study` command (lua/study.c, driver in lua/eddy/study.lua). */
#ifndef EDDY_STUDY_H
#define EDDY_STUDY_H

/* argv[1] is "study". Returns the exit status: 0 all runs done and written,
 * 1 a run or the study file failed, 2 bad usage. */
int eddy_study_main(int argc, char **argv);

#endif
