# eddy — one Makefile for the engine, the Lua module, the command, tests and benchmarks.
#
#   make            build everything into build/
#   make run        install missing Debian packages, build, run the default scene
#   make test       install missing Debian packages, build, run the tests
#   make bench      benchmarks (machine-readable, into build/bench.json)
#   make asan       the tests under AddressSanitizer + UndefinedBehaviorSanitizer
#   make install PREFIX=/usr/local
#   make clean

BUILD   ?= build
PREFIX  ?= /usr/local
CC      ?= cc
SAN     ?=
OPT     ?= -O3

# Layers depend downward only: src knows nothing of Lua or GL, and lua/, render/
# and tests/ see only the public header, copied to $(BUILD)/include, never src/.
WARN    := -Wall -Wextra -Wpedantic -Wshadow -Wstrict-prototypes -Wmissing-prototypes \
           -Wformat=2 -Wvla -Wpointer-arith -Wcast-qual -Wundef -Werror
BASE    := -std=c11 $(OPT) -g -fPIC -fopenmp $(WARN) $(SAN) -MMD -MP
LDBASE  := -fopenmp $(SAN)

LUA_CFLAGS := $(shell pkg-config --cflags lua5.4 2>/dev/null)
LUA_LIBS   := $(shell pkg-config --libs lua5.4 2>/dev/null)

