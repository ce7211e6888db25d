/* Charts of a bench run: data files from memory, the built-in charts.gp, gnuplot (charts.h). */
#include "tools/tileworld/charts.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

#include "tools/outfile.h"
#include "tools/charts-gp.h"   /* TW_CHARTS_GP: tools/tileworld/charts.gp, built in */

extern char **environ;

#define DATA TW_REPORT_CHART_DATA

/* ---- the data files --------------------------------------------------------------------- */

/* What the data files need beyond the run. */
struct chart_data {
    const struct tw_chart_run *run;
    bool gpu;                                   /* the primary time is GPU time */
    bool lod;                                   /* chart-lod.png is drawn (lod_drawn) */
    uint32_t order[64];                         /* the sweep's values in ascending order */
};

/* The columns of methods.dat (after method) and of sweep-METHOD.dat (after
 * value), named as in summary.json. */
static const char figures_header[] =
    "frames mean_ms median_ms p95_ms p99_ms max_ms mean_triangles mean_queries "
    "mean_overdraw_triangles missed_pixels_total frames_with_missed_pixels "
    "mean_cpu_ms median_cpu_ms p99_cpu_ms depth_errors_total frames_with_depth_errors "
    "missed_clusters_total mean_gpu_ms gpu_frames\n";

/* A time for a data file: NaN (gnuplot leaves the point out) when unknown. */
static void put_time(struct tw_outfile *o, double ms)
{
    if (isnan(ms))
        tw_outfile_printf(o, " NaN");
    else
        tw_outfile_printf(o, " %.3f", ms);
}

/* A method's mean GPU time per frame, NaN where no frame's came back. */
static double gpu_ms(const struct tw_method_figures *fg)
{
    return fg->gpu_frames > 0 ? fg->mean_gpu_ms : NAN;
}

static void put_figures(struct tw_outfile *o, const struct tw_method_figures *fg)
{
    tw_outfile_printf(o, "%u %.3f %.3f %.3f %.3f %.3f %.3f %.3f %.3f %llu %u %.3f %.3f %.3f %llu %u "
                      "%llu", fg->frames,
                      fg->mean_ms, fg->median_ms, fg->p95_ms, fg->p99_ms, fg->max_ms,
                      fg->mean_triangles, fg->mean_queries, fg->mean_overdraw_triangles,
                      (unsigned long long)fg->missed_pixels_total, fg->frames_with_missed_pixels,
                      fg->mean_cpu_ms, fg->median_cpu_ms, fg->p99_cpu_ms,
                      (unsigned long long)fg->depth_errors_total, fg->frames_with_depth_errors,
                      (unsigned long long)fg->missed_clusters_total);
    put_time(o, gpu_ms(fg));
    tw_outfile_printf(o, " %u\n", fg->gpu_frames);
}

/* A method's mean primary time per frame (NaN: its GPU time is unknown). */
static double primary_ms(const struct chart_data *d, const struct tw_method_figures *fg)
{
    return d->gpu ? gpu_ms(fg) : fg->mean_cpu_ms;
}

static int open_in(struct tw_outfile *o, const char *dir, const char *name, char *err,
                   size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    const int n = snprintf(file, sizeof(file), "%s/%s", dir, name);
    if (n < 0 || (size_t)n >= sizeof(file)) {
        snprintf(err, err_size, "%s: the folder name is too long", dir);
        return TW_ERR_IO;
    }
    return tw_outfile_open(o, file, err, err_size);
}

static int write_methods(const struct chart_data *d, char *err, size_t err_size)
{
    const struct tw_chart_run *run = d->run;
    struct tw_outfile o;
    int rc = open_in(&o, run->dir, DATA "/methods.dat", err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&o, "# one row per method, in the order of the run\nmethod %s", figures_header);
    for (uint32_t k = 0; k < run->method_count; k++) {
        tw_outfile_printf(&o, "%s ", tw_method_name(run->methods[k]));
        put_figures(&o, &run->figures[run->methods[k]]);
    }
    return tw_outfile_commit(&o, err, err_size);
}

/* A parameter that leaves a method's triangles, missed pixels and overdraw
 * the same at every value changes nothing it draws (T for vfc): its points
 * differ only by timing noise. */
static bool unaffected(const struct tw_chart_sweep *s, enum tw_method m)
{
    if (s->count < 2)
        return false;
    const struct tw_method_figures *first = &s->figures[0][m];
    for (uint32_t k = 1; k < s->count; k++) {
        const struct tw_method_figures *fg = &s->figures[k][m];
        if (fg->mean_triangles != first->mean_triangles ||
            fg->missed_pixels_total != first->missed_pixels_total ||
            fg->mean_overdraw_triangles != first->mean_overdraw_triangles)
            return false;
    }
    return true;
}

/* The sweep's values in ascending order, as indices. */
static void sort_values(const struct tw_chart_sweep *s, uint32_t *order)
{
    for (uint32_t k = 0; k < s->count; k++) {
        uint32_t j = k;
        for (; j > 0 && s->values[order[j - 1]] > s->values[k]; j--)
            order[j] = order[j - 1];
        order[j] = k;
    }
}

static int write_sweep(const struct chart_data *d, char *err, size_t err_size)
{
    const struct tw_chart_run *run = d->run;
    const struct tw_chart_sweep *s = run->sweep;
    for (uint32_t m = 0; m < run->method_count; m++) {
        const enum tw_method me = run->methods[m];
        char name[128];
        snprintf(name, sizeof(name), DATA "/sweep-%s.dat", tw_method_name(me));
        struct tw_outfile o;
        int rc = open_in(&o, run->dir, name, err, err_size);
        if (rc)
            return rc;
        tw_outfile_printf(&o, "# %s: one row per value of %s, by value\nvalue %s", tw_method_name(me),
                          s->param, figures_header);
        for (uint32_t k = 0; k < s->count; k++) {
            tw_outfile_printf(&o, "%g ", s->values[d->order[k]]);
            put_figures(&o, &s->figures[d->order[k]][me]);
        }
        if ((rc = tw_outfile_commit(&o, err, err_size)))
            return rc;
    }
    return TW_OK;
}

/* ---- labels placed apart ------------------------------------------------------------ */

static double box_overlap(const struct tw_chart_box *a, const struct tw_chart_box *b)
{
    const double w = fmin(a->x1, b->x1) - fmax(a->x0, b->x0);
    const double h = fmin(a->y1, b->y1) - fmax(a->y0, b->y0);
    return w > 0.0 && h > 0.0 ? w * h : 0.0;
}

static struct tw_chart_box box_at(double cx, double cy, double w, double h)
{
    return (struct tw_chart_box){cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h};
}

/* The length of the segment from (x0, y0) to (x1, y1) inside box b
 * (Liang-Barsky clipping). */
static double segment_inside(double x0, double y0, double x1, double y1,
                             const struct tw_chart_box *b)
{
    const double dx = x1 - x0, dy = y1 - y0;
    const double p[4] = {-dx, dx, -dy, dy};
    const double q[4] = {x0 - b->x0, b->x1 - x0, y0 - b->y0, b->y1 - y0};
    double t0 = 0.0, t1 = 1.0;
    for (int k = 0; k < 4; k++) {
        if (p[k] == 0.0) {
            if (q[k] < 0.0)
                return 0.0;
        } else {
            const double t = q[k] / p[k];
            if (p[k] < 0.0)
                t0 = fmax(t0, t);
            else
                t1 = fmin(t1, t);
        }
    }
    return t1 > t0 ? (t1 - t0) * hypot(dx, dy) : 0.0;
}

