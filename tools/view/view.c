/*
 * tileworld-view: the interactive viewer (`tileworld view`, DESIGN.md §9).
 * A GLFW window over the runtime: fly with the mouse and WASD, switch the
 * culling method, and look at what the culling did (the tile-query state of
 * each cell, the BVH nodes drawn, the query boxes), or freeze the culled set
 * and fly around it.
 *
 * A program of its own so that it links libGL (through GLFW) and never
 * libOSMesa: every GL call goes through entry points that glfwGetProcAddress
 * hands out. Bad input: exit status 2 and one line on stderr; no window or
 * no usable OpenGL: exit status 1.
 */
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <stb/stb_easy_font.h>

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "runtime/gl.h"
#include "runtime/programs.h"
#include "tiles/tiles-internal.h"
#include "tools/cli.h"
#include "tools/outfile.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

#define EXIT_USAGE TW_CLI_EXIT_USAGE

static const char program[] = "tileworld view";

static const float pi_f = 3.14159265358979f;

/* ---- options -------------------------------------------------------------------- */

struct options {
    struct tw_cli cli;          /* tileset, path (NULL: keyboard and mouse), frames (0: until
                                 * the window closes or the path ends), quiet, world settings */
    const char *screenshot;
    unsigned debug;
    uint32_t freeze_at;         /* 0: never */
    bool no_overlay;
};

static void usage(FILE *f)
{
    fputs("usage: tileworld view [--tileset NAME|FILE.json] [--seed N] [--method M] [--size WxH]\n"
          "                      [--start-cell I,J] [--repeat P] [--view-distance M]\n"
          "                      [--max-screen-error PX]\n"
          "                      [--debug cells,nodes,queries|all] [--no-overlay]\n"
          "                      [--path NAME|FILE.csv] [--frames N] [--screenshot FILE.png]\n"
          "                      [--freeze-at N] [--quiet] [--workers N] [--policy wait|skip]\n"
          "                      [--budget BYTES] [--upload-budget BYTES]\n"
          "\n"
          "A window onto the world (GLFW; without a display, run it under xvfb-run).\n"
          "--tileset NAME|FILE.json  built-in city (default), forest, hybrid; the providers\n"
          "                      city-gen and forest-gen; or a manifest\n"
          "--seed N              seed of the generators and of the cells' selection (default 1)\n"
          "--method M            the method at the start: vfc, tilequery, chc, tilequery+chc\n"
          "                      (default), oracle, hzb, tilequery+hzb, box-oracle\n"
          "--size WxH            window size, each side 16..8192 (default 1280x720)\n"
          "--start-cell I,J      the cell the camera starts in (with --path: moves the path)\n"
          "--repeat P            the selection repeats every P cells\n"
          "--view-distance M     metres, 1..100000 (default 600)\n"
          "--max-screen-error PX  levels of detail: each tile drawn at its coarsest level whose\n"
          "                      error projects to at most PX pixels, 0..1000; 0: full detail\n"
          "                      (default 1)\n"
          "--debug cells,nodes,queries|all  debug views shown at the start (keys C, B, X)\n"
          "--no-overlay          no text overlay at the start (key O)\n"
          "--path NAME|FILE.csv  play a camera path (built-in name or CSV) instead of flying\n"
          "--frames N            frames to show, then exit (with --path: default 300; a CSV: its rows)\n"
          "--screenshot FILE.png with --path: write the last frame as FILE.png and exit\n"
          "--freeze-at N         with --path: freeze the culled set at frame N (key F)\n"
          "--quiet               no summary line at the end and no screenshot line\n"
          "--workers N           threads generating a provider's tiles, 1..64 (default: cores - 1)\n"
          "--policy wait|skip    a visible tile not ready: wait for it (default) or draw without it\n"
          "--budget BYTES        the tile cache's budget, with a binary suffix K, M, G, T; 0: none\n"
          "--upload-budget BYTES per frame, bytes of finished tiles uploaded ahead of need (32M)\n"
          "options take their value as --opt VALUE or --opt=VALUE; numbers are plain decimal digits\n"
          "keys: mouse drag or Tab (captured mouse) to look; W A S D to fly, Q/E down/up, Shift\n"
          "fast, wheel changes speed; 1-8 method (vfc, tilequery, chc, tilequery+chc, oracle,\n"
          "hzb, tilequery+hzb, box-oracle); C cells, B BVH nodes, X query boxes; F freeze the\n"
          "culled set; P screenshot; H help; O overlay; Esc quits\n",
          f);
}

static unsigned parse_debug(const char *opt, const char *s)
{
    char buf[128];
    if (!s || *s == '\0' || strlen(s) >= sizeof(buf))
        tw_cli_fail(program, opt, "'%s' is not a list of debug views (cells, nodes, queries, all)",
                    s ? s : "");
    strcpy(buf, s);
    unsigned mask = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (strcmp(tok, "cells") == 0)
            mask |= TW_DEBUG_CELLS;
        else if (strcmp(tok, "nodes") == 0)
            mask |= TW_DEBUG_NODES;
        else if (strcmp(tok, "queries") == 0)
            mask |= TW_DEBUG_QUERIES;
        else if (strcmp(tok, "all") == 0)
            mask |= TW_DEBUG_ALL;
        else if (strcmp(tok, "none") != 0)
            tw_cli_fail(program, opt, "unknown debug view '%s' (cells, nodes, queries, all, none)", tok);
    }
    return mask;
}

enum {
    OPT_DEBUG = TW_CLI_OPT_PROGRAM,
    OPT_NO_OVERLAY,
    OPT_SCREENSHOT,
    OPT_FREEZE_AT,
};

static const struct option options_table[] = {
    TW_CLI_COMMON_OPTIONS,
    {"debug", required_argument, NULL, OPT_DEBUG},
    {"no-overlay", no_argument, NULL, OPT_NO_OVERLAY},
    {"screenshot", required_argument, NULL, OPT_SCREENSHOT},
    {"freeze-at", required_argument, NULL, OPT_FREEZE_AT},
    {NULL, 0, NULL, 0},
};