SRC_C   := $(wildcard src/*.c)
LUA_C   := $(filter-out lua/main.c,$(wildcard lua/*.c))
MAIN_C  := lua/main.c
TEST_C  := $(wildcard tests/test_*.c) tests/runner.c tests/fuzz_scene.c
BENCH_C := tests/bench.c

SRC_O   := $(SRC_C:%.c=$(BUILD)/obj/%.o)
LUA_O   := $(LUA_C:%.c=$(BUILD)/obj/%.o)
MAIN_O  := $(MAIN_C:%.c=$(BUILD)/obj/%.o)
TEST_O  := $(TEST_C:%.c=$(BUILD)/obj/%.o)
BENCH_O := $(BENCH_C:%.c=$(BUILD)/obj/%.o)

HEADER  := $(BUILD)/include/eddy.h
LIBS    := -lm

# ---- FLIP: CHOLMOD (sparse Cholesky), BLAS through Debian's alternatives ----
# libcholmod pulls libblas.so.3, which Debian points at OpenBLAS when
# libopenblas0-pthread is installed (update-alternatives; reference BLAS is
# about 7x slower for the factorisation). Only src/flip_cholmod.c includes it.
CHOLMOD_LIBS := -lcholmod
LIBS    += $(CHOLMOD_LIBS)
# ---- end FLIP ----

.PHONY: all run test bench asan fuzz install clean deps check-tests
.DEFAULT_GOAL := all

all: $(BUILD)/libeddy.a $(BUILD)/libeddy.so $(BUILD)/eddy.so $(BUILD)/eddy $(BUILD)/eddy.pc

$(HEADER): src/eddy.h
	@mkdir -p $(dir $@)
	cp $< $@

$(BUILD)/obj/src/%.o: src/%.c
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -Isrc -c $< -o $@

$(BUILD)/obj/lua/%.o: lua/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -I$(BUILD)/include $(LUA_CFLAGS) -c $< -o $@

$(BUILD)/obj/tests/%.o: tests/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -I$(BUILD)/include -Ilua $(LUA_CFLAGS) -c $< -o $@

$(BUILD)/libeddy.a: $(SRC_O)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/libeddy.so: $(SRC_O)
	$(CC) -shared -Wl,-soname,libeddy.so.0 $(LDBASE) $^ -o $@ $(LIBS)

# The Lua module: the stock lua5.4 interpreter provides the Lua symbols.
$(BUILD)/eddy.so: $(LUA_O) $(SRC_O)
	$(CC) -shared $(LDBASE) $^ -o $@ $(LIBS)

$(BUILD)/eddy: $(MAIN_O) $(LUA_O) $(BUILD)/libeddy.a
	$(CC) $(LDBASE) $(MAIN_O) $(LUA_O) $(BUILD)/libeddy.a -o $@ $(LUA_LIBS) $(LIBS)

$(BUILD)/eddy.pc: Makefile
	@mkdir -p $(BUILD)
	printf 'prefix=%s\nincludedir=$${prefix}/include\nlibdir=$${prefix}/lib\n\nName: eddy\nDescription: headless fluid engine\nVersion: 0.1.0\nCflags: -I$${includedir}\nLibs: -L$${libdir} -leddy\nLibs.private: -lOSMesa -lcholmod -lm -fopenmp\n' '$(PREFIX)' > $@

$(BUILD)/tests/run: $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a -o $@ $(LUA_LIBS) $(LIBS)

$(BUILD)/tests/bench: $(BENCH_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(BENCH_O) $(BUILD)/libeddy.a -o $@ $(LIBS)

# ---- renderer and particle exports (render/) ------------------------------------
# render/ compiles against the public header only. gl_osmesa.c is the one file
# that includes OSMesa, png.c the one with stb_image_write's implementation.
# The render objects join libeddy (and so eddy, eddy.so and the tests), which
# therefore links OSMesa.
OSMESA_CFLAGS := $(shell pkg-config --cflags osmesa 2>/dev/null)
OSMESA_LIBS   := $(shell pkg-config --libs osmesa 2>/dev/null || echo -lOSMesa)
RENDER_C      := $(wildcard render/*.c)
RENDER_O      := $(RENDER_C:%.c=$(BUILD)/obj/%.o)
LIBS          += $(OSMESA_LIBS)

.PHONY: bench-render

$(BUILD)/obj/render/%.o: render/%.c $(HEADER)
	@mkdir -p $(dir $@)
	$(CC) $(BASE) -I$(BUILD)/include $(OSMESA_CFLAGS) -c $< -o $@

$(BUILD)/libeddy.a $(BUILD)/libeddy.so $(BUILD)/eddy.so: $(RENDER_O)

$(BUILD)/tests/bench_render: $(BUILD)/obj/tests/bench_render.o $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $^ -o $@ $(LIBS)

# per-frame render time at 1280x720, 10k/100k/1M particles, 1 and 2 llvmpipe threads
bench-render: deps
	@$(MAKE) --no-print-directory $(BUILD)/tests/bench_render
	$(BUILD)/tests/bench_render $(BUILD)/bench_render.json

bench: bench-render

# Mesa's process-wide allocations are not eddy's leaks (see the file)
asan: export LSAN_OPTIONS = suppressions=$(CURDIR)/tests/lsan_mesa.supp:print_suppressions=0

# ---- end of the renderer block ------------------------------------------------------

# ---- FLIP benchmarks (make bench) ----
$(BUILD)/tests/bench_flip: $(BUILD)/obj/tests/bench_flip.o $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $< $(BUILD)/libeddy.a -o $@ $(LIBS)
# ---- end FLIP ----

# ---- the README's two commands -------------------------------------------------

deps:
	@sh scripts/deps.sh

run: deps
	@$(MAKE) --no-print-directory all
	@mkdir -p out/splash
	$(BUILD)/eddy run scenes/splash.lua --stats out/splash/stats.jsonl

test: deps
	@$(MAKE) --no-print-directory all $(BUILD)/tests/run
	@$(MAKE) --no-print-directory check-tests

check-tests:
	EDDY_BUILD=$(BUILD) $(BUILD)/tests/run

bench: deps
	@$(MAKE) --no-print-directory all $(BUILD)/tests/bench $(BUILD)/tests/bench_flip
	$(BUILD)/tests/bench $(BUILD)/bench.json
	$(BUILD)/tests/bench_flip $(BUILD)/bench_flip.json

asan: deps
	@$(MAKE) --no-print-directory BUILD=build/asan OPT=-O1 \
		SAN="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer" \
		all build/asan/tests/run
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1 \
		EDDY_BUILD=build/asan build/asan/tests/run
	@echo "asan: a full run of the default scene, leaks checked at exit"
	ASAN_OPTIONS=detect_leaks=1 build/asan/eddy run scenes/bounce.lua --quiet --out build/asan/out

# ---- fuzzing (clang libFuzzer): scene loading and stepping ---------------------
# Everything is rebuilt with clang, libFuzzer, ASan and UBSan. OpenMP is left out
# (its pragmas are ignored): the fuzzer runs one thread. make fuzz FUZZ_SECONDS=3600
# for a longer session; crashes land in build/fuzz/ and belong in tests/fuzz/regressions/.
FUZZ_SECONDS ?= 60
FUZZ_CFLAGS := -std=c11 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
               -Wall -Wextra -Wno-unknown-pragmas -DEDDY_LIBFUZZER
FUZZ_SRC = $(SRC_C) $(LUA_C) $(RENDER_C) tests/fuzz_scene.c

$(BUILD)/fuzz/fuzz_scene: $(FUZZ_SRC) $(HEADER)
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -Isrc -Ilua $(LUA_CFLAGS) $(OSMESA_CFLAGS) $(FUZZ_SRC) -o $@ $(LUA_LIBS) $(LIBS)

fuzz: deps
	@$(MAKE) --no-print-directory $(BUILD)/fuzz/fuzz_scene
	@mkdir -p $(BUILD)/fuzz/corpus
	$(BUILD)/fuzz/fuzz_scene -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=4096 -timeout=30 \
		-artifact_prefix=$(BUILD)/fuzz/ -print_final_stats=1 $(BUILD)/fuzz/corpus tests/fuzz/seeds tests/fuzz/regressions

install: all
	install -d $(DESTDIR)$(PREFIX)/include $(DESTDIR)$(PREFIX)/lib $(DESTDIR)$(PREFIX)/lib/pkgconfig \
		$(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/lib/lua/5.4
	install -m 644 src/eddy.h $(DESTDIR)$(PREFIX)/include/eddy.h
	install -m 644 $(BUILD)/libeddy.a $(DESTDIR)$(PREFIX)/lib/libeddy.a
	install -m 755 $(BUILD)/libeddy.so $(DESTDIR)$(PREFIX)/lib/libeddy.so.0
	ln -sf libeddy.so.0 $(DESTDIR)$(PREFIX)/lib/libeddy.so
	install -m 755 $(BUILD)/eddy $(DESTDIR)$(PREFIX)/bin/eddy
	install -m 755 $(BUILD)/eddy.so $(DESTDIR)$(PREFIX)/lib/lua/5.4/eddy.so
	install -d $(DESTDIR)$(PREFIX)/share/eddy/lua/eddy
	install -m 644 lua/eddy/*.lua $(DESTDIR)$(PREFIX)/share/eddy/lua/eddy/
	sed 's|^prefix=.*|prefix=$(PREFIX)|' $(BUILD)/eddy.pc > $(DESTDIR)$(PREFIX)/lib/pkgconfig/eddy.pc

clean:
	rm -rf build out

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)

# ---- SPH pair loops: sqrtf as the bare instruction ---------------------------------
# With errno semantics GCC follows every sqrtss with a compare and a branch to
# libm's sqrtf (to set errno for a negative argument, which r^2 never is) in
# the innermost pair loops. -fno-math-errno drops only that: results are
# bit-identical, and no code here reads errno.
$(BUILD)/obj/src/sys_sph_pressure.o $(BUILD)/obj/src/sys_sph_viscosity.o: BASE += -fno-math-errno

# ---- SPH benchmark (tests/bench_sph.c): run by make bench -------------------------
BENCH_SPH_O := $(BUILD)/obj/tests/bench_sph.o

$(BUILD)/tests/bench_sph: $(BENCH_SPH_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(BENCH_SPH_O) $(BUILD)/libeddy.a -o $@ $(LIBS)

.PHONY: bench-sph
bench-sph: deps
	@$(MAKE) --no-print-directory $(BUILD)/tests/bench_sph
	$(BUILD)/tests/bench_sph $(BUILD)/bench_sph.json

bench: bench-sph
# ---- end SPH benchmark ------------------------------------------------------------

# ---- accuracy/time study (eddy study; lua/study.c, lua/eddy/study.lua) -------------
# Every shipped study, full sweep: out/study_<name>/<name>.csv and .png.
# make study STUDY_FLAGS=--quick for the reduced sweeps.
STUDIES ?= $(sort $(wildcard scenes/studies/*.lua))
STUDY_FLAGS ?=

.PHONY: study
study: deps
	@$(MAKE) --no-print-directory all
	@for s in $(STUDIES); do echo "== $$s"; $(BUILD)/eddy study $$s $(STUDY_FLAGS) || exit 1; done
# ---- end study ----------------------------------------------------------------------