/* How badly a label sits at b (its leader line from its point (x, y) to
 * (ax, ay) when moved): *hard, the area its box shares with the labels
 * placed before and the obstacles, and that outside area (weighed more);
 * *soft, the lengths of leader lines crossing labels (unavoidable where
 * many labels share one point). */
static void placement_cost(const struct tw_chart_box *b, bool moved, double x, double y, double ax,
                           double ay, const struct tw_chart_label *placed, uint32_t placed_count,
                           const struct tw_chart_box *obstacles, uint32_t obstacle_count,
                           const struct tw_chart_box *area, double *hard, double *soft)
{
    const double own = (b->x1 - b->x0) * (b->y1 - b->y0);
    *hard = 4.0 * (own - box_overlap(b, area));
    *soft = 0.0;
    for (uint32_t k = 0; k < obstacle_count; k++)
        *hard += box_overlap(b, &obstacles[k]);
    for (uint32_t k = 0; k < placed_count; k++) {
        const struct tw_chart_label *l = &placed[k];
        const struct tw_chart_box o = box_at(l->centre_x, l->centre_y, l->width, l->height);
        *hard += box_overlap(b, &o);
        if (moved)
            *soft += segment_inside(x, y, ax, ay, &o);
        if (l->moved) {
            double lx, ly;
            tw_charts_label_anchor(l, &lx, &ly);
            *soft += segment_inside(l->x, l->y, lx, ly, b);
        }
    }
}

uint32_t tw_charts_place_labels(struct tw_chart_label *labels, uint32_t count,
                                const struct tw_chart_box *obstacles, uint32_t obstacle_count,
                                double gap, struct tw_chart_box area)
{
    /* Next to the point: right, above, below, left, then the corners. */
    static const double near[8][2] = {
        {1, 0}, {0, -1}, {0, 1}, {-1, 0}, {1, -1}, {1, 1}, {-1, -1}, {-1, 1},
    };
    const double diagonal = hypot(area.x1 - area.x0, area.y1 - area.y0);
    uint32_t overlapping = 0;
    for (uint32_t k = 0; k < count; k++) {
        struct tw_chart_label *l = &labels[k];
        const double w = l->width, h = l->height;
        /* The best place: no overlap first, then the least leader line
         * through other labels (a pixel of it weighs as much as 10 pixels
         * farther out), then the nearest. */
        double best_hard = INFINITY, best_score = INFINITY;
        double best_x = l->x + gap + 0.5 * w, best_y = l->y;
        bool best_moved = false, perfect = false;
        /* Ring 0 beside the point; rings 1.. farther out, every 22.5
         * degrees, a line height apart, until the area is crossed. */
        const double step = fmax(h, 4.0);
        const uint32_t rings = 1 + (uint32_t)ceil(diagonal / step);
        for (uint32_t ring = 0; ring <= rings && !perfect; ring++) {
            const uint32_t directions = ring == 0 ? 8 : 16;
            for (uint32_t d = 0; d < directions && !perfect; d++) {
                double cx, cy;
                if (ring == 0) {
                    const double diag = near[d][0] != 0.0 && near[d][1] != 0.0 ? 0.7 : 1.0;
                    cx = l->x + near[d][0] * (diag * gap + 0.5 * w);
                    cy = l->y + near[d][1] * (diag * gap + 0.5 * h);
                } else {
                    /* 0, 180, 90, 270, 45, ... degrees: sideways first. */
                    static const uint8_t turn[16] = {0, 8, 4, 12, 2, 6, 10, 14,
                                                     1, 7, 9, 15, 3, 5, 11, 13};
                    const double a = turn[d] * (3.14159265358979323846 / 8.0);
                    const double r = gap + ring * step;
                    cx = l->x + cos(a) * (r + 0.5 * w);
                    cy = l->y - sin(a) * (r + 0.5 * h);
                }
                const struct tw_chart_box b = box_at(cx, cy, w, h);
                double ax = l->x, ay = l->y;
                if (ring > 0) {
                    const struct tw_chart_label at = {.x = l->x, .y = l->y, .width = w, .height = h,
                                                      .centre_x = cx, .centre_y = cy};
                    tw_charts_label_anchor(&at, &ax, &ay);
                }
                double hard, soft;
                placement_cost(&b, ring > 0, l->x, l->y, ax, ay, labels, k, obstacles,
                               obstacle_count, &area, &hard, &soft);
                const double score = 10.0 * soft + hypot(cx - l->x, cy - l->y);
                if (hard < best_hard || (hard == best_hard && score < best_score)) {
                    best_hard = hard;
                    best_score = score;
                    best_x = cx;
                    best_y = cy;
                    best_moved = ring > 0;
                    /* Nothing farther out can do better. */
                    perfect = hard == 0.0 && soft == 0.0;
                }
            }
        }
        l->centre_x = best_x;
        l->centre_y = best_y;
        l->moved = best_moved;
        l->overlaps = best_hard > 0.0;
        overlapping += l->overlaps;
    }
    return overlapping;
}

void tw_charts_label_anchor(const struct tw_chart_label *l, double *x, double *y)
{
    const double dx = l->centre_x - l->x, dy = l->centre_y - l->y;
    const double hw = 0.5 * l->width, hh = 0.5 * l->height;
    double t = 0.0;
    if (fabs(dx) > hw || fabs(dy) > hh) {
        /* The border the line from the point to the centre crosses. */
        t = fabs(dx) * hh > fabs(dy) * hw ? (fabs(dx) - hw) / fabs(dx) : (fabs(dy) - hh) / fabs(dy);
    }
    *x = l->x + dx * t;
    *y = l->y + dy * t;
}

/* ---- the panels of the speed-accuracy and Pareto charts -------------------------------- */

/* Both are 1200x600, two panels side by side, the keys below them (and
 * chart-lod.png, one panel over both places); charts.gp sets these margins
 * (screen fractions) from run.gp. */
enum { CHART_W = 1200, CHART_H = 600 };
static const double panel_left[2] = {0.075, 0.575}, panel_right[2] = {0.475, 0.975};
static const double panel_bottom = 0.22, panel_top = 0.84;

/* Marker sizes (half widths, pixels) of charts.gp's points: ps 2, ps 1.3,
 * ps 1.4 and the ring of a front point (ps 2.6); label fonts (points). */
#define MARK_METHOD 8.0
#define MARK_SWEEP 5.5
#define MARK_PARETO 6.0
#define MARK_FRONT 11.0
#define FONT_METHOD 10.0
#define FONT_VALUE 8.0
#define FONT_NOTE 9.0

struct axis {
    double lo, hi;      /* the range, as charts.gp sets it */
    bool log;
    double p0, p1;      /* the pixels of lo and hi */
};

static double to_px(const struct axis *a, double v)
{
    const double t = a->log ? (log10(v) - log10(a->lo)) / (log10(a->hi) - log10(a->lo))
                            : (v - a->lo) / (a->hi - a->lo);
    return a->p0 + t * (a->p1 - a->p0);
}

static double from_px(const struct axis *a, double p)
{
    const double t = (p - a->p0) / (a->p1 - a->p0);
    return a->log ? pow(10.0, log10(a->lo) + t * (log10(a->hi) - log10(a->lo)))
                  : a->lo + t * (a->hi - a->lo);
}

