/* SPDX-License-Identifier: MIT */
/* The GL context: Mesa's off-screen renderer (OSMesa, llvmpipe on Debian 12),
 * the only file that includes OSMesa or GL. One context per renderer, drawing
 * into a buffer this file owns, so renderers never share GL state.
 *
 * render_surface draws through it. render_points draws on the CPU
 * (render/splat.c), pixel for pixel as the sprite program here, which stays
 * as the reference tests/test_render.c compares that against.
 *
 * Particles are point sprites shaded as spheres: the vertex shader sizes each
 * point to the projected diameter 2 r P11 (h/2) / w_clip (exact for
 * orthographic views, the sphere's centre scale for perspective ones); the
 * fragment shader discards outside the unit disc, builds the sphere normal
 * n = (u, v, sqrt(1 - u^2 - v^2)), moves the fragment to the sphere surface
 * z = z_c + r n_z in eye space and writes that point's depth, so overlapping
 * spheres intersect and occlude correctly; colour = albedo (ambient + diffuse)
 * plus a Blinn-Phong highlight. */
#define _POSIX_C_SOURCE 200809L
#define GL_GLEXT_PROTOTYPES 1
#include <GL/osmesa.h>
#include <GL/gl.h>
#include <GL/glext.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "render.h"

struct eddy_gl {
	OSMesaContext ctx;
	int width, height;
	uint8_t *buffer; /* RGBA, bottom row first */
	GLuint sprite_prog, line_prog;
	GLint sp_view, sp_proj, sp_radius, sp_half_height, sp_light, sp_halfway, sp_depth_a, sp_depth_b, sp_ortho;
	GLint sp_ax, sp_ay, sp_az, sp_color;
	GLint ln_view, ln_proj, ln_color, ln_pos;
	GLuint mesh_prog; /* triangle meshes (render_surface), made at the first mesh drawn */
	GLint ms_view, ms_proj, ms_light, ms_color, ms_spec, ms_fresnel, ms_ortho, ms_pos, ms_normal;
};

static const char sprite_vs[] = "#version 120\n"
								"attribute float ax, ay, az;\n"
								"attribute vec4 acolor;\n"
								"uniform mat4 view, proj;\n"
								"uniform float radius, half_height;\n"
								"varying float v_z;\n"
								"varying vec3 v_color;\n"
								"void main() {\n"
								"  vec4 e = view * vec4(ax, ay, az, 1.0);\n"
								"  v_z = e.z;\n"
								"  v_color = acolor.rgb;\n"
								"  vec4 c = proj * e;\n"
								"  gl_Position = c;\n"
								"  gl_PointSize = 2.0 * radius * proj[1][1] * half_height / c.w;\n"
								"}\n";

/* Per fragment only what varies over the sprite: the fragment shader is the
 * cost at a million particles (writing depth turns off early depth tests), so
 * the eye direction is taken as the view axis (halfway vector a uniform), the
 * depth uses only the projection's z row (z_ndc = (a z + b) / w with w = -z,
 * or 1 when orthographic) and the highlight is s^32 by squaring. */
static const char sprite_fs[] =
	"#version 120\n"
	"uniform float radius, depth_a, depth_b, ortho;\n"
	"uniform vec3 light, halfway;\n"
	"varying float v_z;\n"
	"varying vec3 v_color;\n"
	"void main() {\n"
	"  vec2 p = gl_PointCoord * vec2(2.0, -2.0) + vec2(-1.0, 1.0);\n" /* y grows downwards */
	"  float r2 = dot(p, p);\n"
	"  if (r2 > 1.0) discard;\n"
	"  float nz = sqrt(1.0 - r2);\n"
	"  float z = v_z + radius * nz;\n"
	"  gl_FragDepth = 0.5 * (depth_a * z + depth_b) / mix(-z, 1.0, ortho) + 0.5;\n"
	"  vec3 n = vec3(p, nz);\n"
	"  float diffuse = max(dot(n, light), 0.0);\n"
	"  float s = max(dot(n, halfway), 0.0);\n"
	"  s *= s; s *= s; s *= s; s *= s; s *= s;\n"
	"  gl_FragColor = vec4(min(v_color * (0.32 + 0.68 * diffuse) + vec3(0.28 * s), vec3(1.0)), 1.0);\n"
	"}\n";

