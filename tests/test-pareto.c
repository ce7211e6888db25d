/* The Pareto fronts of a sweep (tools/tileworld/pareto.h) on figures made up
 * for the purpose, where the front is known: dominated points (slower and
 * no fewer errors; as fast with more errors) are off it, equal points both
 * on it, the oracle never; the same for the front of image error (pixels
 * differing from full detail); speed-ups against T=0 or the defaults; the
 * fronts again by another time (tw_pareto_mark_fronts); sweep.md names the
 * fronts, with the image error in its table. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tools/tileworld/pareto.h"
#include "tests/check.h"

enum { VALUES = 3, METHODS = 4 };

static const double values[VALUES] = {0, 4, 16};
static const enum tw_method methods[METHODS] = {TW_METHOD_CHC, TW_METHOD_TILEQUERY_CHC,
                                                TW_METHOD_ORACLE, TW_METHOD_BOX_ORACLE};

/* Mean CPU ms and missed pixels (over 10 frames) per value and method. */
static void set(struct tw_method_figures *fg, double cpu, uint64_t missed, uint64_t depth)
{
    fg->used = true;
    fg->frames = 10;
    fg->mean_cpu_ms = cpu;
    fg->missed_pixels_total = missed;
    fg->depth_errors_total = depth;
}

/* The share of the image a frame that differs from full detail. */
static void set_lod(struct tw_method_figures *fg, double fraction)
{
    fg->lod_pixel_fraction = fraction;
    fg->lod_pixels_total = (uint64_t)(fraction * 160 * 90 * fg->frames);
}

static const struct tw_pareto_point *find(const struct tw_pareto_point *p, uint32_t n,
                                          enum tw_method m, double value)
{
    for (uint32_t k = 0; k < n; k++)
        if (p[k].method == m && p[k].value == value)
            return &p[k];
    CHECK(!"point not found");
    return &p[0];
}

static char *read_all(const char *file)
{
    FILE *f = fopen(file, "rb");
    if (!f)
        return NULL;
    static char text[16384];
    const size_t n = fread(text, 1, sizeof(text) - 1, f);
    text[n] = '\0';
    fclose(f);
    return text;
}