/* The box of a text of n characters in DejaVu Sans at pt points on the
 * pngcairo terminal (96 dpi; measured: 21 characters at 9 pt are 142 px
 * wide, this says 155). */
static void text_size(size_t n, double pt, double *w, double *h)
{
    const double em = pt * 96.0 / 72.0;
    *w = (double)n * 0.6 * em + 4.0;
    *h = 1.3 * em;
}

enum { LABELS_MAX = 64 * TW_METHOD_ALL + TW_METHOD_ALL };

/* One panel's points and labels, in pixels, with what they must avoid. */
struct panel {
    struct axis x, y;
    struct tw_chart_box area;
    struct tw_chart_label label[LABELS_MAX];
    enum tw_method method[LABELS_MAX];
    int kind[LABELS_MAX];                   /* 1: a method's point, 2: a sweep value's */
    char text[LABELS_MAX][96];
    uint32_t count;
    struct tw_chart_box obstacle[2 * LABELS_MAX + 4];
    uint32_t obstacle_count;
};

/* A panel from left to right (screen fractions) of the chart's width. */
static void panel_init(struct panel *p, double left, double right, double x_lo, double x_hi,
                       double y_lo, double y_hi, bool log_y)
{
    p->x = (struct axis){x_lo, x_hi, false, left * CHART_W, right * CHART_W};
    p->y = (struct axis){y_lo, y_hi, log_y, (1.0 - panel_bottom) * CHART_H,
                         (1.0 - panel_top) * CHART_H};
    p->area = (struct tw_chart_box){p->x.p0 + 2.0, p->y.p1 + 2.0, p->x.p1 - 2.0, p->y.p0 - 2.0};
    p->count = p->obstacle_count = 0;
}

static void add_obstacle(struct panel *p, struct tw_chart_box b)
{
    if (p->obstacle_count < sizeof(p->obstacle) / sizeof(p->obstacle[0]))
        p->obstacle[p->obstacle_count++] = b;
}

/* A point drawn at (x, y) in the panel's coordinates, with a marker of
 * half width mark; labelled with text when text is not NULL. */
static void add_point(struct panel *p, enum tw_method m, int kind, double x, double y, double mark,
                      const char *text, double pt)
{
    if (!isfinite(x) || !isfinite(y))
        return;
    const double px = to_px(&p->x, x), py = to_px(&p->y, y);
    add_obstacle(p, box_at(px, py, 2.0 * mark, 2.0 * mark));
    if (!text || p->count >= LABELS_MAX)
        return;
    struct tw_chart_label *l = &p->label[p->count];
    memset(l, 0, sizeof(*l));
    l->x = px;
    l->y = py;
    text_size(strlen(text), pt, &l->width, &l->height);
    p->method[p->count] = m;
    p->kind[p->count] = kind;
    snprintf(p->text[p->count], sizeof(p->text[0]), "%s", text);
    p->count++;
}

/* A fixed text of charts.gp, right-aligned at a fraction of the panel's
 * width, centred at pixel row y. */
static void add_note(struct panel *p, const char *text, double pt, double right, double y)
{
    double w, h;
    text_size(strlen(text), pt, &w, &h);
    const double x1 = p->x.p0 + right * (p->x.p1 - p->x.p0);
    add_obstacle(p, (struct tw_chart_box){x1 - w, y - 0.5 * h, x1, y + 0.5 * h});
}

/* Places the panel's labels and writes them as chart-data/NAME: the point,
 * where its label goes (data coordinates), where its leader line ends. */
static int write_labels(const char *dir, const char *name, const char *what, struct panel *p,
                        char *err, size_t err_size)
{
    tw_charts_place_labels(p->label, p->count, p->obstacle, p->obstacle_count,
                           MARK_METHOD + 2.0, p->area);
    char file[128];
    snprintf(file, sizeof(file), DATA "/%s", name);
    struct tw_outfile o;
    int rc = open_in(&o, dir, file, err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&o, "# %s: each point's label, placed by tileworld apart from the others "
                          "for the panels and ranges of run.gp; moved 1: joined to its point by "
                          "a leader line ending at anchor; kind 1: a method's point, 2: a sweep "
                          "value's, 0: none\n"
                          "method kind x y label_x label_y anchor_x anchor_y moved text\n", what);
    for (uint32_t k = 0; k < p->count; k++) {
        const struct tw_chart_label *l = &p->label[k];
        double ax, ay;
        tw_charts_label_anchor(l, &ax, &ay);
        tw_outfile_printf(&o, "%s %d %.10g %.10g %.10g %.10g %.10g %.10g %d \"%s\"\n",
                          tw_method_name(p->method[k]), p->kind[k], from_px(&p->x, l->x),
                          from_px(&p->y, l->y), from_px(&p->x, l->centre_x),
                          from_px(&p->y, l->centre_y), from_px(&p->x, ax), from_px(&p->y, ay),
                          l->moved, p->text[k]);
    }
    /* gnuplot warns of a file with no row: a panel without labels has one
     * of kind 0, which draws nothing (inside the axes: gnuplot 5.4.4
     * crashes on labels that are all NaN). */
    if (p->count == 0) {
        const double x = from_px(&p->x, p->area.x0), y = from_px(&p->y, p->area.y1);
        tw_outfile_printf(&o, "none 0 %.10g %.10g %.10g %.10g %.10g %.10g 0 \"\"\n", x, y, x, y, x,
                          y);
    }
    return tw_outfile_commit(&o, err, err_size);
}

/* The range of a log axis of 1 + value that holds values up to max, as
 * charts.gp's symlog_tics labels it: up to factor * (max + 1), at least 20,
 * and a ninth of a decade below 1. */
static void symlog_range(double max, double factor, double *lo, double *hi)
{
    *hi = fmax(20.0, (max + 1.0) * factor);
    *lo = pow(*hi, -1.0 / 9.0);
}

/* The geometry of chart-speed-accuracy.png, chart-pareto.png and
 * chart-lod.png, for run.gp. */
struct geometry {
    double sa_x_hi;
    double sa_y_lo[2], sa_y_hi[2], sa_y_scale[2];
    bool sa_y_log[2];
    uint32_t sa_labels[2];
    double pa_x_lo, pa_x_hi;            /* the primary time; chart-lod.png's y */
    double pa_y_lo[2], pa_y_hi[2];
    uint32_t pa_labels[2];
    double lod_x_hi;                    /* pixels differing from full detail, % */
    uint32_t lod_labels;
};

/* chart-speed-accuracy.png: one point per method (and per value of a sweep
 * that changes what the method draws) at its mean primary time, against
 * missed pixels over the run (left) and overdraw (right). */
