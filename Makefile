# SPDX-License-Identifier: MIT
# eddy: one Makefile for the engine, the Lua module, the command, tests and benchmarks.
#
#   make            build everything into build/
#   make run        install missing Debian packages, build, run the default scene
#   make test       install missing Debian packages, build, run the tests (suites in
#                   parallel, one per CPU; JOBS=N to choose, JOBS=1 one process)
#   make test SIMD=scalar   the same on the SPH passes' scalar back-end (build/scalar)
#   make bench      benchmarks (machine-readable JSON in build/bench*.json)
#   make asan       the tests under AddressSanitizer + UndefinedBehaviorSanitizer
#   make fuzz       libFuzzer over scene loading and stepping (FUZZ_SECONDS)
#   make study      every accuracy/time study in scenes/studies/
#   make format     clang-format over the tree (.clang-format)
#   make install PREFIX=/usr/local [DESTDIR=...]
#   make clean

# SIMD=scalar: the SPH passes on simd.h's scalar back-end, no AVX2 variants,
# in a build directory of its own.
SIMD    ?=
ifeq ($(SIMD),scalar)
BUILD   ?= build/scalar
SIMD_FLAGS := -DEDDY_SIMD_SCALAR
else ifneq ($(SIMD),)
$(error SIMD=$(SIMD): allowed are SIMD=scalar or nothing)
endif
BUILD   ?= build
PREFIX  ?= /usr/local
CC      ?= cc
CXX     ?= g++
SAN     ?=
OPT     ?= -O3

# The version lives in the public header; the soname carries the major.
VERSION := $(shell sed -n 's/^\#define EDDY_VERSION_STRING "\(.*\)"/\1/p' src/eddy.h)
SOMAJOR := $(firstword $(subst ., ,$(VERSION)))

# Layers depend downward only: src knows nothing of Lua or GL, and lua/, render/
# and tests/ see only the public header, copied to $(BUILD)/include, never src/.
# Symbols are hidden unless the public header marks them EDDY_API.
WARN    := -Wall -Wextra -Wpedantic -Wshadow -Wstrict-prototypes -Wmissing-prototypes \
           -Wformat=2 -Wvla -Wpointer-arith -Wcast-qual -Wundef -Werror
BASE    := -std=c11 $(OPT) -g -fPIC -fopenmp -fvisibility=hidden $(WARN) $(SAN) $(SIMD_FLAGS) -MMD -MP
LDBASE  := -fopenmp $(SAN)
# The one C++ file (src/surface_vdb.cpp, OpenVDB): same warnings and sanitizers.
# Not -fvisibility=hidden: OpenVDB's templates instantiated here must share
# libopenvdb's type identities (hidden copies crash openvdb::initialize());
# the file hides its own functions with a visibility pragma instead.
CXXBASE := -std=c++17 $(OPT) -g -fPIC -Wall -Wextra -Wpedantic -Wshadow -Werror $(SAN) -MMD -MP

LUA_CFLAGS    := $(shell pkg-config --cflags lua5.4 2>/dev/null)
LUA_LIBS      := $(shell pkg-config --libs lua5.4 2>/dev/null)
OSMESA_CFLAGS := $(shell pkg-config --cflags osmesa 2>/dev/null)
OSMESA_LIBS   := $(shell pkg-config --libs osmesa 2>/dev/null || echo -lOSMesa)
# CHOLMOD pulls libblas.so.3, which Debian points at OpenBLAS when it is
# installed (reference BLAS is about 7x slower for the factorisation). Only
# src/flip_cholmod.c includes CHOLMOD, only render/gl_osmesa.c OSMesa, only
# render/png.c libpng. render_points draws on a thread of its own (-pthread).
# HYPRE (Debian's libhypre-dev) is built against Open MPI: only
# src/flip_hypre.c includes HYPRE and MPI, and it opens both libraries at
# its first solve (dlopen) by the sonames found here: nothing links them.
PNG_CFLAGS    := $(shell pkg-config --cflags libpng 2>/dev/null)
PNG_LIBS      := $(shell pkg-config --libs libpng 2>/dev/null || echo -lpng16)
MPI_CFLAGS    := $(shell pkg-config --cflags ompi-c 2>/dev/null || mpicc --showme:compile 2>/dev/null)
# as system headers: HYPRE's are not -Wstrict-prototypes clean
HYPRE_CFLAGS  := -isystem /usr/include/hypre $(patsubst -I%,-isystem %,$(MPI_CFLAGS))
soname = $(or $(shell objdump -p "$$(readlink -f "$$($(CC) -print-file-name=$(1))")" 2>/dev/null | awk '/SONAME/ {print $$2}'),$(1))
HYPRE_SONAME  := $(call soname,libHYPRE.so)
MPI_SONAME    := $(call soname,libmpi.so)
HYPRE_DEFS    := -DEDDY_HYPRE_SONAME='"$(HYPRE_SONAME)"' -DEDDY_MPI_SONAME='"$(MPI_SONAME)"'
# Only src/surface_vdb.cpp includes OpenVDB (with TBB and Imath, which its
# headers use).
VDB_LIBS      := -lopenvdb $(shell pkg-config --libs Imath tbb 2>/dev/null || echo -lImath-3_1 -ltbb) -lstdc++
# Meshes are read through assimp's C API; only src/mesh.c includes it.
ASSIMP_LIBS   := $(shell pkg-config --libs assimp 2>/dev/null || echo -lassimp)
LIBS          := -lcholmod $(OSMESA_LIBS) $(PNG_LIBS) $(ASSIMP_LIBS) $(VDB_LIBS) -lz -pthread -lm

