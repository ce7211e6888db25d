/*
 * What the GL tests that draw the built-in tilesets set up alike: a logger
 * that prints warnings and errors, a headless context with a built-in
 * tileset, and the world settings each test starts from.
 */
#ifndef TW_TESTS_HEADLESS_WORLD_H
#define TW_TESTS_HEADLESS_WORLD_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime/runtime-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

static void log_stderr(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    if (level <= TW_LOG_WARN)
        fprintf(stderr, "log: %s\n", msg);
}

static const struct tw_log test_log = {log_stderr, NULL};

/* Fixed views of a city world that the tests compare methods from: at eye
 * height on streets and across blocks, and one from 45 m up. */
static const struct tw_camera city_views[5] = {
    {{{0, 0}, {0.0f, 1.7f, 2.0f}}, 10.0f, 3.0f},
    {{{3, -2}, {0.5f, 1.7f, 40.0f}}, 180.0f, 0.0f},
    {{{-5, 7}, {30.0f, 1.7f, 0.2f}}, 95.0f, 5.0f},
    {{{1, 1}, {10.0f, 45.0f, 10.0f}}, 40.0f, -12.0f},
    {{{2, 2}, {0.1f, 1.7f, 0.1f}}, 225.0f, 1.0f},
};

/* A headless context of width x height and the built-in tileset named
 * tileset, made with seed, both logging to test_log. False, after a message
 * and with nothing left to destroy, if either cannot be made. */
static inline bool open_headless(uint32_t width, uint32_t height, const char *tileset, uint64_t seed,
                          struct tw_context **ctx, struct tw_tileset **ts)
{
    *ts = NULL;
    if (tw_context_create_headless(width, height, &test_log, ctx) != TW_OK) {
        fprintf(stderr, "cannot create the headless context\n");
        return false;
    }
    if (tw_tilesets_builtin(tileset, seed, 0, &test_log, ts) != TW_OK) {
        fprintf(stderr, "cannot build the %s tileset\n", tileset);
        tw_context_destroy(*ctx);
        *ctx = NULL;
        return false;
    }
    return true;
}

/* A world of ts drawn into ctx at width x height, its cells chosen with
 * seed, out to view_distance metres, logging to test_log; the test sets the
 * rest (method, verify, ...). */
static inline struct tw_world_settings world_settings(struct tw_context *ctx, const struct tw_tileset *ts,
                                               uint32_t width, uint32_t height, uint64_t seed,
                                               float view_distance)
{
    struct tw_world_settings s = {0};
    s.tileset = ts;
    s.selection.seed = seed;
    s.width = width;
    s.height = height;
    s.view_distance = view_distance;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = test_log;
    /* The levels' store of the test run (tests/meson.build), as a program's. */
    const char *store = getenv("TW_LEVELS_CACHE");
    s.levels_cache_dir = store && store[0] && strcmp(store, "off") != 0 ? store : NULL;
    return s;
}

#endif