static int write_speed_accuracy(const struct chart_data *d, struct geometry *g, char *err,
                                size_t err_size)
{
    const struct tw_chart_run *run = d->run;
    const struct tw_chart_sweep *s = run->sweep;
    double x_max = 0.0, missed_max = 0.0, over_max = 0.0, over_min = INFINITY;
    for (uint32_t m = 0; m < run->method_count; m++) {
        const enum tw_method me = run->methods[m];
        const bool swept = s && !unaffected(s, me);
        for (uint32_t k = 0; k <= (swept ? s->count : 0); k++) {
            const struct tw_method_figures *fg = k == 0 ? &run->figures[me] : &s->figures[k - 1][me];
            const double t = primary_ms(d, fg);
            if (isfinite(t))
                x_max = fmax(x_max, t);
            missed_max = fmax(missed_max, (double)fg->missed_pixels_total);
            over_max = fmax(over_max, fg->mean_overdraw_triangles);
            if (fg->mean_overdraw_triangles > 0.0)
                over_min = fmin(over_min, fg->mean_overdraw_triangles);
        }
    }
    g->sa_x_hi = x_max > 0.0 ? x_max * 1.25 : 1.0;
    symlog_range(missed_max, 8.0, &g->sa_y_lo[0], &g->sa_y_hi[0]);
    g->sa_y_log[0] = true;
    g->sa_y_scale[0] = 1.0;
    /* Overdraw on a log axis too when vfc's dwarfs the rest. */
    g->sa_y_log[1] = isfinite(over_min) && over_max / over_min > 10.0;
    if (g->sa_y_log[1]) {
        symlog_range(over_max, 4.0, &g->sa_y_lo[1], &g->sa_y_hi[1]);
        g->sa_y_scale[1] = 1.0;
    } else {
        g->sa_y_scale[1] = over_max >= 1e7 ? 1e6 : over_max >= 1e4 ? 1e3 : 1.0;
        g->sa_y_lo[1] = 0.0;
        g->sa_y_hi[1] = over_max > 0.0 ? over_max / g->sa_y_scale[1] * 1.15 : 1.0;
    }
    struct panel *p = malloc(sizeof(*p));
    if (!p) {
        snprintf(err, err_size, "%s: out of memory placing the chart labels", run->dir);
        return TW_ERR_NOMEM;
    }
    int rc = TW_OK;
    for (int panel = 0; panel < 2 && !rc; panel++) {
        panel_init(p, panel_left[panel], panel_right[panel], 0.0, g->sa_x_hi, g->sa_y_lo[panel],
                   g->sa_y_hi[panel], g->sa_y_log[panel]);
        const bool log_y = g->sa_y_log[panel];
        /* The methods' points first: they get the places beside them. */
        for (int kind = 1; kind <= 2; kind++)
            for (uint32_t m = 0; m < run->method_count; m++) {
                const enum tw_method me = run->methods[m];
                if (kind == 2 && (!s || unaffected(s, me)))
                    continue;
                for (uint32_t j = 0; j < (kind == 1 ? 1 : s->count); j++) {
                    const uint32_t k = kind == 1 ? 0 : d->order[j];
                    const struct tw_method_figures *fg = kind == 1 ? &run->figures[me]
                                                                   : &s->figures[k][me];
                    const double v = panel == 0 ? (double)fg->missed_pixels_total
                                                : fg->mean_overdraw_triangles;
                    const double y = log_y ? v + 1.0 : v / g->sa_y_scale[panel];
                    char text[96];
                    if (kind == 1)
                        snprintf(text, sizeof(text), "%s", tw_method_name(me));
                    else
                        snprintf(text, sizeof(text), "%s%s%s=%g", j == 0 ? tw_method_name(me) : "",
                                 j == 0 ? " " : "", s->param, s->values[k]);
                    add_point(p, me, kind, primary_ms(d, fg), y,
                              kind == 1 ? MARK_METHOD : MARK_SWEEP, text,
                              kind == 1 ? FONT_METHOD : FONT_VALUE);
                }
            }
        /* charts.gp's notes in the panel. */
        if (panel == 0)
            add_note(p, "no pixel missed (conservative)", FONT_NOTE, 0.99, to_px(&p->y, 1.0) + 16.0);
        else
            add_note(p, "triangles drawn in clusters with no visible pixel", FONT_NOTE, 0.99,
                     p->y.p0 - 0.03 * (p->y.p0 - p->y.p1));
        if (!run->verified) {
            const double cx = 0.5 * (p->x.p0 + p->x.p1), cy = p->y.p0 + 0.6 * (p->y.p1 - p->y.p0);
            add_obstacle(p, box_at(cx, cy, 240.0, 44.0));
        }
        char name[64], what[96];
        snprintf(name, sizeof(name), "labels-speed-accuracy-%d.dat", panel + 1);
        snprintf(what, sizeof(what), "chart-speed-accuracy.png, the %s panel",
                 panel == 0 ? "left (missed pixels)" : "right (overdraw)");
        rc = write_labels(run->dir, name, what, p, err, err_size);
        g->sa_labels[panel] = p->count;
    }
    free(p);
    return rc;
}

/* Where method m comes in the run's order. */
static uint32_t method_rank(const struct tw_chart_run *run, enum tw_method m)
{
    uint32_t k = 0;
    while (k < run->method_count && run->methods[k] != m)
        k++;
    return k;
}

/* chart-lod.png's panel: each point at its image error (%) and primary
 * time, labelled with its value, by method and value (by_value); the
 * front's staircase, through its points by image error (order: by time,
 * reversed), kept clear of labels. */
static int write_lod_labels(const struct chart_data *d, struct geometry *g,
                            const struct tw_pareto_point *points, const double *time,
                            const uint32_t *order, const uint32_t *by_value, uint32_t n,
                            struct panel *p, char *err, size_t err_size)
{
    double hi = 0.0;
    for (uint32_t k = 0; k < n; k++)
        hi = fmax(hi, 100.0 * points[k].lod_fraction);
    g->lod_x_hi = hi > 0.0 ? hi * 1.15 : 1.0;
    panel_init(p, panel_left[0], panel_right[1], 0.0, g->lod_x_hi, g->pa_x_lo, g->pa_x_hi, false);
    double step_x = NAN, step_y = NAN;
    for (uint32_t k = n; k-- > 0;) {
        const struct tw_pareto_point *pt = &points[order[k]];
        if (!pt->front_lod)
            continue;
        const double x = to_px(&p->x, 100.0 * pt->lod_fraction), y = to_px(&p->y, time[order[k]]);
        if (!isnan(step_x)) {
            add_obstacle(p, (struct tw_chart_box){step_x, step_y - 1.5, x, step_y + 1.5});
            add_obstacle(p, (struct tw_chart_box){x - 1.5, step_y, x + 1.5, y});
        }
        step_x = x;
        step_y = y;
    }
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_pareto_point *pt = &points[by_value[k]];
        char text[32];
        snprintf(text, sizeof(text), "%g", pt->value);
        add_point(p, pt->method, 2, 100.0 * pt->lod_fraction, time[by_value[k]],
                  pt->front_lod ? MARK_FRONT : MARK_SWEEP, text, FONT_VALUE);
    }
    g->lod_labels = p->count;
    return write_labels(d->run->dir, "labels-lod.dat", "chart-lod.png", p, err, err_size);
}

/* Speed against accuracy over the sweep: chart-data/pareto.dat (every
 * point) and pareto-front.dat, pareto-front-depth.dat (the points of each
 * front), each by primary time, so that a front's points join in order;
 * and the labels of the fronts' points. For chart-lod.png also
 * pareto-lod.dat (every point, by method and value: each method's points
 * join in the order of value) and pareto-front-lod.dat (by image error:
 * the front's staircase runs along its x), and every point's label. On a
 * GPU the fronts are those of GPU time (pareto.h's are of CPU time, as
 * sweep.md's). */
