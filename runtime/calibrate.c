/* The cost calibration (calibrate.h, DESIGN §14). */
#include "runtime/calibrate.h"

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
    memset(out, 0, sizeof(*out));
    out->query_ms = 0.030;
    out->query_box_ms = 0.001;
    out->query_pixel_ns = 1.0;
    out->draw_ms = 0.0015;
    out->triangle_ns = 60.0;
    out->query_scale = 1.0;
    out->draw_scale = 1.0;
}

/* The focal length in pixels of a height-pixel image with fov_y. */
static double focal_pixels(uint32_t height, float fov_y)
{
    return 0.5 * (double)height / tan(0.5 * (double)fov_y * 3.14159265358979 / 180.0);
}

/* A cube of side a centred on the view axis at distance z: the pixels of
 * its near face (what a query with near faces only mostly draws). */
static struct tw_box axis_cube(float z, float a, double f, double *pixels)
{
    const struct tw_box b = {{-0.5f * a, -0.5f * a, z - 0.5f * a}, {0.5f * a, 0.5f * a, z + 0.5f * a}};
    const double side = f * a / (z - 0.5 * a);
    *pixels = side * side;
    return b;
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

/* CPU milliseconds per draw of cluster c of prototype p, placed 150 m ahead. */
static double time_draws(struct tw_renderer *r, const struct tw_query_backend *be,
                         const struct tw_tileset *ts, uint32_t first_content, uint32_t p,
                         uint32_t c)
{
    const struct tw_box *b = &ts->prototypes[p].clusters[c].box;
    const float offset[3] = {-0.5f * (b->min[0] + b->max[0]), -0.5f * (b->min[1] + b->max[1]),
                             150.0f - 0.5f * (b->min[2] + b->max[2])};
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

/* The figures of one round of measurement: query, box, pixel (ms each),
 * draw (ms) and triangle (ms). */
enum { FIG_QUERY, FIG_BOX, FIG_PIXEL, FIG_DRAW, FIG_TRIANGLE, FIGURES };

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

/* One round: lo and hi are the probes when has_probes, nominal holds the
 * figures that a tileset without clusters keeps. */
static void measure_round(struct tw_renderer *r, const struct tw_query_backend *be,
                          const struct tw_tileset *ts, uint32_t first_content, double f,
                          bool has_probes, const struct probe *lo, const struct probe *hi,
                          const struct tw_calibration *nominal, double fig[FIGURES])
{
    /* Queries: one small box, one large box, eight small boxes side by side. */
    double small_px, large_px;
    const struct tw_box small = axis_cube(100.0f, 1.0f, f, &small_px);
    const struct tw_box large = axis_cube(20.0f, 6.0f, f, &large_px);
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
    double box = (q_eight - q_small - pixel * 7.0 * small_px) / 7.0;
    if (!(box > 0.0))
        box = 0.0;

    /* Draws: the two probes; the difference prices a triangle. */
    double draw = nominal->draw_ms, triangle = nominal->triangle_ns * 1e-6;
    if (has_probes) {
        const double d_lo = time_draws(r, be, ts, first_content, lo->prototype, lo->cluster);
        if (hi->triangles > lo->triangles) {
            const double d_hi =
                time_draws(r, be, ts, first_content, hi->prototype, hi->cluster);
            triangle = (d_hi - d_lo) / (double)(hi->triangles - lo->triangles);
        } else {
            /* One size of cluster: split its cost as the nominal figures do. */
            const double whole = nominal->draw_ms + triangle * lo->triangles;
            triangle = d_lo * triangle / whole;
        }
        if (!(triangle > 0.0))
            triangle = 0.0;
        draw = d_lo - triangle * lo->triangles;
    }
    fig[FIG_QUERY] = query;
    fig[FIG_BOX] = box;
    fig[FIG_PIXEL] = pixel;
    fig[FIG_DRAW] = draw;
    fig[FIG_TRIANGLE] = triangle;
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
        measure_round(r, &be, ts, first_content, f, has_probes, &lo, &hi, out, fig);
        for (int i = 0; i < FIGURES; i++)
            rounds[i][k] = fig[i];
    }
    for (int i = 0; i < FIGURES; i++) {
        qsort(rounds[i], ROUNDS, sizeof(double), compare_double);
        fig[i] = rounds[i][ROUNDS / 2];
    }
    const double query = fig[FIG_QUERY], box = fig[FIG_BOX], pixel = fig[FIG_PIXEL];
    const double draw = fig[FIG_DRAW], triangle = fig[FIG_TRIANGLE];
    /* A figure that noise drove to nothing keeps a floor: a query or a draw
     * never costs less than a microsecond. */
    out->query_ms = query > 1e-3 ? query : 1e-3;
    out->query_box_ms = box;
    out->query_pixel_ns = pixel * 1e6;
    out->draw_ms = draw > 1e-3 ? draw : 1e-3;
    out->triangle_ns = triangle * 1e6;
    out->measured = true;
    out->calibrate_ms = tw_renderer_cpu_ms() - start;
    /* Leave a clean frame behind. */
    tw_renderer_begin_frame(r, &v);
    return TW_OK;
}

/* Solves the 3 x 3 system a x = b by Cramer's rule; false if singular. */
static bool solve3(const double a[3][3], const double b[3], double x[3])
{
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                       a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (!(fabs(det) > 1e-12))
        return false;
    for (int c = 0; c < 3; c++) {
        double m[3][3];
        memcpy(m, a, sizeof(m));
        for (int r = 0; r < 3; r++)
            m[r][c] = b[r];
        x[c] = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])) / det;
    }
    return true;
}