int main(void)
{
    struct tw_method_figures figures[VALUES][TW_METHOD_ALL];
    bool conservative[VALUES][TW_METHOD_ALL];
    memset(figures, 0, sizeof(figures));
    memset(conservative, 0, sizeof(conservative));
    /* chc: T=0 is beaten by tilequery+chc T=0 (faster, as few errors);
     * T=16 is as fast as T=4 with more errors. */
    set(&figures[0][TW_METHOD_CHC], 10.0, 0, 0);
    set(&figures[1][TW_METHOD_CHC], 8.0, 5, 7);
    set(&figures[2][TW_METHOD_CHC], 8.0, 500, 2);
    /* tilequery+chc: T=4 is beaten by its own T=0; T=16 the fastest. */
    set(&figures[0][TW_METHOD_TILEQUERY_CHC], 9.0, 0, 0);
    set(&figures[1][TW_METHOD_TILEQUERY_CHC], 9.5, 20, 20);
    set(&figures[2][TW_METHOD_TILEQUERY_CHC], 7.0, 100, 100);
    /* The oracles (limits) beat everything and are on no front. */
    for (int k = 0; k < VALUES; k++) {
        set(&figures[k][TW_METHOD_ORACLE], 1.0, 0, 0);
        set(&figures[k][TW_METHOD_BOX_ORACLE], 1.5, 0, 0);
        conservative[k][TW_METHOD_ORACLE] = conservative[k][TW_METHOD_BOX_ORACLE] = true;
    }
    conservative[0][TW_METHOD_CHC] = conservative[0][TW_METHOD_TILEQUERY_CHC] = true;
    /* Image error: chc T=4 is as fast as chc T=16 with more; tilequery+chc
     * T=0 beats chc T=0 (faster, as little) and its own T=4 (slower, more);
     * the oracles have none and are still on no front. */
    set_lod(&figures[0][TW_METHOD_CHC], 0.0);
    set_lod(&figures[1][TW_METHOD_CHC], 0.02);
    set_lod(&figures[2][TW_METHOD_CHC], 0.01);
    set_lod(&figures[0][TW_METHOD_TILEQUERY_CHC], 0.0);
    set_lod(&figures[1][TW_METHOD_TILEQUERY_CHC], 0.03);
    set_lod(&figures[2][TW_METHOD_TILEQUERY_CHC], 0.05);

    struct tw_pareto_point points[VALUES * METHODS];
    const uint32_t n = VALUES * METHODS;
    tw_pareto_points(values, VALUES, (const struct tw_method_figures(*)[TW_METHOD_ALL])figures,
                     (const bool(*)[TW_METHOD_ALL])conservative, methods, METHODS, NULL, 0,
                     points);
    const struct tw_pareto_point *chc0 = find(points, n, TW_METHOD_CHC, 0);
    const struct tw_pareto_point *chc4 = find(points, n, TW_METHOD_CHC, 4);
    const struct tw_pareto_point *chc16 = find(points, n, TW_METHOD_CHC, 16);
    const struct tw_pareto_point *tq0 = find(points, n, TW_METHOD_TILEQUERY_CHC, 0);
    const struct tw_pareto_point *tq4 = find(points, n, TW_METHOD_TILEQUERY_CHC, 4);
    const struct tw_pareto_point *tq16 = find(points, n, TW_METHOD_TILEQUERY_CHC, 16);
    CHECK(!chc0->front && chc4->front && !chc16->front);
    CHECK(tq0->front && !tq4->front && tq16->front);
    for (int k = 0; k < VALUES; k++)
        for (int m = 2; m < METHODS; m++)
            CHECK(!find(points, n, methods[m], values[k])->front &&
                  !find(points, n, methods[m], values[k])->front_depth &&
                  !find(points, n, methods[m], values[k])->front_lod);
    /* Depth errors: chc T=16 (2 per 10 frames) now beats chc T=4 (7). */
    CHECK(chc16->front_depth && !chc4->front_depth && tq0->front_depth && tq16->front_depth);
    CHECK(chc4->missed_per_frame == 0.5 && chc16->depth_errors_per_frame == 0.2);
    CHECK(chc0->conservative && !chc4->conservative);
    CHECK(!chc0->front_lod && !chc4->front_lod && chc16->front_lod);
    CHECK(tq0->front_lod && !tq4->front_lod && tq16->front_lod);
    CHECK(chc4->lod_fraction == 0.02 && tq0->lod_fraction == 0.0);
    /* Speed-ups against each method's T=0. */
    CHECK(chc4->speedup == 10.0 / 8.0 && tq16->speedup == 9.0 / 7.0 && chc0->speedup == 1.0);

    /* Equal points: neither beats the other. Against the defaults. */
    set(&figures[1][TW_METHOD_CHC], 7.0, 1000, 1000);
    set(&figures[2][TW_METHOD_CHC], 7.0, 1000, 1000);
    struct tw_method_figures defaults[TW_METHOD_ALL];
    memset(defaults, 0, sizeof(defaults));
    set(&defaults[TW_METHOD_CHC], 14.0, 0, 0);
    set(&defaults[TW_METHOD_TILEQUERY_CHC], 14.0, 0, 0);
    tw_pareto_points(values, VALUES, (const struct tw_method_figures(*)[TW_METHOD_ALL])figures,
                     (const bool(*)[TW_METHOD_ALL])conservative, methods, METHODS, defaults,
                     UINT32_MAX, points);
    CHECK(!chc4->front && !chc16->front);   /* tilequery+chc T=16 is as fast with fewer */
    set(&figures[2][TW_METHOD_TILEQUERY_CHC], 7.0, 1000, 1000);
    tw_pareto_points(values, VALUES, (const struct tw_method_figures(*)[TW_METHOD_ALL])figures,
                     (const bool(*)[TW_METHOD_ALL])conservative, methods, METHODS, defaults,
                     UINT32_MAX, points);
    CHECK(chc4->front && chc16->front && tq16->front);
    CHECK(chc4->speedup == 2.0);
    /* Image error: all three as fast, chc T=16 with the least. */
    CHECK(chc16->front_lod && !chc4->front_lod && !tq16->front_lod && tq0->front_lod);

    /* The fronts again by another time (GPU time on a GPU): chc T=0 the
     * fastest conservative point now, chc T=4 of unknown time (NaN) on no
     * front and beating none; the oracles still on none. */
    double time[VALUES * METHODS];
    for (uint32_t k = 0; k < n; k++)
        time[k] = points[k].cpu_ms;
    for (uint32_t k = 0; k < n; k++) {
        if (&points[k] == chc0)
            time[k] = 0.5;
        if (&points[k] == chc4)
            time[k] = NAN;
    }
    tw_pareto_mark_fronts(points, n, time);
    CHECK(chc0->front && chc0->front_depth && !chc4->front && !chc4->front_depth);
    CHECK(!tq0->front && !tq0->front_depth);   /* slower than chc T=0, as few errors */
    /* chc T=0 (no image error) beats every point but the oracles now. */
    CHECK(chc0->front_lod && !chc4->front_lod && !tq0->front_lod && !chc16->front_lod);
    CHECK(!find(points, n, TW_METHOD_ORACLE, 0)->front_lod);
    CHECK(!find(points, n, TW_METHOD_ORACLE, 0)->front);
    tw_pareto_mark_fronts(points, n, NULL);     /* by cpu_ms again */
    CHECK(!chc0->front && tq0->front && chc4->front);
    CHECK(!chc0->front_lod && tq0->front_lod && chc16->front_lod);

    /* sweep.md names the front, each point with its speed-up and error. */
    char dir[] = "/tmp/test-pareto-XXXXXX";
    CHECK(mkdtemp(dir) != NULL);
    char file[64], err[256];
    snprintf(file, sizeof(file), "%s/sweep.md", dir);
    struct tw_outfile o;
    CHECK(tw_outfile_open(&o, file, err, sizeof(err)) == 0);
    tw_pareto_write_md(&o, "T", "defaults", true, points, n);
    CHECK(tw_outfile_commit(&o, err, sizeof(err)) == 0);
    const char *md = read_all(file);
    CHECK(md != NULL);
    if (md) {
        CHECK(strstr(md, "| missed pixels / frame | depth errors / frame | pixels differing from "
                         "full detail (%) | conservative | on the front |\n"));
        CHECK(strstr(md, "| chc | 4 | 7.00 | 2.00x | 100.0 | 100.0 | 2.000 | no | yes (both) |"));
        CHECK(strstr(md, "| oracle | 0 | 1.00 | - | 0.0 | 0.0 | 0.000 | yes | no (a limit) |"));
        CHECK(strstr(md, "| box-oracle | 4 | 1.50 | - | 0.0 | 0.0 | 0.000 | yes | no (a limit) |"));
        CHECK(strstr(md, "| chc | 0 | 10.00 | 1.40x | 0.0 | 0.0 | 0.000 | yes | no |"));
        CHECK(strstr(md, "- tilequery+chc T=0: 9.00 ms CPU per frame, speed-up 1.56 over "
                         "defaults, 0.0 missed pixels per frame (conservative)"));
        CHECK(!strstr(md, "- chc T=0:"));
        CHECK(!strstr(md, "- oracle"));
        /* The front of image error, named last: chc T=16 and tilequery+chc
         * T=0, not chc T=4 (as fast, more error). */
        const char *lod = strstr(md, "\n**The front of CPU time against image error (pixels "
                                     "differing from full detail)** (no other point is as fast "
                                     "with as little image error, and better in one;");
        CHECK(lod && lod > strstr(md, "**The front of CPU time against depth errors**"));
        if (lod) {
            CHECK(strstr(lod, "- chc T=16: 7.00 ms CPU per frame, speed-up 2.00 over defaults, "
                              "1.000 % of the pixels differing from full detail per frame\n"));
            CHECK(strstr(lod, "- tilequery+chc T=0: 9.00 ms CPU per frame, speed-up 1.56 over "
                              "defaults, 0.000 % of the pixels differing from full detail per "
                              "frame (conservative)\n"));
            CHECK(!strstr(lod, "- chc T=4:") && !strstr(lod, "- tilequery+chc T=16:"));
        }
    }
    /* Not verified: no image error in the table, no front. */
    CHECK(tw_outfile_open(&o, file, err, sizeof(err)) == 0);
    tw_pareto_write_md(&o, "T", "defaults", false, points, n);
    CHECK(tw_outfile_commit(&o, err, sizeof(err)) == 0);
    md = read_all(file);
    CHECK(md && strstr(md, "| chc | 4 | 7.00 | 2.00x | 100.0 | 100.0 | - | no | - |") &&
          !strstr(md, "**The front"));
    unlink(file);
    rmdir(dir);
    return check_summary("test-pareto");
}
