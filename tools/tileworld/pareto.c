/* Speed against accuracy over a sweep: points, Pareto fronts, sweep.md (pareto.h). */
#include "tools/tileworld/pareto.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* Whether q beats p: no slower, no more errors, and better on one. */
static bool dominates(double q_time, double q_error, double p_time, double p_error)
{
    return q_time <= p_time && q_error <= p_error && (q_time < p_time || q_error < p_error);
}

/* The fronts: of time against missed pixels, depth errors, image error. */
enum front { FRONT_MISSED, FRONT_DEPTH, FRONT_LOD, FRONT_COUNT };

static double error_of(const struct tw_pareto_point *p, enum front f)
{
    return f == FRONT_MISSED ? p->missed_per_frame
           : f == FRONT_DEPTH ? p->depth_errors_per_frame
                              : p->lod_fraction;
}

static bool on_front(const struct tw_pareto_point *p, enum front f)
{
    return f == FRONT_MISSED ? p->front : f == FRONT_DEPTH ? p->front_depth : p->front_lod;
}

/* Marks the points of out that no other (realisable) point dominates, by
 * time[k] (NULL: cpu_ms); a point of unknown time (NaN) is on no front and
 * beats none. */
static void mark_front(struct tw_pareto_point *points, uint32_t n, const double *time, enum front f)
{
    for (uint32_t p = 0; p < n; p++) {
        struct tw_pareto_point *pp = &points[p];
        const double p_time = time ? time[p] : pp->cpu_ms;
        bool beaten = tw_method_limit(pp->method) || isnan(p_time);
        for (uint32_t q = 0; q < n && !beaten; q++) {
            const struct tw_pareto_point *qp = &points[q];
            const double q_time = time ? time[q] : qp->cpu_ms;
            if (q == p || tw_method_limit(qp->method) || isnan(q_time))
                continue;
            beaten = dominates(q_time, error_of(qp, f), p_time, error_of(pp, f));
        }
        if (f == FRONT_MISSED)
            pp->front = !beaten;
        else if (f == FRONT_DEPTH)
            pp->front_depth = !beaten;
        else
            pp->front_lod = !beaten;
    }
}

void tw_pareto_points(const double *values, uint32_t count,
                      const struct tw_method_figures (*figures)[TW_METHOD_ALL],
                      const bool (*conservative)[TW_METHOD_ALL], const enum tw_method *methods,
                      uint32_t method_count, const struct tw_method_figures *reference,
                      uint32_t reference_value_index, struct tw_pareto_point *out)
{
    for (uint32_t k = 0; k < count; k++)
        for (uint32_t m = 0; m < method_count; m++) {
            const enum tw_method me = methods[m];
            const struct tw_method_figures *fg = &figures[k][me];
            const struct tw_method_figures *ref = reference_value_index < count
                                                      ? &figures[reference_value_index][me]
                                                      : &reference[me];
            const double frames = fg->frames ? (double)fg->frames : 1.0;
            out[k * method_count + m] = (struct tw_pareto_point){
                .method = me,
                .value = values[k],
                .cpu_ms = fg->mean_cpu_ms,
                .speedup = fg->mean_cpu_ms > 0.0 ? ref->mean_cpu_ms / fg->mean_cpu_ms : 0.0,
                .missed_per_frame = (double)fg->missed_pixels_total / frames,
                .depth_errors_per_frame = (double)fg->depth_errors_total / frames,
                .lod_fraction = fg->lod_pixel_fraction,
                .conservative = conservative[k][me],
            };
        }
    tw_pareto_mark_fronts(out, count * method_count, NULL);
}

void tw_pareto_mark_fronts(struct tw_pareto_point *points, uint32_t n, const double *time)
{
    for (int f = 0; f < FRONT_COUNT; f++)
        mark_front(points, n, time, (enum front)f);
}

/* The points' indices by CPU time, then by method and value. */
static uint32_t *by_time(const struct tw_pareto_point *points, uint32_t n)
{
    uint32_t *order = malloc(sizeof(*order) * (n ? n : 1));
    if (!order)
        return NULL;
    for (uint32_t k = 0; k < n; k++) {
        uint32_t j = k;
        for (; j > 0 && points[order[j - 1]].cpu_ms > points[k].cpu_ms; j--)
            order[j] = order[j - 1];
        order[j] = k;
    }
    return order;
}

static void name_front(struct tw_outfile *o, const char *param, const char *reference,
                       const struct tw_pareto_point *points, const uint32_t *order, uint32_t n,
                       enum front f)
{
    static const char *const against[FRONT_COUNT] = {
        "missed pixels", "depth errors", "image error (pixels differing from full detail)",
    };
    static const char *const as_few[FRONT_COUNT] = {
        "as few missed pixels", "as few depth errors", "as little image error",
    };
    tw_outfile_printf(o, "\n**The front of CPU time against %s** (no other point is as fast "
                         "with %s, and better in one; the oracles are left out: they need "
                         "the ID pass):\n\n", against[f], as_few[f]);
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_pareto_point *p = &points[order[k]];
        if (!on_front(p, f))
            continue;
        char error[96];
        if (f == FRONT_LOD)
            snprintf(error, sizeof(error), "%.3f %% of the pixels differing from full detail "
                                           "per frame", 100.0 * p->lod_fraction);
        else
            snprintf(error, sizeof(error), "%.1f %s per frame", error_of(p, f), against[f]);
        tw_outfile_printf(o, "- %s %s=%g: %.2f ms CPU per frame, speed-up %.2f over %s, %s%s\n",
                          tw_method_name(p->method), param, p->value, p->cpu_ms, p->speedup,
                          reference, error, p->conservative ? " (conservative)" : "");
    }
}

void tw_pareto_write_md(struct tw_outfile *o, const char *param, const char *reference,
                        bool verified, const struct tw_pareto_point *points, uint32_t n)
{
    uint32_t *order = by_time(points, n);
    if (!order) {
        tw_outfile_printf(o, "(out of memory)\n");
        return;
    }
    tw_outfile_printf(o, "| method | %s | mean CPU ms | speed-up vs %s | missed pixels / frame | "
                         "depth errors / frame | pixels differing from full detail (%%) | "
                         "conservative | on the front |\n"
                         "|---|---|---|---|---|---|---|---|---|\n", param, reference);
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_pareto_point *p = &points[order[k]];
        const char *front = !verified ? "-"
                            : tw_method_limit(p->method) ? "no (a limit)"
                            : p->front && p->front_depth ? "yes (both)"
                            : p->front ? "yes" : p->front_depth ? "depth errors only" : "no";
        char speedup[32] = "-", lod[32] = "-";
        if (p->speedup > 0.0)
            snprintf(speedup, sizeof(speedup), "%.2fx", p->speedup);
        if (verified)
            snprintf(lod, sizeof(lod), "%.3f", 100.0 * p->lod_fraction);
        tw_outfile_printf(o, "| %s | %g | %.2f | %s | %.1f | %.1f | %s | %s | %s |\n",
                          tw_method_name(p->method), p->value, p->cpu_ms, speedup,
                          p->missed_per_frame, p->depth_errors_per_frame, lod,
                          p->conservative ? "yes" : "no", front);
    }
    if (verified) {
        for (int f = 0; f < FRONT_COUNT; f++)
            name_front(o, param, reference, points, order, n, (enum front)f);
    } else {
        tw_outfile_printf(o, "\nAccuracy not measured (no --verify): no front, missed pixels read "
                             "0.\n");
    }
    free(order);
}
