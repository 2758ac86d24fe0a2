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
TEST_C  := $(wildcard tests/test_*.c) tests/runner.c
BENCH_C := tests/bench.c

SRC_O   := $(SRC_C:%.c=$(BUILD)/obj/%.o)
LUA_O   := $(LUA_C:%.c=$(BUILD)/obj/%.o)
MAIN_O  := $(MAIN_C:%.c=$(BUILD)/obj/%.o)
TEST_O  := $(TEST_C:%.c=$(BUILD)/obj/%.o)
BENCH_O := $(BENCH_C:%.c=$(BUILD)/obj/%.o)

HEADER  := $(BUILD)/include/eddy.h
LIBS    := -lm

.PHONY: all run test bench asan install clean deps check-tests
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
	printf 'prefix=%s\nincludedir=$${prefix}/include\nlibdir=$${prefix}/lib\n\nName: eddy\nDescription: headless fluid engine\nVersion: 0.1.0\nCflags: -I$${includedir}\nLibs: -L$${libdir} -leddy\nLibs.private: -lm -fopenmp\n' '$(PREFIX)' > $@

$(BUILD)/tests/run: $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(TEST_O) $(LUA_O) $(BUILD)/libeddy.a -o $@ $(LUA_LIBS) $(LIBS)

$(BUILD)/tests/bench: $(BENCH_O) $(BUILD)/libeddy.a
	@mkdir -p $(dir $@)
	$(CC) $(LDBASE) $(BENCH_O) $(BUILD)/libeddy.a -o $@ $(LIBS)

# ---- the README's two commands -------------------------------------------------

deps:
	@sh scripts/deps.sh

run: deps
	@$(MAKE) --no-print-directory all
	@mkdir -p out/bounce
	$(BUILD)/eddy run scenes/bounce.lua --stats out/bounce/stats.jsonl

test: deps
	@$(MAKE) --no-print-directory all $(BUILD)/tests/run
	@$(MAKE) --no-print-directory check-tests

check-tests:
	EDDY_BUILD=$(BUILD) $(BUILD)/tests/run

bench: deps
	@$(MAKE) --no-print-directory all $(BUILD)/tests/bench
	$(BUILD)/tests/bench $(BUILD)/bench.json

asan: deps
	@$(MAKE) --no-print-directory BUILD=build/asan OPT=-O1 \
		SAN="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer" \
		all build/asan/tests/run
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1 \
		EDDY_BUILD=build/asan build/asan/tests/run

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
