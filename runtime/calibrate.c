/* The cost calibration (calibrate.h, DESIGN §14). */
#include "runtime/calibrate.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define QUERY_BATCH 48u
#define DRAW_BATCH 24u
#define DRAW_MAX_TRIANGLES 512u
#define REPEATS 2
#define ROUNDS 5

void tw_calibrate_nominal(struct tw_calibration *out)
{
    /* The city's, from tileworld info --calibrate on llvmpipe, two cores
     * (2026-12-03; the draw figures are of a hidden cluster). */
    memset(out, 0, sizeof(*out));
    out->query_ms = 0.056;
    out->query_batched_ms = 0.012;
    out->query_box_ms = 0.0013;
    out->query_pixel_ns = 1.9;
    out->draw_ms = 0.0125;
    out->triangle_ns = 115.0;
    out->draw_pixel_ns = 8.5;
}

/* The focal length in pixels of a height-pixel image with fov_y. */
static double focal_pixels(uint32_t height, float fov_y)
{
    return 0.5 * (double)height / tan(0.5 * (double)fov_y * 3.14159265358979 / 180.0);
}

/* The pixels of the screen rectangle of box b moved by offset (NULL: none)
 * in view v, as the cost model counts them (cull/chc-queries.c): the calibration's
 * pixel figures are per such pixel. */
static double model_pixels(const struct tw_view *v, double screen, const struct tw_box *b,
                           const float offset[3])
{
    return screen * tw_cull_box_screen_fraction(v, b, offset);
}

/* A cube of side a centred on the view axis at distance z, and its pixels
 * (its near face's, what a query with near faces only draws). */
static struct tw_box axis_cube(float z, float a, const struct tw_view *v, double screen,
                               double *pixels)
{
    const struct tw_box b = {{-0.5f * a, -0.5f * a, z - 0.5f * a}, {0.5f * a, 0.5f * a, z + 0.5f * a}};
    *pixels = model_pixels(v, screen, &b, NULL);
    return b;
}

/* The offset that centres box b on the view axis z metres ahead. */
static void probe_offset(const struct tw_box *b, float z, float offset[3])
{
    offset[0] = -0.5f * (b->min[0] + b->max[0]);
    offset[1] = -0.5f * (b->min[1] + b->max[1]);
    offset[2] = z - 0.5f * (b->min[2] + b->max[2]);
}

/* CPU milliseconds per query of count boxes (best of REPEATS batches):
 * queries issued in a batch and read at its end (round_trip false), or
 * each read as soon as it is issued, as a traversal that needs the answer
 * to go on does (true: the GPU's round trip included). */
static double time_queries(struct tw_renderer *r, const struct tw_query_backend *be,
                           const struct tw_box *boxes, uint32_t count, bool round_trip)
{
    static const float zero[3] = {0, 0, 0};
    uint32_t handles[QUERY_BATCH];
    double best = INFINITY;
    for (int rep = -1; rep < REPEATS; rep++) {
        const uint32_t n = rep < 0 ? 2 : QUERY_BATCH;   /* rep -1: warm-up */
        tw_renderer_finish(r);
        const double t0 = tw_renderer_cpu_ms();
        for (uint32_t k = 0; k < n; k++) {
            handles[k] = be->issue(be->ctx, boxes, count, zero);
            if (round_trip) {
                be->flush(be->ctx);
                be->wait(be->ctx, handles[k]);
            }
        }
        be->flush(be->ctx);
        for (uint32_t k = 0; k < n && !round_trip; k++)
            be->wait(be->ctx, handles[k]);
        tw_renderer_finish(r);
        const double dt = (tw_renderer_cpu_ms() - t0) / n;
        if (rep >= 0 && dt < best)
            best = dt;
    }
    return best;
}

/* CPU milliseconds per draw of cluster c of prototype p, its box centred on
 * the view axis z metres ahead. */
static double time_draws(struct tw_renderer *r, const struct tw_query_backend *be,
                         const struct tw_tileset *ts, uint32_t first_content, uint32_t p,
                         uint32_t c, float z)
{
    float offset[3];
    probe_offset(&ts->prototypes[p].clusters[c].box, z, offset);
    const struct tw_cell cell = {0, 0};
    double best = INFINITY;
    for (int rep = -1; rep < REPEATS; rep++) {
        const uint32_t n = rep < 0 ? 2 : DRAW_BATCH;
        tw_renderer_finish(r);
        const double t0 = tw_renderer_cpu_ms();
        for (uint32_t k = 0; k < n; k++)
            be->draw(be->ctx, cell, first_content + p, offset, &c, 1);
        tw_renderer_finish(r);
        const double dt = (tw_renderer_cpu_ms() - t0) / n;
        if (rep >= 0 && dt < best)
            best = dt;
    }
    return best;
}

/* The figures of one round of measurement, in ms each: query, box, pixel,
 * and of a hidden cluster's draw: the call, a triangle, a pixel. */
enum { FIG_QUERY, FIG_QUERY_BATCHED, FIG_BOX, FIG_PIXEL, FIG_DRAW, FIG_TRIANGLE,
       FIG_DRAW_PIXEL, FIGURES };