static const char line_vs[] = "#version 120\n"
							  "attribute vec3 pos;\n"
							  "uniform mat4 view, proj;\n"
							  "void main() { gl_Position = proj * (view * vec4(pos, 1.0)); }\n";

static const char line_fs[] = "#version 120\n"
							  "uniform vec3 color;\n"
							  "void main() { gl_FragColor = vec4(color, 1.0); }\n";

/* Meshes (render_surface): per-pixel Phong in eye space with a Schlick
 * Fresnel term F = (1 - n.v)^5 that brightens grazing angles towards the
 * sky colour, the look of water; the view vector is exact (towards the
 * eye, or the view axis when orthographic). */
static const char mesh_vs[] = "#version 120\n"
							  "attribute vec3 pos, normal;\n"
							  "uniform mat4 view, proj;\n"
							  "varying vec3 v_p, v_n;\n"
							  "void main() {\n"
							  "  vec4 e = view * vec4(pos, 1.0);\n"
							  "  v_p = e.xyz;\n"
							  "  v_n = mat3(view) * normal;\n"
							  "  gl_Position = proj * e;\n"
							  "}\n";

static const char mesh_fs[] = "#version 120\n"
							  "uniform vec3 light, color;\n"
							  "uniform float spec, fresnel, ortho;\n"
							  "varying vec3 v_p, v_n;\n"
							  "void main() {\n"
							  "  vec3 n = normalize(v_n);\n"
							  "  vec3 v = normalize(mix(-v_p, vec3(0.0, 0.0, 1.0), ortho));\n"
							  "  if (dot(n, v) < 0.0) n = -n;\n"
							  "  float diffuse = max(dot(n, light), 0.0);\n"
							  "  float s = pow(max(dot(n, normalize(light + v)), 0.0), 60.0);\n"
							  "  float f = pow(1.0 - max(dot(n, v), 0.0), 5.0);\n"
							  "  vec3 sky = vec3(0.75, 0.85, 0.95);\n"
							  "  vec3 c = color * (0.30 + 0.70 * diffuse);\n"
							  "  c = mix(c, sky, fresnel * (0.04 + 0.96 * f)) + vec3(spec * s);\n"
							  "  gl_FragColor = vec4(min(c, vec3(1.0)), 1.0);\n"
							  "}\n";

static GLuint compile(GLenum type, const char *src, char *err, size_t cap)
{
	GLuint s = glCreateShader(type);
	glShaderSource(s, 1, &src, NULL);
	glCompileShader(s);
	GLint ok = 0;
	glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
	if (!ok) {
		char log[512] = "";
		glGetShaderInfoLog(s, sizeof log, NULL, log);
		snprintf(err, cap, "GL shader does not compile: %s", log);
		glDeleteShader(s);
		return 0;
	}
	return s;
}

static GLuint program(const char *vs, const char *fs, char *err, size_t cap)
{
	GLuint v = compile(GL_VERTEX_SHADER, vs, err, cap);
	if (!v)
		return 0;
	GLuint f = compile(GL_FRAGMENT_SHADER, fs, err, cap);
	if (!f) {
		glDeleteShader(v);
		return 0;
	}
	GLuint p = glCreateProgram();
	glAttachShader(p, v);
	glAttachShader(p, f);
	glLinkProgram(p);
	glDeleteShader(v);
	glDeleteShader(f);
	GLint ok = 0;
	glGetProgramiv(p, GL_LINK_STATUS, &ok);
	if (!ok) {
		char log[512] = "";
		glGetProgramInfoLog(p, sizeof log, NULL, log);
		snprintf(err, cap, "GL program does not link: %s", log);
		glDeleteProgram(p);
		return 0;
	}
	return p;
}