static void apply_option(void *user, int opt, const char *name, const char *v)
{
    struct options *o = user;
    switch (opt) {
    case OPT_DEBUG: o->debug = parse_debug(name, v); break;
    case OPT_NO_OVERLAY: o->no_overlay = true; break;
    case OPT_SCREENSHOT:
        if (*v == '\0')
            tw_cli_fail(program, name, "the file name is empty");
        o->screenshot = v;
        break;
    case OPT_FREEZE_AT: o->freeze_at = (uint32_t)tw_cli_u64(program, name, v, 1, 10000000); break;
    default: tw_cli_fail(program, name, "unknown option '%s' (see tileworld view --help)", name);
    }
}

static void parse_options(int argc, char **argv, struct options *o)
{
    memset(o, 0, sizeof(*o));
    tw_cli_init(&o->cli, program);
    o->cli.world.width = 1280;
    o->cli.world.height = 720;
    tw_cli_parse(&o->cli, argc, argv, options_table, apply_option, o, usage);
}

/* ---- the overlay: text (stb_easy_font) and flat shapes as triangles ------------ */

/* The library's GL loader (runtime/gl.h) takes the window's entry points
 * from glfwGetProcAddress, so that they are libGL's. */
static void *glfw_get_proc(const char *name)
{
    /* Function pointer to data pointer, which POSIX allows. */
    GLFWglproc f = glfwGetProcAddress(name);
    void *p;
    memcpy(&p, &f, sizeof(p));
    return p;
}

static const char *const overlay_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec2 a_pos;\n"
    "layout(location = 1) in vec4 a_color;\n"
    "uniform vec2 u_screen;\n"
    "out vec4 v_color;\n"
    "void main() {\n"
    "    v_color = a_color;\n"
    "    gl_Position = vec4(a_pos.x / u_screen.x * 2.0 - 1.0, 1.0 - a_pos.y / u_screen.y * 2.0,\n"
    "                       0.0, 1.0);\n"
    "}\n";

static const char *const overlay_fs =
    "#version 330 core\n"
    "in vec4 v_color;\n"
    "out vec4 o_color;\n"
    "void main() { o_color = v_color; }\n";

enum {
    VERTEX_FLOATS = 6,          /* x, y (pixels, top left origin), r, g, b, a */
    FONT_LINE = 12,             /* stb_easy_font's line height, in font pixels */
    FONT_HEIGHT = 8,            /* its glyphs' height above the baseline and a little below */
    TEXT_MAX = 256,             /* characters drawn of one string */
};

struct overlay {
    struct tw_gl gl;
    GLuint program, vao, vbo;
    GLint u_screen;
    float *verts;
    size_t count, cap;          /* vertices */
    size_t clip_first;          /* vertices from here on are drawn inside clip */
    int clip[4];                /* x, y, w, h in pixels, top left origin; w = 0: none */
    float scale;                /* screen pixels per font pixel */
    /* stb_easy_font's quads of one string: 4 vertices of x, y, z and 4
     * colour bytes, about 270 bytes a character. */
    float quads[TEXT_MAX * 300 / sizeof(float)];
};

static int overlay_init(struct overlay *o, const struct tw_log *log)
{
    int err = tw_gl_load(&o->gl, glfw_get_proc, log);
    if (err)
        return err;
    const struct tw_gl *gl = &o->gl;
    bool out_of_memory = false;
    o->program = tw_programs_link(gl, log, overlay_vs, NULL, overlay_fs, &out_of_memory);
    if (!o->program)
        return out_of_memory ? TW_ERR_NOMEM : TW_ERR_GL;
    o->u_screen = gl->GetUniformLocation(o->program, "u_screen");

    gl->GenVertexArrays(1, &o->vao);
    gl->BindVertexArray(o->vao);
    gl->GenBuffers(1, &o->vbo);
    gl->BindBuffer(GL_ARRAY_BUFFER, o->vbo);
    const GLsizei stride = VERTEX_FLOATS * sizeof(float);
    gl->EnableVertexAttribArray(0);
    gl->VertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, stride, (const void *)0);
    gl->EnableVertexAttribArray(1);
    gl->VertexAttribPointer(1, 4, GL_FLOAT, GL_FALSE, stride, (const void *)(2 * sizeof(float)));
    gl->BindVertexArray(0);
    const GLenum gl_err = gl->GetError();
    if (gl_err != GL_NO_ERROR) {
        fprintf(stderr, "tileworld view: OpenGL error 0x%x while setting up the overlay\n", gl_err);
        return TW_ERR_GL;
    }
    return TW_OK;
}

static void overlay_finish(struct overlay *o)
{
    if (o->vao) {
        o->gl.DeleteBuffers(1, &o->vbo);
        o->gl.DeleteVertexArrays(1, &o->vao);
    }
    if (o->program)
        o->gl.DeleteProgram(o->program);
    free(o->verts);
}

/* A flat quad with corners (x[k], y[k]) in order around it. */
static void overlay_shape(struct overlay *o, const float x[4], const float y[4], const float color[4])
{
    if (o->count + 6 > o->cap) {
        size_t cap = o->cap ? 2 * o->cap : 6 * 1024;
        float *p = realloc(o->verts, sizeof(float) * VERTEX_FLOATS * cap);
        if (!p)
            return;   /* the overlay loses shapes, the frame goes on */
        o->verts = p;
        o->cap = cap;
    }
    static const int order[6] = {0, 1, 2, 0, 2, 3};
    for (int k = 0; k < 6; k++) {
        float *p = o->verts + VERTEX_FLOATS * o->count++;
        p[0] = x[order[k]];
        p[1] = y[order[k]];
        memcpy(p + 2, color, 4 * sizeof(float));
    }
}

static void overlay_rect(struct overlay *o, float x0, float y0, float x1, float y1,
                         const float color[4])
{
    const float x[4] = {x0, x1, x1, x0}, y[4] = {y0, y0, y1, y1};
    overlay_shape(o, x, y, color);
}