static int write_pareto(const struct chart_data *d, struct geometry *g, char *err,
                        size_t err_size)
{
    static const char *const names[5] = {
        DATA "/pareto.dat", DATA "/pareto-front.dat", DATA "/pareto-front-depth.dat",
        DATA "/pareto-lod.dat", DATA "/pareto-front-lod.dat",
    };
    static const char *const what[5] = {
        "every point", "the front of %s against missed pixels",
        "the front of %s against depth errors", "every point",
        "the front of %s against image error (lod_fraction)",
    };
    static const char *const sorted[5] = {
        "by mean %s per frame (time_ms)", "by mean %s per frame (time_ms)",
        "by mean %s per frame (time_ms)", "by method, in the order of the run, and value",
        "by image error (lod_fraction)",
    };
    const struct tw_chart_run *run = d->run;
    const struct tw_chart_sweep *s = run->sweep;
    const uint32_t n = s->point_count < LABELS_MAX ? s->point_count : LABELS_MAX;
    struct tw_pareto_point *points = malloc(sizeof(*points) * n);
    double *time = malloc(sizeof(*time) * n), *gpu = malloc(sizeof(*gpu) * n);
    uint32_t *order = malloc(sizeof(*order) * n), *by_value = malloc(sizeof(*by_value) * n);
    struct panel *p = malloc(sizeof(*p));
    int rc = TW_OK;
    if (!points || !time || !gpu || !order || !by_value || !p) {
        snprintf(err, err_size, "%s: out of memory writing the Pareto chart's data", run->dir);
        rc = TW_ERR_NOMEM;
        goto out;
    }
    memcpy(points, s->points, sizeof(*points) * n);
    for (uint32_t k = 0; k < n; k++) {
        gpu[k] = NAN;
        for (uint32_t v = 0; v < s->count; v++)
            if (s->values[v] == points[k].value)
                gpu[k] = gpu_ms(&s->figures[v][points[k].method]);
        time[k] = d->gpu ? gpu[k] : points[k].cpu_ms;
    }
    if (d->gpu)
        tw_pareto_mark_fronts(points, n, time);
    /* By time, the unknown last; and by method and value. */
    for (uint32_t k = 0; k < n; k++) {
        uint32_t j = k;
        for (; j > 0 && (isnan(time[order[j - 1]]) ? !isnan(time[k])
                                                    : time[order[j - 1]] > time[k]); j--)
            order[j] = order[j - 1];
        order[j] = k;
        const uint32_t rank = method_rank(run, points[k].method);
        for (j = k; j > 0; j--) {
            const struct tw_pareto_point *q = &points[by_value[j - 1]];
            const uint32_t q_rank = method_rank(run, q->method);
            if (q_rank < rank || (q_rank == rank && q->value <= points[k].value))
                break;
            by_value[j] = by_value[j - 1];
        }
        by_value[j] = k;
    }
    const char *time_name = d->gpu ? "GPU time" : "CPU time";
    for (int file = 0; file < (d->lod ? 5 : 3) && !rc; file++) {
        struct tw_outfile o;
        if ((rc = open_in(&o, run->dir, names[file], err, err_size)))
            break;
        tw_outfile_printf(&o, "# ");
        tw_outfile_printf(&o, what[file], time_name);
        tw_outfile_printf(&o, " of the sweep of %s, ", s->param);
        tw_outfile_printf(&o, sorted[file], time_name);
        tw_outfile_printf(&o, "\nmethod value mean_cpu_ms missed_per_frame depth_errors_per_frame "
                              "conservative front front_depth speedup time_ms mean_gpu_ms "
                              "lod_fraction front_lod\n");
        for (uint32_t k = 0; k < n; k++) {
            /* Along a front, the faster has more error: the front of image
             * error by time from the slowest is by image error. */
            const uint32_t i = file == 3 ? by_value[k] : file == 4 ? order[n - 1 - k] : order[k];
            const struct tw_pareto_point *pt = &points[i];
            if ((file == 1 && !pt->front) || (file == 2 && !pt->front_depth) ||
                (file == 4 && !pt->front_lod))
                continue;
            tw_outfile_printf(&o, "%s %g %.3f %.3f %.3f %d %d %d %.3f", tw_method_name(pt->method),
                              pt->value, pt->cpu_ms, pt->missed_per_frame,
                              pt->depth_errors_per_frame, pt->conservative, pt->front,
                              pt->front_depth, pt->speedup);
            put_time(&o, time[i]);
            put_time(&o, gpu[i]);
            tw_outfile_printf(&o, " %.6g %d\n", pt->lod_fraction, pt->front_lod);
        }
        rc = tw_outfile_commit(&o, err, err_size);
    }
    /* The axes, as charts.gp sets them, and the labels of the fronts. */
    double lo = INFINITY, hi = -INFINITY, missed_hi = 0.0, depth_hi = 0.0;
    for (uint32_t k = 0; k < n; k++) {
        if (isfinite(time[k])) {
            lo = fmin(lo, time[k]);
            hi = fmax(hi, time[k]);
        }
        missed_hi = fmax(missed_hi, points[k].missed_per_frame);
        depth_hi = fmax(depth_hi, points[k].depth_errors_per_frame);
    }
    if (!isfinite(lo))
        lo = hi = 0.0;
    const double span = hi > lo ? hi - lo : fmax(hi, 1.0) * 0.1;
    g->pa_x_lo = fmax(0.0, lo - 0.15 * span);
    g->pa_x_hi = hi + 0.15 * span;
    symlog_range(missed_hi, 8.0, &g->pa_y_lo[0], &g->pa_y_hi[0]);
    symlog_range(depth_hi, 8.0, &g->pa_y_lo[1], &g->pa_y_hi[1]);
    for (int panel = 0; panel < 2 && !rc; panel++) {
        panel_init(p, panel_left[panel], panel_right[panel], g->pa_x_lo, g->pa_x_hi,
                   g->pa_y_lo[panel], g->pa_y_hi[panel], true);
        for (uint32_t k = 0; k < n; k++) {
            const struct tw_pareto_point *pt = &points[order[k]];
            const bool front = panel == 0 ? pt->front : pt->front_depth;
            char text[96];
            snprintf(text, sizeof(text), "%s %s=%g", tw_method_name(pt->method), s->param,
                     pt->value);
            add_point(p, pt->method, 2, time[order[k]],
                      1.0 + (panel == 0 ? pt->missed_per_frame : pt->depth_errors_per_frame),
                      front ? MARK_FRONT : MARK_PARETO, front ? text : NULL, FONT_VALUE);
        }
        add_note(p, panel == 0 ? "no pixel missed" : "no depth error", FONT_NOTE, 0.99,
                 to_px(&p->y, 1.0) + 16.0);
        char name[64], title[96];
        snprintf(name, sizeof(name), "labels-pareto-%d.dat", panel + 1);
        snprintf(title, sizeof(title), "chart-pareto.png, the %s panel",
                 panel == 0 ? "left (missed pixels)" : "right (depth errors)");
        rc = write_labels(run->dir, name, title, p, err, err_size);
        g->pa_labels[panel] = p->count;
    }
    if (!rc && d->lod)
        rc = write_lod_labels(d, g, points, time, order, by_value, n, p, err, err_size);
out:
    free(p);
    free(by_value);
    free(order);
    free(gpu);
    free(time);
    free(points);
    return rc;
}

/* A gnuplot single-quoted string: '' stands for a quote; no control
 * characters. */