eddy_gl *eddy_gl_create(int width, int height, char *err, size_t cap)
{
	const char *forced = getenv("EDDY_RENDER_FAIL_CONTEXT");
	if (forced && forced[0]) {
		/* fault injection for tests: the same path as a real failure */
		snprintf(err, cap,
		         "cannot create an OpenGL context with OSMesa (EDDY_RENDER_FAIL_CONTEXT is set); "
		         "the renderer needs Mesa's libOSMesa (Debian: libosmesa6)");
		return NULL;
	}
	eddy_gl *g = calloc(1, sizeof *g);
	if (g)
		g->buffer = malloc((size_t)width * (size_t)height * 4);
	if (!g || !g->buffer) {
		free(g);
		snprintf(err, cap, "out of memory for a %dx%d image", width, height);
		return NULL;
	}
	g->width = width;
	g->height = height;
	const int attribs[] = {OSMESA_FORMAT,
	                       OSMESA_RGBA,
	                       OSMESA_DEPTH_BITS,
	                       24,
	                       OSMESA_STENCIL_BITS,
	                       0,
	                       OSMESA_ACCUM_BITS,
	                       0,
	                       OSMESA_PROFILE,
	                       OSMESA_COMPAT_PROFILE,
	                       0};
	g->ctx = OSMesaCreateContextAttribs(attribs, NULL);
	if (!g->ctx) {
		snprintf(err, cap,
		         "cannot create an OpenGL context with OSMesa (OSMesaCreateContextAttribs failed); "
		         "the renderer needs Mesa's libOSMesa (Debian: libosmesa6)");
		eddy_gl_destroy(g);
		return NULL;
	}
	if (!OSMesaMakeCurrent(g->ctx, g->buffer, GL_UNSIGNED_BYTE, width, height)) {
		snprintf(err, cap, "cannot create an OpenGL context with OSMesa (OSMesaMakeCurrent failed for %dx%d)", width,
		         height);
		eddy_gl_destroy(g);
		return NULL;
	}
	GLint maxdims[2] = {0, 0};
	OSMesaGetIntegerv(OSMESA_MAX_WIDTH, &maxdims[0]);
	OSMesaGetIntegerv(OSMESA_MAX_HEIGHT, &maxdims[1]);
	if ((maxdims[0] && width > maxdims[0]) || (maxdims[1] && height > maxdims[1])) {
		snprintf(err, cap, "image %dx%d is larger than OSMesa allows (%dx%d)", width, height, maxdims[0], maxdims[1]);
		eddy_gl_destroy(g);
		return NULL;
	}
	if (!(g->sprite_prog = program(sprite_vs, sprite_fs, err, cap)) ||
	    !(g->line_prog = program(line_vs, line_fs, err, cap))) {
		eddy_gl_destroy(g);
		return NULL;
	}
	g->sp_view = glGetUniformLocation(g->sprite_prog, "view");
	g->sp_proj = glGetUniformLocation(g->sprite_prog, "proj");
	g->sp_radius = glGetUniformLocation(g->sprite_prog, "radius");
	g->sp_half_height = glGetUniformLocation(g->sprite_prog, "half_height");
	g->sp_light = glGetUniformLocation(g->sprite_prog, "light");
	g->sp_halfway = glGetUniformLocation(g->sprite_prog, "halfway");
	g->sp_depth_a = glGetUniformLocation(g->sprite_prog, "depth_a");
	g->sp_depth_b = glGetUniformLocation(g->sprite_prog, "depth_b");
	g->sp_ortho = glGetUniformLocation(g->sprite_prog, "ortho");
	g->sp_ax = glGetAttribLocation(g->sprite_prog, "ax");
	g->sp_ay = glGetAttribLocation(g->sprite_prog, "ay");
	g->sp_az = glGetAttribLocation(g->sprite_prog, "az");
	g->sp_color = glGetAttribLocation(g->sprite_prog, "acolor");
	g->ln_view = glGetUniformLocation(g->line_prog, "view");
	g->ln_proj = glGetUniformLocation(g->line_prog, "proj");
	g->ln_color = glGetUniformLocation(g->line_prog, "color");
	g->ln_pos = glGetAttribLocation(g->line_prog, "pos");
	return g;
}

