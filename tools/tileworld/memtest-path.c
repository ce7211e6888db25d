/* tileworld memtest: the camera's walk, a long built-in path or a CSV
 * repeated end to end (memtest-private.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/tileworld/memtest-private.h"

static const char program[] = TW_MEMTEST_PROGRAM;

/* What one run may cost, refused before it starts: as many frames as walk's
 * --frames allows (weeks of rendering on a CPU), and rows of memory.csv
 * (about 250 bytes each). */
#define MAX_FRAMES 10000000.0
#define MAX_ROWS 1000000.0

/* Metres from a to b (cells as integers first: exact far from the origin). */
static double step_m(const struct tw_camera *a, const struct tw_camera *b, const float fp[2])
{
    const double dx = (double)(b->pos.cell.i - a->pos.cell.i) * fp[0] +
                      ((double)b->pos.local[0] - a->pos.local[0]);
    const double dy = (double)b->pos.local[1] - a->pos.local[1];
    const double dz = (double)(b->pos.cell.j - a->pos.cell.j) * fp[1] +
                      ((double)b->pos.local[2] - a->pos.local[2]);
    return sqrt(dx * dx + dy * dy + dz * dz);
}

int tw_memtest_walk_next(struct tw_memtest_walk *w, struct tw_camera *cam, double *moved)
{
    bool jump = false;
    if (w->next == w->path.count) {
        w->next = 0;
        w->rep++;
        jump = true;
    }
    *cam = w->path.keys[w->next++];
    const int64_t limit = (int64_t)1 << 62;
    const double di = (double)w->shift_i * (double)w->rep, dj = (double)w->shift_j * (double)w->rep;
    if (fabs(di) > (double)limit || fabs(dj) > (double)limit)
        return TW_ERR_LIMIT;
    cam->pos.cell.i += w->shift_i * w->rep;
    cam->pos.cell.j += w->shift_j * w->rep;
    *moved = w->have_last && !jump ? step_m(&w->last, cam, w->footprint) : 0.0;
    w->last = *cam;
    w->have_last = true;
    return TW_OK;
}

void tw_memtest_walk_init(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                          struct tw_memtest_walk *w)
{
    memset(w, 0, sizeof(*w));
    w->footprint[0] = shown->footprint[0];
    w->footprint[1] = shown->footprint[1];
    const char *name = o->cli.path;
    if (strcmp(name, "straight") == 0 || strcmp(name, "wander") == 0) {
        /* 2 m a frame (tw_path_builtin's own speed); turns cost a little. */
        const double frames = ceil(o->distance_m / 2.0 * 1.05) + 16.0;
        if (frames > MAX_FRAMES)
            tw_cli_fail(program, "--distance", "%g km would take about %.0f frames, more than "
                        "memtest's limit of %.0f: give a shorter --distance",
                        o->distance_m / 1000.0, frames, MAX_FRAMES);
        const int err = tw_path_builtin(name, o->cli.world.selection.seed, (uint32_t)frames,
                                              0.0f, w->footprint[0], w->footprint[1], &w->path);
        if (err) {
            tw_cli_message(program, "--path %s: %s", name, tw_error_to_str(err));
            exit(1);
        }
        if (tw_path_translate(&w->path, o->cli.start_cell.i, o->cli.start_cell.j))
            tw_cli_fail(program, "--start-cell", "the translated path overflows the grid");
    } else {
        if (strcmp(name, "street") == 0 || strcmp(name, "flyover") == 0 ||
            strcmp(name, "forest") == 0 || strcmp(name, "teleport") == 0 ||
            strcmp(name, "spin") == 0)
            tw_cli_fail(program, "--path", "memtest walks straight, wander or a CSV file, not '%s'",
                        name);
        tw_cli_load_path(&o->cli, name, 0, w->footprint, &w->path);
    }
    if (w->path.count == 0)
        tw_cli_fail(program, "--path", "'%s' has no camera keys", name);
    const struct tw_camera *first = &w->path.keys[0], *last = &w->path.keys[w->path.count - 1];
    w->shift_i = last->pos.cell.i - first->pos.cell.i;
    w->shift_j = last->pos.cell.j - first->pos.cell.j;
    double length = 0.0;
    for (uint32_t k = 1; k < w->path.count; k++)
        length += step_m(&w->path.keys[k - 1], &w->path.keys[k], w->footprint);
    if (!(length > 0.0))
        tw_cli_fail(program, "--path", "'%s' does not move the camera: no distance to cover", name);
    /* Each repetition moves length metres in count frames (its first frame
     * moves none): the frames are known before one is rendered. */
    const double frames = ceil(o->distance_m / length) * (double)w->path.count;
    if (frames > MAX_FRAMES)
        tw_cli_fail(program, "--path", "'%s' moves %g m over its %u rows: %g km would take about "
                    "%.0f frames, more than memtest's limit of %.0f; give a path that moves "
                    "farther a row, or a shorter --distance", name, length, w->path.count,
                    o->distance_m / 1000.0, frames, MAX_FRAMES);
    const double rows = fmin(frames, floor(o->distance_m / o->every_m)) + 2.0;
    if (rows > MAX_ROWS)
        tw_cli_fail(program, "--every", "a row every %g m over %g km makes about %.0f rows of "
                    "memory.csv, more than memtest's limit of %.0f; give a larger --every or a "
                    "shorter --distance", o->every_m, o->distance_m / 1000.0, rows, MAX_ROWS);
}

void tw_memtest_walk_restart(struct tw_memtest_walk *w)
{
    w->next = 0;
    w->rep = 0;
    w->have_last = false;
}