static void overlay_line(struct overlay *o, float xa, float ya, float xb, float yb, float width,
                         const float color[4])
{
    float dx = xb - xa, dy = yb - ya;
    const float len = sqrtf(dx * dx + dy * dy);
    if (len <= 0.0f)
        return;
    const float nx = -dy / len * 0.5f * width, ny = dx / len * 0.5f * width;
    const float x[4] = {xa + nx, xb + nx, xb - nx, xa - nx};
    const float y[4] = {ya + ny, yb + ny, yb - ny, ya - ny};
    overlay_shape(o, x, y, color);
}

/* s as stb_easy_font takes it: printable ASCII only (it indexes its tables
 * by character), at most TEXT_MAX characters. */
static void font_text(const char *s, char out[TEXT_MAX + 1])
{
    size_t n = 0;
    for (; s[n] && n < TEXT_MAX; n++)
        out[n] = s[n] >= 32 && s[n] <= 126 ? s[n] : '?';
    out[n] = '\0';
}

static float text_width(const struct overlay *o, const char *s)
{
    char text[TEXT_MAX + 1];
    font_text(s, text);
    return (float)stb_easy_font_width(text) * o->scale;
}

static float line_h(const struct overlay *o)
{
    return FONT_LINE * o->scale;
}

/* Draws text with its top left at (x, y), over a dark shadow so that it
 * reads over any scene. */
static void overlay_text(struct overlay *o, float x, float y, const float color[4], const char *s)
{
    static const float shadow[4] = {0.0f, 0.0f, 0.0f, 0.85f};
    char text[TEXT_MAX + 1];
    font_text(s, text);
    const int quads = stb_easy_font_print(0.0f, 0.0f, text, NULL, o->quads, sizeof(o->quads));
    const float k = o->scale;
    for (int pass = 0; pass < 2; pass++) {
        const float px = pass == 0 ? x + k : x, py = pass == 0 ? y + k : y;
        for (int q = 0; q < quads; q++) {
            /* 4 vertices of 16 bytes: x, y, z, colour. */
            const float *v = o->quads + q * 16;
            const float qx[4] = {px + v[0] * k, px + v[4] * k, px + v[8] * k, px + v[12] * k};
            const float qy[4] = {py + v[1] * k, py + v[5] * k, py + v[9] * k, py + v[13] * k};
            overlay_shape(o, qx, qy, pass == 0 ? shadow : color);
        }
    }
}

static void overlay_draw(struct overlay *o, int fb_w, int fb_h)
{
    const struct tw_gl *gl = &o->gl;
    if (o->count > 0) {
        gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
        gl->Viewport(0, 0, fb_w, fb_h);
        gl->Disable(GL_DEPTH_TEST);
        gl->Disable(GL_CULL_FACE);
        gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
        gl->Enable(GL_BLEND);
        gl->BlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
        gl->UseProgram(o->program);
        const float screen[2] = {(float)fb_w, (float)fb_h};
        gl->Uniform2fv(o->u_screen, 1, screen);
        gl->BindVertexArray(o->vao);
        gl->BindBuffer(GL_ARRAY_BUFFER, o->vbo);
        gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(sizeof(float) * VERTEX_FLOATS * o->count),
                       o->verts, GL_STREAM_DRAW);
        const size_t first = o->clip[2] > 0 ? o->clip_first : o->count;
        gl->DrawArrays(GL_TRIANGLES, 0, (GLsizei)first);
        if (first < o->count) {
            gl->Enable(GL_SCISSOR_TEST);
            gl->Scissor(o->clip[0], fb_h - o->clip[1] - o->clip[3], o->clip[2], o->clip[3]);
            gl->DrawArrays(GL_TRIANGLES, (GLint)first, (GLsizei)(o->count - first));
            gl->Disable(GL_SCISSOR_TEST);
        }
        /* Leave the state the renderer expects. */
        gl->Disable(GL_BLEND);
        gl->Enable(GL_DEPTH_TEST);
        gl->BindVertexArray(0);
    }
    o->count = 0;
    o->clip[2] = 0;
}

/* ---- the viewer ----------------------------------------------------------------- */

struct viewer {
    struct options opt;
    GLFWwindow *win;
    struct tw_cli_world shown;   /* the tileset or provider shown */
    struct tw_world *world;
    struct overlay ov;
    struct tw_camera cam;
    struct tw_frame_stats st;
    unsigned debug;
    bool show_overlay, show_help;
    float speed;                 /* m/s, before Shift */
    double fps;                  /* frames per second over the last half second */
    double fps_since;
    uint32_t fps_frames;

    /* Mouse look: while the left button is down, or always when captured. */
    bool looking, captured;
    double mouse_x, mouse_y;

    /* Freeze: the clusters drawn, and every debug view, at the moment of freezing. */
    bool freeze_pending, frozen;
    struct tw_drawn_cluster *frozen_set;
    size_t frozen_count;
    struct tw_debug_box *frozen_boxes, *shown_boxes;
    size_t frozen_box_count;
    struct tw_camera frozen_cam;
    uint32_t frozen_frame;

    bool screenshot_pending;
    uint32_t screenshot_count;
    uint64_t frame;
};

static void set_title(struct viewer *v)
{
    char title[256];
    char name[256];
    snprintf(title, sizeof(title), "tileworld view: %s, %s%s",
             tw_cli_escape(v->shown.name, name, sizeof(name)),
             tw_method_name(tw_world_settings(v->world)->method), v->frozen ? " (frozen)" : "");
    glfwSetWindowTitle(v->win, title);
}

static void toggle_debug(struct viewer *v, unsigned flag)
{
    const unsigned debug = v->debug ^ flag;
    if (tw_world_set_debug(v->world, debug) == TW_OK)
        v->debug = debug;
}

static void unfreeze(struct viewer *v)
{
    v->frozen = false;
    free(v->frozen_set);
    free(v->frozen_boxes);
    free(v->shown_boxes);
    v->frozen_set = NULL;
    v->frozen_boxes = v->shown_boxes = NULL;
    v->frozen_count = v->frozen_box_count = 0;
}