/* Where the draw figures are timed: far enough that a cluster's pixels
 * cost next to nothing. */
#define DRAW_FAR 150.0f

/* A cluster that the draw figures are timed on. */
struct probe {
    uint32_t prototype, cluster, triangles;
};

/* The smallest cluster of the tileset and the largest of at most
 * DRAW_MAX_TRIANGLES; false if the tileset has no cluster. */
static bool find_probes(const struct tw_tileset *ts, struct probe *lo, struct probe *hi)
{
    *lo = (struct probe){0, 0, UINT32_MAX};
    *hi = (struct probe){0, 0, 0};
    for (uint32_t p = 0; ts && p < ts->prototype_count; p++)
        for (uint32_t c = 0; c < ts->prototypes[p].cluster_count; c++) {
            const uint32_t t = ts->prototypes[p].clusters[c].triangle_count;
            if (t < lo->triangles)
                *lo = (struct probe){p, c, t};
            if (t > hi->triangles && t <= DRAW_MAX_TRIANGLES)
                *hi = (struct probe){p, c, t};
        }
    return lo->triangles != UINT32_MAX;
}


/* The draw figures of a hidden cluster: every fragment fails the depth test,
 * as those of a cluster drawn without a query that would have found it
 * hidden. The call and the triangle from the two probes far away, the pixel
 * from the larger probe near, its box covering about a sixteenth of the
 * screen. */
static void measure_hidden_draws(struct tw_renderer *r, const struct tw_query_backend *be,
                                 const struct tw_tileset *ts, uint32_t first_content,
                                 const struct tw_view *v, double f, double screen,
                                 const struct probe *lo, const struct probe *hi,
                                 const struct tw_calibration *nominal, double fig[FIGURES])
{
    tw_renderer_finish(r);
    tw_renderer_clear_depth(r, true);
    double triangle = nominal->triangle_ns * 1e-6;
    const double d_lo = time_draws(r, be, ts, first_content, lo->prototype, lo->cluster, DRAW_FAR);
    const struct probe *big = lo;
    double d_big = d_lo;
    if (hi->triangles > lo->triangles) {
        big = hi;
        d_big = time_draws(r, be, ts, first_content, hi->prototype, hi->cluster, DRAW_FAR);
        triangle = (d_big - d_lo) / (double)(hi->triangles - lo->triangles);
    } else {
        /* One size of cluster: split its cost as the nominal figures do. */
        const double whole = nominal->draw_ms + triangle * lo->triangles;
        triangle = d_lo * triangle / whole;
    }
    if (!(triangle > 0.0))
        triangle = 0.0;
    const struct tw_box *b = &ts->prototypes[big->prototype].clusters[big->cluster].box;
    const float dx = b->max[0] - b->min[0], dy = b->max[1] - b->min[1], dz = b->max[2] - b->min[2];
    const double radius = 0.5 * sqrt((double)(dx * dx + dy * dy + dz * dz));
    double z_near = sqrt(0.25 * tw_box_surface_area(b) * f * f / (screen / 16.0));
    if (z_near < 2.0 * radius + 1.0)
        z_near = 2.0 * radius + 1.0;
    double pixel = 0.0;
    float near_offset[3], far_offset[3];
    probe_offset(b, (float)z_near, near_offset);
    probe_offset(b, DRAW_FAR, far_offset);
    const double px_near = model_pixels(v, screen, b, near_offset);
    const double px_far = model_pixels(v, screen, b, far_offset);
    if (z_near < 0.5 * DRAW_FAR && px_near > px_far) {
        const double d_near =
            time_draws(r, be, ts, first_content, big->prototype, big->cluster, (float)z_near);
        pixel = (d_near - d_big) / (px_near - px_far);
        if (!(pixel > 0.0))
            pixel = 0.0;
    }
    tw_renderer_finish(r);
    tw_renderer_clear_depth(r, false);
    /* The far draws' few pixels are left in the call and the triangle. */
    fig[FIG_DRAW] = d_lo - triangle * lo->triangles;
    fig[FIG_TRIANGLE] = triangle;
    fig[FIG_DRAW_PIXEL] = pixel;
}

/* One round: lo and hi are the probes when has_probes, nominal holds the
 * figures that a tileset without clusters keeps. */