static void put_string(struct tw_outfile *o, const char *s)
{
    tw_outfile_printf(o, "'");
    for (; *s; s++) {
        const char c = (unsigned char)*s < 0x20 || *s == 0x7f ? '?' : *s;
        if (c == '\'')
            tw_outfile_printf(o, "''");
        else
            tw_outfile_printf(o, "%c", c);
    }
    tw_outfile_printf(o, "'");
}

/* chart-pareto.png needs a sweep whose accuracy was measured. */
static int pareto_drawn(const struct tw_chart_run *run)
{
    return run->sweep && run->sweep->points && run->sweep->point_count > 0 && run->verified;
}

/* chart-lod.png needs such a sweep of max_screen_error (bench's name for
 * it): over other sweeps the image error is the same level of detail's. */
static bool lod_drawn(const struct tw_chart_run *run)
{
    return pareto_drawn(run) && strcmp(run->sweep->param, "max_screen_error") == 0;
}

static void put_array(struct tw_outfile *o, const char *name, const double *v)
{
    tw_outfile_printf(o, "array %s[2] = [%.10g, %.10g]\n", name, v[0], v[1]);
}

static int write_run(const struct chart_data *d, const struct geometry *g, char *err,
                     size_t err_size)
{
    const struct tw_chart_run *run = d->run;
    struct tw_outfile o;
    int rc = open_in(&o, run->dir, DATA "/run.gp", err, err_size);
    if (rc)
        return rc;
    char title[800];
    snprintf(title, sizeof(title), "tileset %s, path %s, %ux%u", run->tileset, run->path,
             run->width, run->height);
    tw_outfile_printf(&o, "# What the run was, for charts.gp (written by tileworld)\nrun_title = ");
    put_string(&o, title);
    tw_outfile_printf(&o, "\nmethods = '");
    uint32_t frames = 0;
    bool same_frames = true;
    for (uint32_t k = 0; k < run->method_count; k++) {
        const struct tw_method_figures *fg = &run->figures[run->methods[k]];
        same_frames &= k == 0 || fg->frames == frames;
        frames = fg->frames;
        tw_outfile_printf(&o, "%s%s", k ? " " : "", tw_method_name(run->methods[k]));
    }
    tw_outfile_printf(&o, "'\n# 0: the methods ran different numbers of frames\n"
                          "frames_per_method = %u\n"
                          "# 1: --verify measured missed pixels and overdraw\nverified = %d\n",
                      same_frames ? frames : 0, run->verified ? 1 : 0);
    /* The time every chart plots first; wall time has charts of its own. */
    char note[160];
    if (d->gpu)
        snprintf(note, sizeof(note), "%s, frames whose GPU time did not come back left out",
                 run->context && *run->context ? run->context : "a GPU");
    else if (run->time == TW_CHART_TIME_GPU)
        snprintf(note, sizeof(note), "the process's, all threads (no GPU time came back)");
    else
        snprintf(note, sizeof(note), "the process's, all threads");
    tw_outfile_printf(&o, "# The time the charts plot ('cpu' or, on a real GPU, 'gpu'), its columns\n"
                          "# in frames-*.dat and in methods.dat and sweep-*.dat, its name and what\n"
                          "# it is; wall time (ms_frame, mean_ms) is drawn in chart-*-wall.png\n"
                          "time = '%s'\nframe_time_column = '%s'\nmean_time_column = '%s'\n"
                          "time_name = '%s'\ntime_note = ",
                      d->gpu ? "gpu" : "cpu", d->gpu ? "gpu_ms" : "cpu_ms",
                      d->gpu ? "mean_gpu_ms" : "mean_cpu_ms", d->gpu ? "GPU time" : "CPU time");
    put_string(&o, note);
    /* Each method's means, so that the script need not tell an unknown GPU
     * time from none. */
    static const char *const arrays[3] = {"mean_time", "mean_wall", "time_frames"};
    tw_outfile_printf(&o, "\n# each method's mean time and wall time per frame (ms, NaN: not known)"
                          "\n# and how many frames had a time\n");
    for (int a = 0; a < 3; a++) {
        tw_outfile_printf(&o, "array %s[%u] = [", arrays[a], run->method_count);
        for (uint32_t k = 0; k < run->method_count; k++) {
            const enum tw_method me = run->methods[k];
            const struct tw_method_figures *fg = &run->figures[me];
            const double t = primary_ms(d, fg);
            if (a == 0 && isnan(t))
                tw_outfile_printf(&o, "%sNaN", k ? ", " : "");
            else if (a < 2)
                tw_outfile_printf(&o, "%s%.10g", k ? ", " : "", a == 0 ? t : fg->mean_ms);
            else
                tw_outfile_printf(&o, "%s%u", k ? ", " : "", d->gpu ? fg->gpu_frames : fg->frames);
        }
        tw_outfile_printf(&o, "]\n");
    }
    const struct tw_chart_sweep *s = run->sweep;
    tw_outfile_printf(&o, "# the swept parameter ('': no sweep), its values, and the methods\n"
                          "# whose drawing it does not change\nsweep_param = ");
    put_string(&o, s ? s->param : "");
    tw_outfile_printf(&o, "\nsweep_values = '");
    for (uint32_t k = 0; s && k < s->count; k++)
        tw_outfile_printf(&o, "%s%g", k ? " " : "", s->values[d->order[k]]);
    tw_outfile_printf(&o, "'\nsweep_unaffected = '");
    bool first = true;
    for (uint32_t k = 0; s && k < run->method_count; k++) {
        if (!unaffected(s, run->methods[k]))
            continue;
        tw_outfile_printf(&o, "%s%s", first ? "" : " ", tw_method_name(run->methods[k]));
        first = false;
    }
    tw_outfile_printf(&o, "'\n# 1: chart-data/pareto*.dat hold the sweep's speed against "
                          "accuracy (--verify)\npareto = %d\n", pareto_drawn(run));
    tw_outfile_printf(&o, "# 1: and it is a sweep of max_screen_error: chart-data/pareto-lod.dat,\n"
                          "# pareto-front-lod.dat, labels-lod.dat for chart-lod.png\nlod = %d\n",
                      d->lod ? 1 : 0);
    tw_outfile_printf(&o, "# 1: bench --split filled frames-*.dat's set_* columns\nsplit = %d\n",
                      run->split ? 1 : 0);
    tw_outfile_printf(&o, "# chart-speed-accuracy.png and chart-pareto.png (%dx%d): their panels'\n"
                          "# margins (screen fractions) and axes' ranges, y of the log axes as\n"
                          "# 1 + value; tileworld placed the labels of chart-data/labels-*.dat\n"
                          "# for these (and counted them)\n", CHART_W, CHART_H);
    put_array(&o, "panel_left", panel_left);
    put_array(&o, "panel_right", panel_right);
    tw_outfile_printf(&o, "panel_bottom = %.10g\npanel_top = %.10g\nsa_x_hi = %.10g\n", panel_bottom,
                      panel_top, g->sa_x_hi);
    put_array(&o, "sa_y_lo", g->sa_y_lo);
    put_array(&o, "sa_y_hi", g->sa_y_hi);
    put_array(&o, "sa_y_scale", g->sa_y_scale);
    tw_outfile_printf(&o, "array sa_y_log[2] = [%d, %d]\narray sa_labels[2] = [%u, %u]\n",
                      g->sa_y_log[0], g->sa_y_log[1], g->sa_labels[0], g->sa_labels[1]);
    tw_outfile_printf(&o, "pa_x_lo = %.10g\npa_x_hi = %.10g\n", g->pa_x_lo, g->pa_x_hi);
    put_array(&o, "pa_y_lo", g->pa_y_lo);
    put_array(&o, "pa_y_hi", g->pa_y_hi);
    tw_outfile_printf(&o, "array pa_labels[2] = [%u, %u]\n", g->pa_labels[0], g->pa_labels[1]);
    tw_outfile_printf(&o, "# chart-lod.png: one panel from panel_left[1] to panel_right[2], x the\n"
                          "# pixels differing from full detail (%% of the image) up to lod_x_hi,\n"
                          "# y the time over pa_x_lo to pa_x_hi\nlod_x_hi = %.10g\n"
                          "lod_labels = %u\n", g->lod_x_hi, g->lod_labels);
    return tw_outfile_commit(&o, err, err_size);
}