static void on_key(GLFWwindow *win, int key, int scancode, int action, int mods)
{
    (void)scancode;
    (void)mods;
    struct viewer *v = glfwGetWindowUserPointer(win);
    if (action != GLFW_PRESS)
        return;
    switch (key) {
    case GLFW_KEY_ESCAPE:
        if (v->captured) {
            v->captured = false;
            glfwSetInputMode(win, GLFW_CURSOR, GLFW_CURSOR_NORMAL);
        } else {
            glfwSetWindowShouldClose(win, GLFW_TRUE);
        }
        break;
    case GLFW_KEY_1: case GLFW_KEY_2: case GLFW_KEY_3: case GLFW_KEY_4: case GLFW_KEY_5:
    case GLFW_KEY_6: case GLFW_KEY_7: case GLFW_KEY_8: {
        static const enum tw_method by_key[8] = {TW_METHOD_VFC, TW_METHOD_TILEQUERY, TW_METHOD_CHC,
                                                 TW_METHOD_TILEQUERY_CHC, TW_METHOD_ORACLE,
                                                 TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB,
                                                 TW_METHOD_BOX_ORACLE};
        if (tw_world_set_method_or_limit(v->world, by_key[key - GLFW_KEY_1]) == TW_OK)
            set_title(v);
        break;
    }
    case GLFW_KEY_C:
        toggle_debug(v, TW_DEBUG_CELLS);
        break;
    case GLFW_KEY_B:
        toggle_debug(v, TW_DEBUG_NODES);
        break;
    case GLFW_KEY_X:
        toggle_debug(v, TW_DEBUG_QUERIES);
        break;
    case GLFW_KEY_F:
        if (v->frozen) {
            unfreeze(v);
            set_title(v);
        } else {
            v->freeze_pending = true;
        }
        break;
    case GLFW_KEY_P:
    case GLFW_KEY_F12:
        v->screenshot_pending = true;
        break;
    case GLFW_KEY_H:
    case GLFW_KEY_F1:
        v->show_help = !v->show_help;
        break;
    case GLFW_KEY_O:
        v->show_overlay = !v->show_overlay;
        break;
    case GLFW_KEY_TAB:
        v->captured = !v->captured;
        glfwSetInputMode(win, GLFW_CURSOR, v->captured ? GLFW_CURSOR_DISABLED : GLFW_CURSOR_NORMAL);
        glfwGetCursorPos(win, &v->mouse_x, &v->mouse_y);
        break;
    default:
        break;
    }
}

static void on_mouse_button(GLFWwindow *win, int button, int action, int mods)
{
    (void)mods;
    struct viewer *v = glfwGetWindowUserPointer(win);
    if (button == GLFW_MOUSE_BUTTON_LEFT || button == GLFW_MOUSE_BUTTON_RIGHT) {
        v->looking = action == GLFW_PRESS;
        glfwGetCursorPos(win, &v->mouse_x, &v->mouse_y);
    }
}

static void on_cursor(GLFWwindow *win, double x, double y)
{
    struct viewer *v = glfwGetWindowUserPointer(win);
    if ((v->looking || v->captured) && !v->opt.cli.path) {
        const float sensitivity = 0.15f;   /* degrees per pixel */
        /* Yaw grows towards +x, which lies to the left when looking along +z. */
        v->cam.yaw -= (float)(x - v->mouse_x) * sensitivity;
        v->cam.pitch -= (float)(y - v->mouse_y) * sensitivity;
        v->cam.yaw = fmodf(v->cam.yaw, 360.0f);
        if (v->cam.pitch > 89.0f)
            v->cam.pitch = 89.0f;
        if (v->cam.pitch < -89.0f)
            v->cam.pitch = -89.0f;
    }
    v->mouse_x = x;
    v->mouse_y = y;
}

static void on_scroll(GLFWwindow *win, double dx, double dy)
{
    (void)dx;
    struct viewer *v = glfwGetWindowUserPointer(win);
    v->speed *= powf(1.25f, (float)dy);
    if (v->speed < 0.5f)
        v->speed = 0.5f;
    if (v->speed > 5000.0f)
        v->speed = 5000.0f;
}

/* WASD flight along the view, Q/E down/up, Shift fast. The position stays a
 * cell and a local offset: normalised every frame, so that flying any
 * distance loses no precision. */
