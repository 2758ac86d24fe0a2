-- SPDX-License-Identifier: MIT
-- continuity: runs another scene with every sph_density it adds set to the
-- continuity density (density = "continuity", sph_density's delta-SPH option;
-- diffusion a param, unset: sph_density's default 0.1), the rest of the
-- scene and its params unchanged. For the tests of the option on scenes
-- that have no param for it (tests/test_stress_wcsph.c).
--
--   build/eddy run tests/scenes/continuity.lua --set scene=scenes/stress/still_water.lua --set solver=wcsph

local eddy = require "eddy"

local scene = eddy.param("scene", nil)
if scene == nil then
	error("continuity: set the scene to run, e.g. --set scene=scenes/stress/still_water.lua")
end
local diffusion = tonumber(eddy.param("diffusion", nil))
local add = eddy.sph_density
eddy.sph_density = function(def)
	def.density = "continuity"
	if diffusion ~= nil then def.diffusion = diffusion end
	return add(def)
end
return dofile(scene)