static double clamp_scale(double s)
{
    return s < 0.1 ? 0.1 : s > 20.0 ? 20.0 : s;
}

void tw_calibrate_refine(struct tw_calibrate_fit *fit, struct tw_calibration *cal, double cpu_ms,
                         uint32_t queries, uint32_t query_boxes, uint32_t draws,
                         uint64_t triangles)
{
    if (!cal->measured || !isfinite(cpu_ms) || cpu_ms < 0.0)
        return;
    /* Recent frames weigh more: about the last hundred count. */
    const double decay = 0.99;
    const double x[3] = {
        1.0,
        queries * cal->query_ms + (query_boxes > queries ? query_boxes - queries : 0) *
                                      cal->query_box_ms,
        draws * cal->draw_ms + (double)triangles * cal->triangle_ns * 1e-6,
    };
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++)
            fit->s[r][c] = decay * fit->s[r][c] + x[r] * x[c];
        fit->sy[r] = decay * fit->sy[r] + x[r] * cpu_ms;
    }
    fit->weight = decay * fit->weight + 1.0;
    fit->query_weight = decay * fit->query_weight + (queries > 0);
    fit->draw_weight = decay * fit->draw_weight + (draws > 0);
    cal->frames++;
    /* Both kinds of work must have been seen before the split between
     * them can be told. */
    if (fit->query_weight < 8.0 || fit->draw_weight < 8.0)
        return;
    /* A prior pulling each factor towards 1, as strong as a few frames. */
    double a[3][3], b[3], sol[3];
    memcpy(a, fit->s, sizeof(a));
    memcpy(b, fit->sy, sizeof(b));
    for (int k = 1; k < 3; k++) {
        const double mu = 2.0 * fit->s[k][k] / fit->weight;
        a[k][k] += mu;
        b[k] += mu;
    }
    if (!solve3(a, b, sol))
        return;
    cal->query_scale = clamp_scale(sol[1]);
    cal->draw_scale = clamp_scale(sol[2]);
}

void tw_calibrate_model(const struct tw_calibration *cal, uint32_t width, uint32_t height,
                        float fov_y, struct tw_cost_model *out)
{
    const double qs = cal->query_scale > 0.0 ? cal->query_scale : 1.0;
    const double ds = cal->draw_scale > 0.0 ? cal->draw_scale : 1.0;
    const double f = focal_pixels(height, fov_y);
    out->query = (float)(cal->query_ms * qs);
    out->query_box = (float)(cal->query_box_ms * qs);
    out->query_pixel = (float)(cal->query_pixel_ns * 1e-6 * qs);
    out->draw = (float)(cal->draw_ms * ds);
    out->triangle = (float)(cal->triangle_ns * 1e-6 * ds);
    out->pixels_per_sr = (float)(f * f);
    out->screen_pixels = (float)width * (float)height;
}