static void fly(struct viewer *v, float dt)
{
    GLFWwindow *win = v->win;
    const float yaw = v->cam.yaw * pi_f / 180.0f, pitch = v->cam.pitch * pi_f / 180.0f;
    const float forward[3] = {sinf(yaw) * cosf(pitch), sinf(pitch), cosf(yaw) * cosf(pitch)};
    const float right[3] = {-cosf(yaw), 0.0f, sinf(yaw)};
    float move[3] = {0, 0, 0};
    const float f = (float)(glfwGetKey(win, GLFW_KEY_W) == GLFW_PRESS) -
                    (float)(glfwGetKey(win, GLFW_KEY_S) == GLFW_PRESS);
    const float r = (float)(glfwGetKey(win, GLFW_KEY_D) == GLFW_PRESS) -
                    (float)(glfwGetKey(win, GLFW_KEY_A) == GLFW_PRESS);
    const float u = (float)(glfwGetKey(win, GLFW_KEY_E) == GLFW_PRESS) -
                    (float)(glfwGetKey(win, GLFW_KEY_Q) == GLFW_PRESS);
    for (int a = 0; a < 3; a++)
        move[a] = f * forward[a] + r * right[a];
    move[1] += u;
    const bool fast = glfwGetKey(win, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS ||
                      glfwGetKey(win, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
    const float step = v->speed * (fast ? 10.0f : 1.0f) * dt;
    for (int a = 0; a < 3; a++)
        v->cam.pos.local[a] += move[a] * step;
    if (v->cam.pos.local[1] < 0.3f)
        v->cam.pos.local[1] = 0.3f;
    if (v->cam.pos.local[1] > 20000.0f)
        v->cam.pos.local[1] = 20000.0f;
    struct tw_world_pos p = v->cam.pos;
    if (tw_tiles_normalize(&p, v->shown.footprint[0], v->shown.footprint[1]) == TW_OK)
        v->cam.pos = p;
}

/* Takes the culled set of the frame just rendered (with every debug view
 * recorded) as the frozen one. */
static int take_freeze(struct viewer *v)
{
    size_t n = 0, nb = 0;
    const struct tw_drawn_cluster *d = tw_world_drawn(v->world, &n);
    const struct tw_debug_box *b = tw_world_debug_boxes(v->world, &nb);
    v->frozen_set = malloc(sizeof(*d) * (n ? n : 1));
    v->frozen_boxes = malloc(sizeof(*b) * (nb ? nb : 1));
    v->shown_boxes = malloc(sizeof(*b) * (nb ? nb : 1));
    if (!v->frozen_set || !v->frozen_boxes || !v->shown_boxes) {
        unfreeze(v);
        return TW_ERR_NOMEM;
    }
    if (n)
        memcpy(v->frozen_set, d, sizeof(*d) * n);
    if (nb)
        memcpy(v->frozen_boxes, b, sizeof(*b) * nb);
    v->frozen_count = n;
    v->frozen_box_count = nb;
    v->frozen_cam = v->cam;
    v->frozen_frame = (uint32_t)v->frame + 1;
    v->frozen = true;
    set_title(v);
    return TW_OK;
}

static unsigned view_of(uint16_t kind)
{
    if (kind <= TW_DEBUG_CELL_NOT_REACHED)
        return TW_DEBUG_CELLS;
    if (kind <= TW_DEBUG_NODE_INNER)
        return TW_DEBUG_NODES;
    return TW_DEBUG_QUERIES;
}

/* The debug boxes to show this frame: the last frame's, or while frozen the
 * frozen ones of the views now on. */
static const struct tw_debug_box *shown_boxes(struct viewer *v, size_t *count)
{
    if (!v->frozen)
        return tw_world_debug_boxes(v->world, count);
    size_t n = 0;
    for (size_t k = 0; k < v->frozen_box_count; k++)
        if (view_of(v->frozen_boxes[k].kind) & v->debug)
            v->shown_boxes[n++] = v->frozen_boxes[k];
    *count = n;
    return v->shown_boxes;
}

static const float white[4] = {1.0f, 1.0f, 1.0f, 1.0f};
static const float dim[4] = {0.70f, 0.74f, 0.80f, 1.0f};
static const float accent[4] = {1.0f, 0.85f, 0.30f, 1.0f};
static const float panel[4] = {0.0f, 0.0f, 0.0f, 0.55f};

static float widest_line(const struct overlay *o, char lines[][160], int count)
{
    float widest = 0.0f;
    for (int k = 0; k < count; k++)
        widest = fmaxf(widest, text_width(o, lines[k]));
    return widest;
}

static void draw_panel_lines(struct overlay *o, float x, float y, char lines[][160], int count,
                             const float colors[][4])
{
    const float pad = 4.0f * o->scale;
    overlay_rect(o, x, y, x + widest_line(o, lines, count) + 2 * pad,
                 y + (float)count * line_h(o) + 2 * pad - 3 * o->scale, panel);
    for (int k = 0; k < count; k++)
        overlay_text(o, x + pad, y + pad + (float)k * line_h(o), colors[k], lines[k]);
}

static void draw_stats(struct viewer *v)
{
    struct overlay *o = &v->ov;
    const struct tw_frame_stats *st = &v->st;
    char lines[6][160];
    float colors[6][4];
    int n = 0;
    if (v->frozen) {
        snprintf(lines[n], sizeof(lines[n]), "FROZEN  %zu clusters of frame %u, drawn %.1f ms  [F] release",
                 v->frozen_count, v->frozen_frame, st->ms_frame);
        memcpy(colors[n++], accent, sizeof(accent));
    } else {
        char fps[16] = "  - fps";   /* until half a second has been measured */
        if (v->fps > 0.0)
            snprintf(fps, sizeof(fps), "%3.0f fps", v->fps);
        snprintf(lines[n], sizeof(lines[n]), "%-13s %6.2f ms  cull %.2f  wait %.2f   %s",
                 tw_method_name(st->method), st->ms_frame, st->ms_cull, st->ms_wait, fps);
        memcpy(colors[n++], accent, sizeof(accent));
    }
    snprintf(lines[n], sizeof(lines[n]), "triangles %llu  clusters %u  draws %u  queries %u",
             (unsigned long long)st->triangles, st->clusters, st->draws, st->queries);
    memcpy(colors[n++], white, sizeof(white));
    if (!v->frozen) {
        snprintf(lines[n], sizeof(lines[n]),
                 "tiles visible %u  queried %u  new %u  cached %u  instances %.2f MiB  "
                 "tile cache %.1f MiB  mispredicted %u",
                 st->tiles_visible, st->tiles_queried, st->tiles_new, st->tiles_cached,
                 (double)st->cache_bytes / (1024.0 * 1024.0),
                 (double)(st->bytes_cpu + st->bytes_gpu) / (1024.0 * 1024.0), st->predict_fail);
        memcpy(colors[n++], white, sizeof(white));
    }
    snprintf(lines[n], sizeof(lines[n]), "cell %lld, %lld  at %.1f %.1f %.1f m  yaw %ld  pitch %ld",
             (long long)v->cam.pos.cell.i, (long long)v->cam.pos.cell.j, v->cam.pos.local[0],
             v->cam.pos.local[1], v->cam.pos.local[2], lroundf(v->cam.yaw), lroundf(v->cam.pitch));
    memcpy(colors[n++], dim, sizeof(dim));
    snprintf(lines[n], sizeof(lines[n]), "[1-8] method  [C] cells %s  [B] nodes %s  [X] queries %s  [H] help",
             v->debug & TW_DEBUG_CELLS ? "ON" : "off", v->debug & TW_DEBUG_NODES ? "ON" : "off",
             v->debug & TW_DEBUG_QUERIES ? "ON" : "off");
    memcpy(colors[n++], dim, sizeof(dim));
    const float margin = 6.0f * o->scale;
    draw_panel_lines(o, margin, margin, lines, n, (const float(*)[4])colors);
}

static void draw_help(struct viewer *v, int fb_w, int fb_h)
{
    /* Keys and what they do, in two columns (the font is proportional). */
    static const char *const help[][2] = {
        {"mouse drag", "look (Tab: capture the mouse, Esc: release)"},
        {"W A S D", "fly forward, left, back, right"},
        {"Q / E", "down / up;  Shift: 10x faster;  wheel: speed"},
        {"1 2 3 4 5", "vfc, tilequery, chc, tilequery+chc, oracle"},
        {"C", "cells by tile-query state (and the map)"},
        {"B", "BVH nodes holding the clusters drawn"},
        {"X", "query boxes issued this frame"},
        {"F", "freeze the culled set, fly around it"},
        {"P", "screenshot (tileworld-view-N.png)"},
        {"O", "overlay on/off;  H help;  Esc quit"},
    };
    enum { N = sizeof(help) / sizeof(help[0]) };
    struct overlay *o = &v->ov;
    float key_w = 0.0f, text_w = 0.0f;
    for (int k = 0; k < N; k++) {
        key_w = fmaxf(key_w, text_width(o, help[k][0]));
        text_w = fmaxf(text_w, text_width(o, help[k][1]));
    }
    const float pad = 4.0f * o->scale, gap = 12.0f * o->scale;
    const float w = key_w + gap + text_w + 2 * pad, h = (float)N * line_h(o) + 2 * pad;
    const float x = floorf(((float)fb_w - w) * 0.5f), y = floorf(((float)fb_h - h) * 0.5f);
    overlay_rect(o, x, y, x + w, y + h - 3 * o->scale, panel);
    for (int k = 0; k < N; k++) {
        const float ty = y + pad + (float)k * line_h(o);
        overlay_text(o, x + pad, ty, accent, help[k][0]);
        overlay_text(o, x + pad + key_w + gap, ty, white, help[k][1]);
    }
}

/* Colour swatches of the debug views on, along the bottom edge, wrapped
 * into as many rows as the window's width needs. */
static void draw_legend(struct viewer *v, int fb_w, int fb_h)
{
    struct overlay *o = &v->ov;
    const float margin = 6.0f * o->scale, sw = 8.0f * o->scale, gap = 3.0f * o->scale;
    const float space = 12.0f * o->scale;   /* between entries */
    int kinds[TW_DEBUG_KIND_COUNT], rows[TW_DEBUG_KIND_COUNT];
    float widths[TW_DEBUG_KIND_COUNT];
    int n = 0, row_count = 1;
    float x = margin;
    for (int k = 0; k < TW_DEBUG_KIND_COUNT; k++) {
        if (!(view_of((uint16_t)k) & v->debug))
            continue;
        const float w = sw + gap + text_width(o, tw_debug_kind_name((enum tw_debug_kind)k));
        if (x > margin && x + w > (float)fb_w - margin) {
            x = margin;
            row_count++;
        }
        kinds[n] = k;
        rows[n] = row_count - 1;
        widths[n++] = w;
        x += w + space;
    }
    const float top = (float)fb_h - margin - (float)row_count * line_h(o);
    for (int r = 0; r < row_count; r++) {
        float row_w = 0.0f;
        for (int k = 0; k < n; k++)
            if (rows[k] == r)
                row_w += widths[k] + space;
        const float y = top + (float)r * line_h(o);
        overlay_rect(o, margin - 2 * o->scale, y - 2 * o->scale, margin + row_w - space / 2,
                     y + line_h(o) - o->scale, panel);
    }
    x = margin;
    for (int k = 0; k < n; k++) {
        if (k > 0 && rows[k] != rows[k - 1])
            x = margin;
        const float y = top + (float)rows[k] * line_h(o);
        float c[4];
        tw_debug_kind_color((enum tw_debug_kind)kinds[k], c);
        c[3] = 1.0f;
        overlay_rect(o, x, y, x + sw, y + FONT_HEIGHT * o->scale, c);
        overlay_text(o, x + sw + gap, y, white, tw_debug_kind_name((enum tw_debug_kind)kinds[k]));
        x += widths[k] + space;
    }
}

/* A map of the cells around the camera, heading up, coloured as the cells
 * view (the paper's Figure 6), with the view's wedge; while frozen, also
 * the frozen camera's. */
static void draw_map(struct viewer *v, const struct tw_debug_box *boxes, size_t count, int fb_w)
{
    struct overlay *o = &v->ov;
    const struct tw_world_settings *s = tw_world_settings(v->world);
    const float size = floorf(fminf(150.0f * o->scale, 0.4f * (float)fb_w));
    const float margin = 6.0f * o->scale;
    const float x0 = (float)fb_w - margin - size, y0 = margin;
    const float cx = x0 + size * 0.5f, cy = y0 + size * 0.5f;
    const float mpp = 2.1f * s->view_distance / size;   /* metres per pixel */
    const float yaw = v->cam.yaw * pi_f / 180.0f;
    const float fx = sinf(yaw), fz = cosf(yaw), rx = -cosf(yaw), rz = sinf(yaw);
    const float *fp = v->shown.footprint;
    static const float frame_color[4] = {0.0f, 0.0f, 0.0f, 0.6f};
    overlay_rect(o, x0, y0, x0 + size, y0 + size, frame_color);
    o->clip_first = o->count;
    o->clip[0] = (int)x0;
    o->clip[1] = (int)y0;
    o->clip[2] = (int)size;
    o->clip[3] = (int)size;
    for (size_t k = 0; k < count; k++) {
        if (boxes[k].kind > TW_DEBUG_CELL_NOT_REACHED)
            continue;
        float off[3];
        tw_tiles_cell_offset(boxes[k].cell, v->cam.pos.cell, fp[0], fp[1], off);
        const float bx[4] = {boxes[k].box.min[0], boxes[k].box.max[0], boxes[k].box.max[0], boxes[k].box.min[0]};
        const float bz[4] = {boxes[k].box.min[2], boxes[k].box.min[2], boxes[k].box.max[2], boxes[k].box.max[2]};
        float qx[4], qy[4];
        for (int c = 0; c < 4; c++) {
            const float dx = off[0] + bx[c] - v->cam.pos.local[0];
            const float dz = off[2] + bz[c] - v->cam.pos.local[2];
            qx[c] = cx + (dx * rx + dz * rz) / mpp;
            qy[c] = cy - (dx * fx + dz * fz) / mpp;
        }
        float color[4];
        tw_debug_kind_color((enum tw_debug_kind)boxes[k].kind, color);
        color[3] = 0.5f + 0.5f * color[3];
        overlay_shape(o, qx, qy, color);
    }
    /* The wedge of a camera: its horizontal field of view out to the view distance. */
    const float aspect = (float)s->width / (float)s->height;
    const float half_h = atanf(tanf(s->fov_y * pi_f / 360.0f) * aspect);
    const struct tw_camera *cams[2] = {&v->cam, v->frozen ? &v->frozen_cam : NULL};
    static const float wedge_colors[2][4] = {{1.0f, 1.0f, 1.0f, 0.9f}, {1.0f, 0.85f, 0.3f, 0.9f}};
    for (int c = 0; c < 2; c++) {
        if (!cams[c])
            continue;
        float off[3];
        tw_tiles_cell_offset(cams[c]->pos.cell, v->cam.pos.cell, fp[0], fp[1], off);
        const float ex = off[0] + cams[c]->pos.local[0] - v->cam.pos.local[0];
        const float ez = off[2] + cams[c]->pos.local[2] - v->cam.pos.local[2];
        const float px = cx + (ex * rx + ez * rz) / mpp, py = cy - (ex * fx + ez * fz) / mpp;
        const float cyaw = cams[c]->yaw * pi_f / 180.0f;
        for (int side = -1; side <= 1; side += 2) {
            const float a = cyaw + (float)side * half_h;
            const float dx = sinf(a) * s->view_distance, dz = cosf(a) * s->view_distance;
            overlay_line(o, px, py, px + (dx * rx + dz * rz) / mpp, py - (dx * fx + dz * fz) / mpp,
                         1.5f * o->scale, wedge_colors[c]);
        }
        overlay_rect(o, px - 2 * o->scale, py - 2 * o->scale, px + 2 * o->scale, py + 2 * o->scale,
                     wedge_colors[c]);
    }
}

static int write_screenshot(struct viewer *v, const char *file, int fb_w, int fb_h)
{
    const struct tw_gl *gl = &v->ov.gl;
    const size_t w = (size_t)fb_w, h = (size_t)fb_h;
    uint8_t *rgba = malloc(w * h * 4), *rgb = malloc(w * h * 3);
    if (!rgba || !rgb) {
        free(rgba);
        free(rgb);
        fprintf(stderr, "tileworld view: out of memory for a screenshot\n");
        return TW_ERR_NOMEM;
    }
    gl->BindFramebuffer(GL_FRAMEBUFFER, 0);
    gl->ReadBuffer(GL_BACK);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 1);
    gl->ReadPixels(0, 0, fb_w, fb_h, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    for (size_t y = 0; y < h; y++)
        for (size_t x = 0; x < w; x++)
            memcpy(rgb + (y * w + x) * 3, rgba + ((h - 1 - y) * w + x) * 4, 3);
    char err[1200];
    const int rc = tw_outfile_write_png(file, rgb, (uint32_t)w, (uint32_t)h, err, sizeof(err));
    if (rc)
        fprintf(stderr, "tileworld view: %s\n", err);
    else if (!v->opt.cli.quiet)
        fprintf(stderr, "tileworld view: wrote %s (%zux%zu)\n", file, w, h);
    free(rgba);
    free(rgb);
    return rc;
}

static GLFWwindow *open_window(const struct options *o)
{
    /* 4.5 core first (glClipControl for reversed depth), then 3.3 core,
     * where the renderer falls back to standard depth. */
    static const int versions[2][2] = {{4, 5}, {3, 3}};
    for (int k = 0; k < 2; k++) {
        glfwDefaultWindowHints();
        glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, versions[k][0]);
        glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, versions[k][1]);
        glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
        glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
        glfwWindowHint(GLFW_DEPTH_BITS, 0);   /* the renderer draws into its own framebuffer */
        GLFWwindow *win = glfwCreateWindow((int)o->cli.world.width, (int)o->cli.world.height, "tileworld view", NULL, NULL);
        if (win)
            return win;
    }
    const char *why = NULL;
    glfwGetError(&why);
    fprintf(stderr, "tileworld view: cannot open an OpenGL 3.3 core window: %s\n",
            why ? why : "unknown reason");
    return NULL;
}

