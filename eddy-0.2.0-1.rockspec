-- SPDX-License-Identifier: MIT
-- LuaRocks build of eddy from a checkout: `luarocks make` in the repository.
-- The Debian packages of scripts/deps.sh must be installed first (the
-- Makefile's `make deps` does that).
package = "eddy"
version = "0.2.0-1"
source = { url = "git+file://." }
description = {
	summary = "A headless fluid engine (SPH and FLIP) with Lua 5.4 scenes",
	detailed = [[
eddy simulates liquids with SPH (Müller et al. 2003, DFSPH) or FLIP on a MAC
grid, composes each scene's pipeline from Lua, and renders PNG frames without a
GPU or display. require "eddy" gives the engine; the `eddy` command runs scenes.]],
	license = "MIT",
}
dependencies = { "lua >= 5.4, < 5.5" }
external_dependencies = {
	CHOLMOD = { header = "suitesparse/cholmod.h" },
	OSMESA = { header = "GL/osmesa.h" },
	ASSIMP = { header = "assimp/cimport.h" },
}
build = {
	type = "make",
	build_target = "all",
	install_target = "install",
	install_variables = {
		PREFIX = "$(PREFIX)",
		LUA_CMOD = "$(LIBDIR)",
		LUA_LMOD = "$(LUADIR)",
	},
}