/* ---- the PNGs gnuplot drew ---------------------------------------------------------------- */

static uint32_t be32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* Why the PNG of size bytes at data is not whole ("" when it is). */
static void png_fault(const unsigned char *data, size_t size, char *why, size_t why_size)
{
    static const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    why[0] = '\0';
    if (size == 0) {
        snprintf(why, why_size, "empty (0 bytes)");
        return;
    }
    if (size < 8 || memcmp(data, signature, 8) != 0) {
        snprintf(why, why_size, "not a PNG (no PNG signature in its %zu bytes)", size);
        return;
    }
    size_t at = 8;
    for (uint32_t chunk = 0;; chunk++) {
        if (size - at < 12) {
            snprintf(why, why_size, "truncated: it ends at byte %zu with no IEND chunk", size);
            return;
        }
        const uint32_t length = be32(data + at);
        char type[5];
        for (int k = 0; k < 4; k++) {
            const unsigned char c = data[at + 4 + k];
            type[k] = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') ? (char)c : '?';
        }
        type[4] = '\0';
        if (length > 0x7fffffffu || strchr(type, '?')) {
            snprintf(why, why_size, "no chunk at byte %zu (length %u, type %s)", at, length, type);
            return;
        }
        if (size - at - 12 < length) {
            snprintf(why, why_size, "truncated: chunk %s at byte %zu needs %llu bytes, the file "
                     "ends at byte %zu", type, at, (unsigned long long)length + 12, size);
            return;
        }
        if (chunk == 0 && (strcmp(type, "IHDR") != 0 || length != 13)) {
            snprintf(why, why_size, "its first chunk is %s, not IHDR", type);
            return;
        }
        /* A chunk's CRC covers its type and data (zlib's crc32, as PNG's). */
        const uint32_t crc = (uint32_t)crc32(0L, data + at + 4, (uInt)length + 4);
        if (crc != be32(data + at + 8 + length)) {
            snprintf(why, why_size, "chunk %s at byte %zu has a bad CRC", type, at);
            return;
        }
        at += (size_t)length + 12;
        if (strcmp(type, "IEND") == 0)
            break;
    }
    if (at != size)
        snprintf(why, why_size, "%zu bytes after its IEND chunk", size - at);
}

/* Reads file and says in why what is wrong with it as a PNG ("" when
 * nothing). Returns TW_OK, or an error with the reason in why. */
static int png_file_fault(const char *file, char *why, size_t why_size)
{
    why[0] = '\0';
    FILE *f = fopen(file, "rb");
    if (!f) {
        snprintf(why, why_size, "cannot read: %s", strerror(errno));
        return TW_ERR_IO;
    }
    unsigned char *data = NULL;
    size_t size = 0, cap = 0;
    int rc = TW_OK;
    for (;;) {
        if (size == cap) {
            /* Charts are tens of kilobytes; 256 MiB is not a chart. */
            unsigned char *grown = cap < (256u << 20) ? realloc(data, cap ? 2 * cap : 65536) : NULL;
            if (!grown) {
                snprintf(why, why_size, "cannot read: %s", cap ? "larger than 256 MiB"
                                                               : strerror(ENOMEM));
                rc = cap ? TW_ERR_FORMAT : TW_ERR_NOMEM;
                break;
            }
            data = grown;
            cap = cap ? 2 * cap : 65536;
        }
        const size_t got = fread(data + size, 1, cap - size, f);
        size += got;
        if (got == 0) {
            if (ferror(f)) {
                snprintf(why, why_size, "cannot read: %s", strerror(errno));
                rc = TW_ERR_IO;
            }
            break;
        }
    }
    fclose(f);
    if (!rc) {
        png_fault(data, size, why, why_size);
        if (why[0])
            rc = TW_ERR_FORMAT;
    }
    free(data);
    return rc;
}

int tw_charts_check_png(const char *file, char *err, size_t err_size)
{
    char why[300];
    const int rc = png_file_fault(file, why, sizeof(why));
    if (rc)
        snprintf(err, err_size, "%s: %s", file, why);
    return rc;
}

/* Whether dir's file system is full: no block left for us (statvfs), or a
 * write of 64 KiB there fails so. Returns that errno value, or 0. */
static int disk_full(const char *dir)
{
    struct statvfs fs;
    if (statvfs(dir, &fs) == 0 && fs.f_bavail == 0)
        return ENOSPC;
    char probe[TW_OUTFILE_PATH];
    snprintf(probe, sizeof(probe), "%s/.tw-space-probe.tmp", dir);
    const int fd = open(probe, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0)
        return errno == ENOSPC || errno == EDQUOT ? errno : 0;
    static const char zeros[65536];
    int e = 0;
    const ssize_t n = write(fd, zeros, sizeof(zeros));
    if (n < 0)
        e = errno;
    else if ((size_t)n < sizeof(zeros))
        e = ENOSPC;
    if (close(fd) != 0 && !e)
        e = errno;
    unlink(probe);
    return e == ENOSPC || e == EDQUOT ? e : 0;
}

static int compare_names(const void *a, const void *b)
{
    return strcmp((const char *)a, (const char *)b);
}

/* Checks each chart gnuplot drew (.chart-NAME.png.tmp), in the order of
 * their names, and gives the whole ones their names; removes the others
 * (and, with keep false, all). Returns TW_OK, or TW_ERR_IO with the first
 * fault in err. */