static void on_glfw_error(int code, const char *msg)
{
    /* Failures are reported where they happen (glfwGetError); a refused
     * 4.5 context on the way to 3.3 is no error at all. */
    (void)code;
    (void)msg;
}

int main(int argc, char **argv)
{
    struct viewer v;
    memset(&v, 0, sizeof(v));
    parse_options(argc, argv, &v.opt);
    const struct options *o = &v.opt;
    const struct tw_log log = {tw_cli_log, &v.opt.cli};
    tw_cli_world_load(&o->cli, 0, &log, &v.shown);
    /* With --path, the path to fly; for the keyboard, a one-key path: the
     * start of the street path, where a camera is on a street at eye height. */
    struct tw_path path = {0};
    const char *path_name = o->cli.path ? o->cli.path : "street";
    tw_cli_load_path(&o->cli, path_name, !o->cli.path ? 1 : o->cli.frames ? o->cli.frames : 300,
                     v.shown.footprint, &path);
    if (path.count == 0)
        tw_cli_fail(program, "--path", "'%s' has no camera keys", path_name);
    v.cam = path.keys[0];
    /* Without a path, --frames alone bounds the run; with one, its length. */
    const uint64_t frames = o->cli.path ? path.count : o->cli.frames;

    int rc = 1;
    glfwSetErrorCallback(on_glfw_error);
    if (!glfwInit()) {
        const char *why = NULL;
        glfwGetError(&why);
        fprintf(stderr, "tileworld view: cannot open a window (%s); without a display, run it "
                        "under xvfb-run\n", why ? why : "GLFW failed to start");
        tw_path_finish(&path);
        tw_cli_world_finish(&v.shown);
        return 1;
    }
    v.win = open_window(o);
    if (!v.win)
        goto out;
    glfwMakeContextCurrent(v.win);
    glfwSwapInterval(frames ? 0 : 1);
    glfwSetWindowUserPointer(v.win, &v);

    struct tw_world_settings ws = o->cli.world;
    tw_cli_world_apply(&v.shown, &ws);
    ws.get_proc = glfw_get_proc;
    ws.log = log;
    int err = tw_world_create_tuned(&ws, &o->cli.tuning, &v.world);
    if (err) {
        /* The library has said why in one line; bad settings are the user's. */
        if (v.opt.cli.errors_logged == 0)
            fprintf(stderr, "tileworld view: cannot set up the world: %s\n", tw_error_to_str(err));
        rc = tw_cli_world_exit_status(err);
        goto out;
    }
    err = overlay_init(&v.ov, &log);
    if (err)
        goto out;
    v.debug = o->debug;
    err = tw_world_set_debug(v.world, v.debug);
    if (err)
        goto out;
    v.show_overlay = !o->no_overlay;
    v.speed = 15.0f;
    set_title(&v);
    glfwSetKeyCallback(v.win, on_key);
    glfwSetMouseButtonCallback(v.win, on_mouse_button);
    glfwSetCursorPosCallback(v.win, on_cursor);
    glfwSetScrollCallback(v.win, on_scroll);
    glfwGetCursorPos(v.win, &v.mouse_x, &v.mouse_y);

    double last = glfwGetTime(), ms_total = 0.0;
    while (!glfwWindowShouldClose(v.win) && (!frames || v.frame < frames)) {
        glfwPollEvents();
        const double now = glfwGetTime();
        const float dt = (float)fmin(now - last, 0.1);
        last = now;
        if (v.frame == 0) {
            v.fps_since = now;
        } else if (++v.fps_frames, now - v.fps_since >= 0.5) {
            v.fps = v.fps_frames / (now - v.fps_since);
            v.fps_since = now;
            v.fps_frames = 0;
        }
        if (o->cli.path)
            v.cam = path.keys[v.frame];
        else
            fly(&v, dt);
        if (o->freeze_at && v.frame + 1 == o->freeze_at && !v.frozen)
            v.freeze_pending = true;

        if (v.frozen) {
            err = tw_world_frame_fixed(v.world, &v.cam, v.frozen_set, v.frozen_count, &v.st);
        } else {
            const bool freezing = v.freeze_pending;
            if (freezing) {
                tw_world_record_draws(v.world, true);
                err = tw_world_set_debug(v.world, TW_DEBUG_ALL);
            }
            if (!err)
                err = tw_world_frame(v.world, &v.cam, &v.st);
            if (!err)
                err = tw_world_finish(v.world, &v.st);
            if (freezing) {
                v.freeze_pending = false;
                if (!err)
                    err = take_freeze(&v);
                tw_world_record_draws(v.world, false);
                if (!err)
                    err = tw_world_set_debug(v.world, v.debug);
            }
        }
        if (err) {
            fprintf(stderr, "tileworld view: frame %llu failed: %s\n",
                    (unsigned long long)v.frame + 1, tw_error_to_str(err));
            goto out;
        }
        ms_total += v.st.ms_frame;
        size_t box_count = 0;
        const struct tw_debug_box *boxes = shown_boxes(&v, &box_count);
        if (box_count)
            tw_world_draw_debug(v.world, boxes, box_count);
        int fb_w = 0, fb_h = 0;
        glfwGetFramebufferSize(v.win, &fb_w, &fb_h);
        if (fb_w > 0 && fb_h > 0) {
            tw_world_blit(v.world, 0, (uint32_t)fb_w, (uint32_t)fb_h);
            v.ov.scale = fb_w >= 1200 && fb_h >= 600 ? 2.0f : 1.0f;
            if (v.show_overlay) {
                draw_stats(&v);
                if (v.debug)
                    draw_legend(&v, fb_w, fb_h);
                if (v.debug & TW_DEBUG_CELLS)
                    draw_map(&v, boxes, box_count, fb_w);
            }
            if (v.show_help)
                draw_help(&v, fb_w, fb_h);
            overlay_draw(&v.ov, fb_w, fb_h);
        }
        v.frame++;
        if (v.screenshot_pending && fb_w > 0) {
            char name[64];
            snprintf(name, sizeof(name), "tileworld-view-%04u.png", ++v.screenshot_count);
            write_screenshot(&v, name, fb_w, fb_h);
            v.screenshot_pending = false;
        }
        /* --screenshot: after the last frame, or before the window closes. */
        if (o->screenshot && ((frames && v.frame == frames) || glfwWindowShouldClose(v.win))) {
            if (fb_w <= 0 || write_screenshot(&v, o->screenshot, fb_w, fb_h)) {
                rc = EXIT_USAGE;
                goto out;
            }
        }
        glfwSwapBuffers(v.win);
    }
    if (!o->cli.quiet)
        fprintf(stderr, "tileworld view: %llu frames, %s, %.2f ms per frame on average\n",
                (unsigned long long)v.frame, tw_method_name(tw_world_settings(v.world)->method),
                v.frame ? ms_total / (double)v.frame : 0.0);
    rc = 0;
out:
    unfreeze(&v);
    overlay_finish(&v.ov);
    tw_cli_world_destroy(v.world);
    if (v.win)
        glfwDestroyWindow(v.win);
    glfwTerminate();
    tw_path_finish(&path);
    tw_cli_world_finish(&v.shown);
    return tw_cli_exit(program, rc);
}