static void measure_round(struct tw_renderer *r, const struct tw_query_backend *be,
                          const struct tw_tileset *ts, uint32_t first_content,
                          const struct tw_view *v, double f, double screen, bool has_probes,
                          const struct probe *lo,
                          const struct probe *hi, const struct tw_calibration *nominal,
                          double fig[FIGURES])
{
    /* Queries: one small box, one large box, eight small boxes side by side. */
    double small_px, large_px;
    const struct tw_box small = axis_cube(100.0f, 1.0f, v, screen, &small_px);
    const struct tw_box large = axis_cube(20.0f, 6.0f, v, screen, &large_px);
    struct tw_box eight[8];
    for (int k = 0; k < 8; k++) {
        eight[k] = small;
        eight[k].min[0] += 1.5f * (float)(k - 4);
        eight[k].max[0] += 1.5f * (float)(k - 4);
    }
    /* The fixed cost is a round trip: a traversal waits for most of its
     * answers (the frames' blocking reads); boxes and pixels are what a
     * query adds to a batch. */
    const double q_trip = time_queries(r, be, &small, 1, true);
    const double q_small = time_queries(r, be, &small, 1, false);
    const double q_large = time_queries(r, be, &large, 1, false);
    const double q_eight = time_queries(r, be, eight, 8, false);
    double pixel = large_px > small_px ? (q_large - q_small) / (large_px - small_px) : 0.0;
    if (!(pixel > 0.0))
        pixel = 0.0;
    const double query = (q_trip > q_small ? q_trip : q_small) - pixel * small_px;
    const double batched = q_small - pixel * small_px;
    double box = (q_eight - q_small - pixel * 7.0 * small_px) / 7.0;
    if (!(box > 0.0))
        box = 0.0;

    fig[FIG_DRAW] = nominal->draw_ms;
    fig[FIG_TRIANGLE] = nominal->triangle_ns * 1e-6;
    fig[FIG_DRAW_PIXEL] = nominal->draw_pixel_ns * 1e-6;
    if (has_probes)
        measure_hidden_draws(r, be, ts, first_content, v, f, screen, lo, hi, nominal, fig);
    fig[FIG_QUERY] = query;
    fig[FIG_QUERY_BATCHED] = batched;
    fig[FIG_BOX] = box;
    fig[FIG_PIXEL] = pixel;
}

static int compare_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int tw_calibrate_measure(struct tw_renderer *r, const struct tw_tileset *ts,
                         uint32_t first_content, uint32_t width, uint32_t height, float fov_y,
                         struct tw_calibration *out)
{
    const double start = tw_renderer_cpu_ms();
    tw_calibrate_nominal(out);
    struct tw_view v;
    const float eye[3] = {0, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, fov_y,
                       (float)width / (float)height, 0.2f, 1000.0f);
    v.view_distance = 600.0f;
    v.frame = 0;
    tw_renderer_begin_frame(r, &v);
    const struct tw_query_backend be = tw_renderer_backend(r);
    const double f = focal_pixels(height, fov_y);

    /* Each figure is the median of ROUNDS rounds: one round's query/triangle
     * balance was seen to range over 823-1293 triangles a query from one
     * world to the next, and it decides what CHC++ queries all run long. */
    struct probe lo, hi;
    const bool has_probes = find_probes(ts, &lo, &hi);
    double rounds[FIGURES][ROUNDS], fig[FIGURES];
    for (int k = 0; k < ROUNDS; k++) {
        measure_round(r, &be, ts, first_content, &v, f, (double)width * height, has_probes,
                      &lo, &hi, out, fig);
        for (int i = 0; i < FIGURES; i++)
            rounds[i][k] = fig[i];
    }
    for (int i = 0; i < FIGURES; i++) {
        qsort(rounds[i], ROUNDS, sizeof(double), compare_double);
        fig[i] = rounds[i][ROUNDS / 2];
    }
    const double query = fig[FIG_QUERY], box = fig[FIG_BOX], pixel = fig[FIG_PIXEL];
    const double draw = fig[FIG_DRAW], triangle = fig[FIG_TRIANGLE];
    const double draw_pixel = fig[FIG_DRAW_PIXEL];
    /* A figure that noise drove to nothing keeps a floor: a query or a draw
     * never costs less than a microsecond. */
    out->query_ms = query > 1e-3 ? query : 1e-3;
    const double batched = fig[FIG_QUERY_BATCHED];
    out->query_batched_ms = batched < 1e-3    ? 1e-3
                            : batched > out->query_ms ? out->query_ms
                                                      : batched;
    out->query_box_ms = box;
    out->query_pixel_ns = pixel * 1e6;
    out->draw_ms = draw > 1e-3 ? draw : 1e-3;
    out->triangle_ns = triangle * 1e6;
    out->draw_pixel_ns = draw_pixel * 1e6;
    out->measured = true;
    out->calibrate_ms = tw_renderer_cpu_ms() - start;
    /* Leave a clean frame behind. */
    tw_renderer_begin_frame(r, &v);
    return TW_OK;
}

/* A batched query's cost; a calibration given without it has the round
 * trip's. */
static double batched_ms(const struct tw_calibration *cal)
{
    return cal->query_batched_ms > 0.0 && cal->query_batched_ms <= cal->query_ms
               ? cal->query_batched_ms
               : cal->query_ms;
}

void tw_calibrate_model(const struct tw_calibration *cal, uint32_t width, uint32_t height,
                        struct tw_cost_model *out)
{
    out->query = (float)batched_ms(cal);
    out->query_flush = (float)(cal->query_ms - batched_ms(cal));
    out->query_box = (float)cal->query_box_ms;
    out->query_pixel = (float)(cal->query_pixel_ns * 1e-6);
    out->draw = (float)cal->draw_ms;
    out->triangle = (float)(cal->triangle_ns * 1e-6);
    out->draw_pixel = (float)(cal->draw_pixel_ns * 1e-6);
    out->screen_pixels = (float)width * (float)height;
}