static int finish_charts(const char *dir, bool keep, char *err, size_t err_size)
{
    DIR *d = opendir(dir);
    if (!d) {
        snprintf(err, err_size, "%s: cannot read the folder: %s", dir, strerror(errno));
        return TW_ERR_IO;
    }
    char names[32][128];
    uint32_t count = 0;
    for (struct dirent *e; (e = readdir(d));) {
        const size_t n = strlen(e->d_name);
        if (strncmp(e->d_name, ".chart-", 7) != 0 || n < 15 || n >= sizeof(names[0]) ||
            strcmp(e->d_name + n - 8, ".png.tmp") != 0)
            continue;
        if (count < sizeof(names) / sizeof(names[0]))
            memcpy(names[count++], e->d_name, n + 1);
    }
    closedir(d);
    qsort(names, count, sizeof(names[0]), compare_names);
    int rc = TW_OK;
    for (uint32_t k = 0; k < count; k++) {
        char tmp[TW_OUTFILE_PATH], final[TW_OUTFILE_PATH];
        const size_t n = strlen(names[k]);
        snprintf(tmp, sizeof(tmp), "%s/%s", dir, names[k]);
        snprintf(final, sizeof(final), "%s/%.*s", dir, (int)(n - 5), names[k] + 1);
        char fault[300];
        if (!keep) {
            unlink(tmp);
        } else if (png_file_fault(tmp, fault, sizeof(fault)) != TW_OK) {
            if (!rc) {
                /* Before it is removed: whether the disk is full. */
                const int full = disk_full(dir);
                if (full)
                    snprintf(err, err_size, "%s: cannot write: %s (gnuplot left it %s)", final,
                             strerror(full), fault);
                else
                    snprintf(err, err_size, "%s: gnuplot did not write it whole: %s", final, fault);
                rc = TW_ERR_IO;
            }
            unlink(tmp);
        } else if (rename(tmp, final) != 0) {
            if (!rc)
                snprintf(err, err_size, "%s: cannot write: %s", final, strerror(errno));
            rc = TW_ERR_IO;
            unlink(tmp);
        }
    }
    return rc;
}

/* ---- gnuplot -------------------------------------------------------------------------- */

/* The last line of gnuplot.log that says something (gnuplot's error, with
 * its script line, comes last). */
static void last_line(const char *file, char *out, size_t size)
{
    out[0] = '\0';
    FILE *f = fopen(file, "r");
    if (!f)
        return;
    char line[512];
    while (fgets(line, sizeof(line), f)) {
        size_t n = strcspn(line, "\r\n");
        line[n] = '\0';
        if (strspn(line, " \t^") < n)
            snprintf(out, size, "%s", line);
    }
    fclose(f);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* Runs `gnuplot -e "cd 'DIR'; tw_temporaries = 1" charts.gp`, its output in
 * DIR/gnuplot.log. Returns TW_OK, TW_CHARTS_NOT_DRAWN or a negative error. */
int tw_charts_run_gnuplot(const char *dir, char *err, size_t err_size)
{
    char log_file[TW_OUTFILE_PATH];
    snprintf(log_file, sizeof(log_file), "%s/gnuplot.log", dir);
    struct tw_outfile log;
    int rc = tw_outfile_open(&log, log_file, err, err_size);
    if (rc)
        return rc;
    /* gnuplot's own quoting: '' inside a single-quoted string. */
    char command[2 * TW_OUTFILE_PATH + 64];
    size_t n = (size_t)snprintf(command, sizeof(command), "cd '");
    for (const char *c = dir; *c && n + 40 < sizeof(command); c++) {
        if (*c == '\'')
            command[n++] = '\'';
        command[n++] = *c;
    }
    snprintf(command + n, sizeof(command) - n, "'; tw_temporaries = 1");
    char *const argv[] = {"gnuplot", "-e", command, "charts.gp", NULL};

    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, fileno(log.f), STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, fileno(log.f), STDERR_FILENO);
    pid_t pid = 0;
    const int spawn_err = posix_spawnp(&pid, "gnuplot", &actions, NULL, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawn_err) {
        tw_outfile_discard(&log);
        if (spawn_err == ENOENT)
            snprintf(err, err_size, "%s: gnuplot is not installed (not found in PATH), so no charts "
                     "were drawn; charts.gp and chart-data/ are written: install gnuplot and run "
                     "`gnuplot charts.gp` there", dir);
        else
            snprintf(err, err_size, "%s: cannot run gnuplot: %s", dir, strerror(spawn_err));
        return TW_CHARTS_NOT_DRAWN;
    }

    /* Waited for with a deadline: a wedged gnuplot must not hold the run. */
    const double deadline = now_s() + TW_CHARTS_TIMEOUT_S;
    int status = 0;
    bool timed_out = false;
    for (;;) {
        const pid_t done = waitpid(pid, &status, WNOHANG);
        if (done == pid)
            break;
        if (done < 0 && errno != EINTR) {
            status = -1;
            break;
        }
        if (now_s() >= deadline) {
            kill(pid, SIGKILL);
            while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
                ;
            timed_out = true;
            break;
        }
        const struct timespec pause = {0, 10 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    const bool ok = !timed_out && status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == 0;
    /* gnuplot exits 0 having written a chart short on a full disk: every
     * chart is checked before it gets its name. A chart's fault is told
     * before gnuplot.log's (which a full disk stops too). */
    char chart_err[TW_OUTFILE_PATH + 400];
    const int charts_rc = finish_charts(dir, ok, chart_err, sizeof(chart_err));
    const int log_rc = tw_outfile_commit(&log, err, err_size);
    if (charts_rc) {
        snprintf(err, err_size, "%s", chart_err);
        return charts_rc;
    }
    if (log_rc)
        return log_rc;
    if (ok)
        return TW_OK;
    char why[600];
    last_line(log_file, why, sizeof(why));
    /* gnuplot that stopped at a file it could not write on a full disk is a
     * failure of the run, not a missing tool. */
    const int full = timed_out ? 0 : disk_full(dir);
    if (full)
        snprintf(err, err_size, "%s: cannot write the charts: %s (gnuplot: %s)", dir,
                 strerror(full), *why ? why : "no message");
    else if (timed_out)
        snprintf(err, err_size, "%s/charts.gp: gnuplot did not finish within %d s and was stopped; "
                 "no charts", dir, TW_CHARTS_TIMEOUT_S);
    else if (status != -1 && WIFSIGNALED(status))
        snprintf(err, err_size, "%s/charts.gp: gnuplot was killed by signal %d, no charts (see "
                 "gnuplot.log)", dir, WTERMSIG(status));
    else
        snprintf(err, err_size, "%s/charts.gp: gnuplot failed (exit status %d), no charts: %s", dir,
                 status == -1 ? -1 : WEXITSTATUS(status), *why ? why : "no message");
    return full ? TW_ERR_IO : TW_CHARTS_NOT_DRAWN;
}

int tw_charts_write(const struct tw_chart_run *run, char *err, size_t err_size)
{
    struct chart_data d = {.run = run};
    const struct tw_chart_sweep *s = run->sweep;
    if (s && s->count > sizeof(d.order) / sizeof(d.order[0])) {
        snprintf(err, err_size, "%s: more than 64 sweep values to chart", run->dir);
        return TW_ERR_LIMIT;
    }
    /* GPU time where it was asked for and some came back. */
    for (uint32_t k = 0; k < run->method_count && run->time == TW_CHART_TIME_GPU; k++)
        d.gpu |= run->figures[run->methods[k]].gpu_frames > 0;
    if (s)
        sort_values(s, d.order);
    d.lod = lod_drawn(run);
    int rc = TW_OK;
    struct geometry g;
    memset(&g, 0, sizeof(g));
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/charts.gp", run->dir);
    if (!rc)
        rc = write_methods(&d, err, err_size);
    if (!rc && s)
        rc = write_sweep(&d, err, err_size);
    if (!rc)
        rc = write_speed_accuracy(&d, &g, err, err_size);
    if (!rc && pareto_drawn(run))
        rc = write_pareto(&d, &g, err, err_size);
    if (!rc)
        rc = write_run(&d, &g, err, err_size);
    if (!rc)
        rc = tw_outfile_write_all(file, TW_CHARTS_GP, strlen(TW_CHARTS_GP), err, err_size);
    return rc ? rc : tw_charts_run_gnuplot(run->dir, err, err_size);
}