void eddy_gl_destroy(eddy_gl *g)
{
	if (!g)
		return;
	if (g->ctx) {
		/* unbind first: a context still current keeps its framebuffer alive;
		 * programs belong to the context and go with it */
		if (OSMesaGetCurrentContext() == g->ctx)
			OSMesaMakeCurrent(NULL, NULL, 0, 0, 0);
		OSMesaDestroyContext(g->ctx);
	}
	free(g->buffer);
	free(g);
}

const uint8_t *eddy_gl_pixels(const eddy_gl *g) { return g->buffer; }

int eddy_gl_draw(eddy_gl *g, const eddy_gl_scene *s, char *err, size_t cap)
{
	/* another renderer's context may be current on this thread */
	if (!OSMesaMakeCurrent(g->ctx, g->buffer, GL_UNSIGNED_BYTE, g->width, g->height)) {
		snprintf(err, cap, "OSMesaMakeCurrent failed");
		return -1;
	}
	glViewport(0, 0, g->width, g->height);
	glClearColor(s->background[0], s->background[1], s->background[2], 1.0f);
	glClearDepth(1.0);
	glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
	glEnable(GL_DEPTH_TEST);
	glDepthFunc(GL_LESS);
	glDisable(GL_BLEND);

	if (s->count > 0) {
		glUseProgram(g->sprite_prog);
		glEnable(GL_PROGRAM_POINT_SIZE);
		glEnable(GL_POINT_SPRITE);
		glUniformMatrix4fv(g->sp_view, 1, GL_FALSE, s->view);
		glUniformMatrix4fv(g->sp_proj, 1, GL_FALSE, s->proj);
		glUniform1f(g->sp_radius, s->radius);
		glUniform1f(g->sp_half_height, 0.5f * (float)g->height);
		glUniform3fv(g->sp_light, 1, s->light);
		const float h[3] = {s->light[0], s->light[1], s->light[2] + 1.0f};
		const float hl = sqrtf(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
		const float halfway[3] = {h[0] / hl, h[1] / hl, h[2] / hl};
		glUniform3fv(g->sp_halfway, 1, halfway);
		glUniform1f(g->sp_depth_a, s->proj[10]);
		glUniform1f(g->sp_depth_b, s->proj[14]);
		glUniform1f(g->sp_ortho, s->proj[15]); /* 1 for orthographic, 0 for perspective */
		/* client-side arrays straight from the world's columns: no interleaving copy */
		glBindBuffer(GL_ARRAY_BUFFER, 0);
		const GLint loc[3] = {g->sp_ax, g->sp_ay, g->sp_az};
		const float *col[3] = {s->x, s->y, s->z};
		for (int i = 0; i < 3; ++i) {
			glEnableVertexAttribArray((GLuint)loc[i]);
			glVertexAttribPointer((GLuint)loc[i], 1, GL_FLOAT, GL_FALSE, 0, col[i]);
		}
		glEnableVertexAttribArray((GLuint)g->sp_color);
		glVertexAttribPointer((GLuint)g->sp_color, 4, GL_UNSIGNED_BYTE, GL_TRUE, 0, s->rgb);
		/* draw in chunks so a count beyond GLsizei still works */
		for (size_t first = 0; first < s->count;) {
			size_t n = s->count - first;
			if (n > (size_t)1 << 24)
				n = (size_t)1 << 24;
			glDrawArrays(GL_POINTS, (GLint)first, (GLsizei)n);
			first += n;
		}
		for (int i = 0; i < 3; ++i)
			glDisableVertexAttribArray((GLuint)loc[i]);
		glDisableVertexAttribArray((GLuint)g->sp_color);
	}
	if (s->mesh_sets > 0 && !g->mesh_prog) {
		if (!(g->mesh_prog = program(mesh_vs, mesh_fs, err, cap)))
			return -1;
		g->ms_view = glGetUniformLocation(g->mesh_prog, "view");
		g->ms_proj = glGetUniformLocation(g->mesh_prog, "proj");
		g->ms_light = glGetUniformLocation(g->mesh_prog, "light");
		g->ms_color = glGetUniformLocation(g->mesh_prog, "color");
		g->ms_spec = glGetUniformLocation(g->mesh_prog, "spec");
		g->ms_fresnel = glGetUniformLocation(g->mesh_prog, "fresnel");
		g->ms_ortho = glGetUniformLocation(g->mesh_prog, "ortho");
		g->ms_pos = glGetAttribLocation(g->mesh_prog, "pos");
		g->ms_normal = glGetAttribLocation(g->mesh_prog, "normal");
	}
	for (int k = 0; k < s->mesh_sets; ++k) {
		const eddy_gl_mesh *m = &s->meshes[k];
		if (!m->triangles)
			continue;
		glUseProgram(g->mesh_prog);
		glUniformMatrix4fv(g->ms_view, 1, GL_FALSE, s->view);
		glUniformMatrix4fv(g->ms_proj, 1, GL_FALSE, s->proj);
		glUniform3fv(g->ms_light, 1, s->light);
		glUniform3fv(g->ms_color, 1, m->rgb);
		glUniform1f(g->ms_spec, m->specular);
		glUniform1f(g->ms_fresnel, m->fresnel);
		glUniform1f(g->ms_ortho, s->proj[15]); /* 1 for orthographic, 0 for perspective */
		if (m->cull_back) {
			glEnable(GL_CULL_FACE);
			glCullFace(GL_BACK);
			glFrontFace(GL_CCW);
		}
		glBindBuffer(GL_ARRAY_BUFFER, 0);
		glEnableVertexAttribArray((GLuint)g->ms_pos);
		glEnableVertexAttribArray((GLuint)g->ms_normal);
		glVertexAttribPointer((GLuint)g->ms_pos, 3, GL_FLOAT, GL_FALSE, 0, m->xyz);
		glVertexAttribPointer((GLuint)g->ms_normal, 3, GL_FLOAT, GL_FALSE, 0, m->normal);
		for (size_t first = 0; first < m->triangles;) {
			size_t n = m->triangles - first;
			if (n > (size_t)1 << 22)
				n = (size_t)1 << 22;
			glDrawElements(GL_TRIANGLES, (GLsizei)(3 * n), GL_UNSIGNED_INT, m->tri + 3 * first);
			first += n;
		}
		glDisableVertexAttribArray((GLuint)g->ms_pos);
		glDisableVertexAttribArray((GLuint)g->ms_normal);
		glDisable(GL_CULL_FACE);
	}
	if (s->line_sets > 0) {
		glUseProgram(g->line_prog);
		glUniformMatrix4fv(g->ln_view, 1, GL_FALSE, s->view);
		glUniformMatrix4fv(g->ln_proj, 1, GL_FALSE, s->proj);
		glEnableVertexAttribArray((GLuint)g->ln_pos);
		for (int k = 0; k < s->line_sets; ++k) {
			const eddy_gl_lines *l = &s->lines[k];
			if (!l->segments)
				continue;
			glLineWidth(l->width);
			glUniform3fv(g->ln_color, 1, l->rgb);
			glVertexAttribPointer((GLuint)g->ln_pos, 3, GL_FLOAT, GL_FALSE, 0, l->xyz);
			glDrawArrays(GL_LINES, 0, (GLsizei)(2 * l->segments));
		}
		glDisableVertexAttribArray((GLuint)g->ln_pos);
	}
	glUseProgram(0);
	glFinish();
	GLenum e = glGetError();
	if (e != GL_NO_ERROR) {
		snprintf(err, cap, "GL error 0x%04x while drawing", (unsigned)e);
		return -1;
	}
	return 0;
}