# The command-line host: main.c and the files named cli_*.c are the command's
# own and stay out of the Lua module.
CLI_C    := lua/main.c $(wildcard lua/cli_*.c)
SRC_C    := $(wildcard src/*.c src/sph/*.c)
SRC_CXX  := $(wildcard src/*.cpp)
RENDER_C := $(wildcard render/*.c)
LUA_C    := $(filter-out $(CLI_C),$(wildcard lua/*.c))
TEST_C   := $(wildcard tests/test_*.c) tests/runner.c tests/fuzz_scene.c
BENCHES  := bench bench_flip bench_sph bench_render

obj = $(1:%.c=$(BUILD)/obj/%.o)

# The files written against src/simd.h: compiled once more with AVX2
# (X.avx2.o, -DEDDY_SIMD_VARIANT: only their kernels) on x86 unless
# SIMD=scalar; the normal compile then gets -DEDDY_SIMD_HAVE_AVX2 so that
# SIMD_PICK can choose the variant at run time (see simd.h).
SIMD_C  := $(shell grep -l 'include "simd.h"' $(SRC_C))
ifeq ($(SIMD),scalar)
SIMD_VARIANT_O :=
else
SIMD_VARIANT_O := $(if $(filter x86_64% i386% i486% i586% i686%,$(shell $(CC) -dumpmachine)),$(SIMD_C:%.c=$(BUILD)/obj/%.avx2.o))
endif

LIB_O   := $(call obj,$(SRC_C) $(RENDER_C)) $(SRC_CXX:%.cpp=$(BUILD)/obj/%.o) $(SIMD_VARIANT_O)
LUA_O   := $(call obj,$(LUA_C))
CLI_O   := $(call obj,$(CLI_C))
TEST_O  := $(call obj,$(TEST_C))
HEADER  := $(BUILD)/include/eddy.h

.PHONY: all run test test-long check-tests bench asan fuzz study format install clean deps deps-test
.DEFAULT_GOAL := all

all: $(BUILD)/libeddy.a $(BUILD)/libeddy.so $(BUILD)/eddy.so $(BUILD)/eddy $(BUILD)/eddy.pc

# ---- compiling: each folder gets its own include flags ----------------------------

$(HEADER): src/eddy.h
	@mkdir -p $(dir $@)
	cp $< $@

$(BUILD)/obj/src/%.o: src/%.c
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -Isrc -c $< -o $@

$(BUILD)/obj/src/%.o: src/%.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXBASE) -Isrc -c $< -o $@

$(BUILD)/obj/render/%.o: render/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -pthread -I$(BUILD)/include $(OSMESA_CFLAGS) $(PNG_CFLAGS) -c $< -o $@

$(BUILD)/obj/lua/%.o: lua/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -I$(BUILD)/include $(LUA_CFLAGS) -c $< -o $@

$(BUILD)/obj/tests/%.o: tests/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -I$(BUILD)/include -Ilua $(LUA_CFLAGS) -c $< -o $@

# SPH pair loops: with errno semantics GCC follows every sqrtss with a compare
# and a branch to libm's sqrtf (to set errno for a negative argument, which r^2
# never is). -fno-math-errno drops only that; results are bit-identical.
$(sort $(call obj,src/sph/pressure.c src/sph/viscosity.c $(SIMD_C))) $(SIMD_VARIANT_O): BASE += -fno-math-errno
$(call obj,$(SIMD_C)): BASE += $(if $(SIMD_VARIANT_O),-DEDDY_SIMD_HAVE_AVX2)

$(BUILD)/obj/src/%.avx2.o: src/%.c
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -mavx2 -mbmi2 -DEDDY_SIMD_VARIANT -Isrc -c $< -o $@
$(BUILD)/obj/src/flip_hypre.o: BASE += $(HYPRE_CFLAGS) $(HYPRE_DEFS)

# ---- linking --------------------------------------------------------------------

$(BUILD)/libeddy.a: $(LIB_O)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/libeddy.so: $(LIB_O)
	$(CC) -shared -Wl,-soname,libeddy.so.$(SOMAJOR) $(LDBASE) $^ -o $@ $(LIBS)

# The Lua module: the stock lua5.4 interpreter provides the Lua symbols.
$(BUILD)/eddy.so: $(LUA_O) $(LIB_O)
	$(CC) -shared $(LDBASE) $^ -o $@ $(LIBS)

$(BUILD)/eddy: $(CLI_O) $(LUA_O) $(BUILD)/libeddy.a
	$(CC) $(LDBASE) $(CLI_O) $(LUA_O) $(BUILD)/libeddy.a -o $@ $(LUA_LIBS) $(LIBS)

$(BUILD)/eddy.pc: Makefile src/eddy.h
	@mkdir -p $(BUILD)
	printf 'prefix=%s\nincludedir=$${prefix}/include\nlibdir=$${prefix}/lib\n\nName: eddy\nDescription: headless fluid engine\nVersion: %s\nCflags: -I$${includedir}\nLibs: -L$${libdir} -leddy\nLibs.private: -lOSMesa -lcholmod -lassimp -lpng16 -lz %s -lm -fopenmp -pthread\n' '$(PREFIX)' '$(VERSION)' '$(VDB_LIBS)' > $@

$(BUILD)/tests/run: $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a -o $@ $(LUA_LIBS) $(LIBS)

$(BENCHES:%=$(BUILD)/tests/%) $(BUILD)/tests/bench_scale: $(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $< $(BUILD)/libeddy.a -o $@ $(LIBS)

# ---- the README's two commands ----------------------------------------------------

deps:
	@sh scripts/deps.sh

# the tests also read exports back with VTK's own reader (python3-vtk9)
deps-test:
	@sh scripts/deps.sh test

run: deps
	@$(MAKE) --no-print-directory all
	@mkdir -p out/splash
	$(BUILD)/eddy run scenes/splash.lua --stats out/splash/stats.jsonl

# the runner runs its suites in parallel processes, one per online CPU unless
# JOBS=N (or EDDY_JOBS) says otherwise; JOBS=1 runs them in one process. The
# builds before it (test, test-long, asan) use every CPU unless make got a -j.
RUN_JOBS = $(if $(JOBS),-j $(JOBS))
BUILD_JOBS = $(if $(filter -j%,$(MAKEFLAGS)),,-j$(shell nproc 2>/dev/null || echo 1))

test: deps-test
	@$(MAKE) --no-print-directory $(BUILD_JOBS) all $(BUILD)/tests/run
	@$(MAKE) --no-print-directory check-tests

check-tests:
	EDDY_BUILD=$(BUILD) $(BUILD)/tests/run $(RUN_JOBS)

# the stress cases that take minutes rather than seconds (CI runs them too)
test-long: deps-test
	@$(MAKE) --no-print-directory $(BUILD_JOBS) all $(BUILD)/tests/run
	EDDY_BUILD=$(BUILD) $(BUILD)/tests/run $(RUN_JOBS) long

# ---- benchmarks: JSON into build/, never part of make test ------------------------
# bench: core systems; bench_flip: FLIP transfers and pressure; bench_sph: SPH
# blocks and the pour; bench_render: 1280x720 frames of 10k/100k/1M/10M particles
# and the surface mesher against the pour's step (it runs $(BUILD)/eddy).

bench: deps
	@$(MAKE) --no-print-directory all $(BENCHES:%=$(BUILD)/tests/%)
	@for b in $(BENCHES); do $(BUILD)/tests/$$b $(BUILD)/$$b.json || exit 1; done

# one of them: make bench-sph, bench-flip, bench-render; make bench-scale (not in
# make bench: 100k to 10M particles of each method, long) passes
# SCALE_ARGS, e.g. SCALE_ARGS="--sizes 100000,1000000 --grids 64,128"
bench-%: deps
	@$(MAKE) --no-print-directory $(BUILD)/tests/bench_$* $(BUILD)/eddy
	$(BUILD)/tests/bench_$* $(BUILD)/bench_$*.json $(if $(filter scale,$*),$(SCALE_ARGS))

# ---- sanitizers ---------------------------------------------------------------------
# Mesa's process-wide allocations are not eddy's leaks (see the suppressions file).
# intercept_tls_get_addr=0: up to GCC 13 the sanitizer runtime's __tls_get_addr
# hook takes a dynamic TLS block that happens to sit 16 bytes past a page start
# for a pre-2.25 glibc header and reads a bogus range from it; LeakSanitizer's
# tracer then dies at exit ("Tracer caught signal 11"), now and then, after
# HYPRE's dlopen'd MPI libraries (which keep dynamic TLS) were used.

asan: deps-test
	@$(MAKE) --no-print-directory $(BUILD_JOBS) BUILD=build/asan OPT=-O1 \
		SAN="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer" \
		all build/asan/tests/run
	LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan_mesa.supp:print_suppressions=0 \
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=0:intercept_tls_get_addr=0 UBSAN_OPTIONS=print_stacktrace=1 \
		EDDY_BUILD=build/asan build/asan/tests/run $(RUN_JOBS)
	@echo "asan: a full run of the default scene, leaks checked at exit"
	LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan_mesa.supp:print_suppressions=0 \
	ASAN_OPTIONS=detect_leaks=1:intercept_tls_get_addr=0 build/asan/eddy run scenes/bounce.lua --quiet --out build/asan/out

# ---- fuzzing (clang libFuzzer): scene loading and stepping ------------------------
# Everything is rebuilt with clang, libFuzzer, ASan and UBSan. OpenMP is left out
# (its pragmas are ignored, so thread counts go unused): the fuzzer runs one
# thread. Crashes land in build/fuzz/ and belong in tests/fuzz/regressions/,
# which make test replays.

FUZZ_SECONDS ?= 60
FUZZ_CFLAGS  := -std=c11 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
                -Wall -Wextra -Wno-unknown-pragmas -Wno-unused-parameter -Wno-unused-variable -DEDDY_LIBFUZZER
FUZZ_SRC     := $(SRC_C) $(LUA_C) $(RENDER_C) tests/fuzz_scene.c

# the C++ file (OpenVDB) with the sanitizers but without libFuzzer's main
# (no vptr or function checks: their C++ runtime is not in what the C
# driver links)
FUZZ_CXXFLAGS := -std=c++17 -O1 -g -fsanitize=address,undefined -fno-sanitize=vptr,function -fno-sanitize-recover=undefined -Wall -Wextra

$(BUILD)/fuzz/surface_vdb.o: $(SRC_CXX) src/surface.h src/eddy.h
	@mkdir -p $(dir $@)
	clang++ $(FUZZ_CXXFLAGS) -Isrc -c $(SRC_CXX) -o $@

# one object per source, so that the build runs on every core
FUZZ_OBJ     := $(FUZZ_SRC:%.c=$(BUILD)/fuzz/obj/%.o)

$(BUILD)/fuzz/obj/%.o: %.c $(HEADER) $(wildcard src/*.h src/sph/*.h lua/*.h render/*.h tests/*.h)
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -Isrc -Ilua $(LUA_CFLAGS) $(OSMESA_CFLAGS) $(HYPRE_CFLAGS) $(HYPRE_DEFS) -c $< -o $@

$(BUILD)/fuzz/fuzz_scene: $(FUZZ_OBJ) $(BUILD)/fuzz/surface_vdb.o
	clang $(FUZZ_CFLAGS) $(FUZZ_OBJ) $(BUILD)/fuzz/surface_vdb.o -o $@ $(LUA_LIBS) $(LIBS)

fuzz: deps
	@$(MAKE) --no-print-directory $(BUILD_JOBS) $(BUILD)/fuzz/fuzz_scene
	@mkdir -p $(BUILD)/fuzz/corpus
	$(BUILD)/fuzz/fuzz_scene -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=4096 -timeout=30 \
		-artifact_prefix=$(BUILD)/fuzz/ -print_final_stats=1 $(BUILD)/fuzz/corpus tests/fuzz/seeds tests/fuzz/regressions

# ---- accuracy/time studies (eddy study) -------------------------------------------
# Every shipped study, full sweep: out/study_<name>/<name>.csv and .png.
# make study STUDY_FLAGS=--quick for the reduced sweeps.

STUDIES     ?= $(sort $(wildcard scenes/studies/*.lua))
STUDY_FLAGS ?=

study: deps
	@$(MAKE) --no-print-directory all
	@for s in $(STUDIES); do echo "== $$s"; $(BUILD)/eddy study $$s $(STUDY_FLAGS) || exit 1; done

# ---- formatting: every C, C++ and header file by .clang-format ----------------------

CLANG_FORMAT ?= $(firstword $(shell for c in clang-format clang-format-14; do command -v $$c; done))

format:
	@test -n "$(CLANG_FORMAT)" || { echo "make format: needs clang-format (apt-get install clang-format)"; exit 1; }
	$(CLANG_FORMAT) -i $$(git ls-files '*.c' '*.h' '*.cpp' | grep -v '^tests/fuzz/')

# ---- install ------------------------------------------------------------------------
# The Lua module and helpers go where the stock lua5.4 looks (lib/lua/5.4/,
# share/lua/5.4/); scenes, studies and their reference data under share/eddy/.

INST_LIB   := $(DESTDIR)$(PREFIX)/lib
INST_SHARE := $(DESTDIR)$(PREFIX)/share
LUA_CMOD ?= $(PREFIX)/lib/lua/5.4
LUA_LMOD ?= $(PREFIX)/share/lua/5.4

install: all
	install -d $(DESTDIR)$(PREFIX)/include $(INST_LIB)/pkgconfig $(DESTDIR)$(PREFIX)/bin \
		$(DESTDIR)$(LUA_CMOD) $(DESTDIR)$(LUA_LMOD)/eddy $(INST_SHARE)/eddy/scenes/studies $(INST_SHARE)/eddy/scenes/meshes $(INST_SHARE)/eddy/data \
		$(INST_SHARE)/man/man1 $(INST_SHARE)/doc/eddy
	install -m 644 src/eddy.h $(DESTDIR)$(PREFIX)/include/eddy.h
	install -m 644 $(BUILD)/libeddy.a $(INST_LIB)/libeddy.a
	install -m 755 $(BUILD)/libeddy.so $(INST_LIB)/libeddy.so.$(VERSION)
	ln -sf libeddy.so.$(VERSION) $(INST_LIB)/libeddy.so.$(SOMAJOR)
	ln -sf libeddy.so.$(SOMAJOR) $(INST_LIB)/libeddy.so
	install -m 755 $(BUILD)/eddy $(DESTDIR)$(PREFIX)/bin/eddy
	install -m 755 $(BUILD)/eddy.so $(DESTDIR)$(LUA_CMOD)/eddy.so
	install -m 644 lua/eddy/*.lua $(DESTDIR)$(LUA_LMOD)/eddy/
	install -m 644 scenes/*.lua $(INST_SHARE)/eddy/scenes/
	install -m 644 scenes/studies/*.lua $(INST_SHARE)/eddy/scenes/studies/
	install -m 644 scenes/meshes/*.obj scenes/meshes/*.stl $(INST_SHARE)/eddy/scenes/meshes/
	install -m 644 data/*.csv data/README.md $(INST_SHARE)/eddy/data/
	install -m 644 docs/eddy.1 $(INST_SHARE)/man/man1/eddy.1
	install -m 644 LICENSE README.md CHANGELOG.md $(INST_SHARE)/doc/eddy/
	sed 's|^prefix=.*|prefix=$(PREFIX)|' $(BUILD)/eddy.pc > $(INST_LIB)/pkgconfig/eddy.pc

clean:
	rm -rf build out

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
