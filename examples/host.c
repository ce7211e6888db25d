/*
 * host.c: tileworld embedded in a program of your own.
 *
 * A host brings the world generator (which prototype each cell shows) and
 * the camera; tileworld streams the tiles in view, culls them and draws
 * them. This one renders headless (OSMesa), chooses its tiles with a
 * checkerboard of two prototypes, walks 100 frames down a street, and checks
 * what it got back. It exits 0 when every check holds, else 1 with a message.
 *
 * Build it against an installed tileworld:
 *     cc -std=c11 host.c $(pkg-config --cflags --libs tileworld tileworld-headless) -o host
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "tileworld/context.h"   /* the headless GL context (tileworld-headless) */
#include "tileworld/runtime.h"   /* the world: tw_world_*, cameras, statistics */
#include "tileworld/tilesets.h"  /* the built-in tilesets */

enum { WIDTH = 320, HEIGHT = 180, FRAMES = 100 };

/* The host's world generator: even cells (i + j even) show one prototype,
 * odd cells another. It must be a pure function of the cell; counting the
 * calls in user does not change what it returns. */
struct checkerboard {
    uint32_t even, odd;     /* the two prototypes */
    uint64_t calls;         /* how often tileworld asked */
};

static uint32_t checkerboard_pick(const struct checkerboard *cb, struct tw_cell c)
{
    /* Parity through unsigned arithmetic: defined for every int64_t cell. */
    return (((uint64_t)c.i + (uint64_t)c.j) & 1u) ? cb->odd : cb->even;
}

static uint32_t select_checkerboard(void *user, struct tw_cell cell)
{
    struct checkerboard *cb = user;
    cb->calls++;
    return checkerboard_pick(cb, cell);
}

/* Prints the first failed check; returns 1 so that main can count them. */
static int fail(uint32_t frame, const char *what)
{
    fprintf(stderr, "host: frame %u: %s\n", frame, what);
    return 1;
}

int main(void)
{
    /* tileworld never prints: its messages go to a logger. This one writes
     * warnings and errors to stderr. */
    const struct tw_log log = {tw_log_stderr, (void *)(intptr_t)TW_LOG_WARN};
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts = NULL;
    struct tw_world *world = NULL;
    struct checkerboard cb = {0};
    struct tw_world_settings s = {0};
    uint64_t even_drawn = 0, odd_drawn = 0;
    int failures = 0, err;

    /* 1. A GL context, current on this thread. A host with a window passes
     *    its own loader as get_proc instead. */
    if ((err = tw_context_create_headless(WIDTH, HEIGHT, &log, &ctx)) != TW_OK)
        goto done;

    /* 2. A tileset: the procedural city, deterministic for its seed (1). */
    if ((err = tw_tilesets_builtin("city", 1, 0, &log, &ts)) != TW_OK)
        goto done;

    /* 3. The world. Zero fields take their defaults; the tileset and the
     *    checkerboard are borrowed and must outlive the world. */
    cb.even = 0;
    cb.odd = ts->prototype_count - 1;
    s.tileset = ts;
    s.selection.fn = select_checkerboard;
    s.selection.user = &cb;
    s.method = TW_METHOD_TILEQUERY_CHC;   /* tile queries + CHC++: the system */
    s.width = WIDTH;
    s.height = HEIGHT;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    if ((err = tw_world_create(&s, &world)) != TW_OK)
        goto done;
    /* Keep the list of clusters each frame draws, to check it below. */
    tw_world_record_draws(world, true);

    /* 4. The walk: eye height on the street at x = 0 (streets run along
     *    every tile border), looking down +z, 1.5 m a frame. Past the end of
     *    the cell the runtime moves the offset into the next cell itself. */
    for (uint32_t f = 0; f < FRAMES && failures == 0; f++) {
        struct tw_camera cam = {{{0, 0}, {0.0f, 1.7f, 2.0f + 1.5f * (float)f}}, 10.0f, 2.0f};
        struct tw_frame_stats st;
        const uint64_t calls_before = cb.calls;
        if ((err = tw_world_frame(world, &cam, &st)) != TW_OK)
            goto done;

        if (st.frame != f + 1)
            failures += fail(f, "the frame counter does not count frames");
        if (st.triangles == 0 || st.tiles_visible == 0)
            failures += fail(f, "nothing was drawn");
        if (cb.calls == calls_before)
            failures += fail(f, "the selection callback was not called");

        /* Every drawn cluster lies in a cell that shows the prototype our
         * callback chose for it, and their triangles are what the frame
         * reports. */
        size_t n = 0;
        const struct tw_drawn_cluster *drawn = tw_world_drawn(world, &n);
        uint64_t triangles = 0;
        for (size_t k = 0; k < n; k++) {
            const struct tw_drawn_cluster *d = &drawn[k];
            /* Far tiles are drawn at a coarser level of detail: its own
             * prototype holds the clusters (level 0 is ours). */
            const struct tw_prototype *drawn_proto =
                tw_world_level(world, d->prototype, d->level, NULL);
            if (d->prototype != checkerboard_pick(&cb, d->cell) || !drawn_proto ||
                (d->level == 0 && drawn_proto != &ts->prototypes[d->prototype]) ||
                d->cluster >= drawn_proto->cluster_count) {
                failures += fail(f, "a drawn cluster is not the callback's choice");
                break;
            }
            triangles += drawn_proto->clusters[d->cluster].triangle_count;
            if (d->prototype == cb.even)
                even_drawn++;
            else
                odd_drawn++;
        }
        if (n == 0 || triangles != st.triangles)
            failures += fail(f, "the recorded draws do not add up to the frame's triangles");
    }
    if (failures == 0 && (even_drawn == 0 || odd_drawn == 0))
        failures += fail(FRAMES, "the walk did not see both squares of the checkerboard");
    if (failures == 0)
        printf("host: %d frames, %llu calls to the selection callback, %llu + %llu clusters drawn: ok\n",
               FRAMES, (unsigned long long)cb.calls, (unsigned long long)even_drawn,
               (unsigned long long)odd_drawn);

done:
    /* 5. Destroy in reverse order: the world before its tileset and context
     *    (each destroy accepts NULL, so one exit serves every path). */
    if (err != TW_OK)
        fprintf(stderr, "host: %s\n", tw_error_to_str(err));
    tw_world_destroy(world);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return err != TW_OK || failures ? EXIT_FAILURE : EXIT_SUCCESS;
}
