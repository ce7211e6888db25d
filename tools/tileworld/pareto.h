/*
 * Speed against accuracy over a sweep (DESIGN.md §8): one point per method
 * and value of the swept parameter, at its mean CPU time per frame and its
 * missed pixels (and depth errors, and image error of levels of detail) per
 * frame; a Pareto front is the set of points that no other point beats on
 * both (as fast or faster and with as few errors or fewer, better on one).
 * The oracle is drawn, never on a front: it needs the ID pass to know what
 * to draw, so no host can have it.
 *
 * bench --sweep writes sweep.md from these (each front named with its
 * speed-up and its error) and charts.h draws them as chart-pareto.png and,
 * for a sweep of max_screen_error, chart-lod.png (on a real GPU by GPU
 * time, tw_pareto_mark_fronts).
 */
#ifndef TW_TOOLS_PARETO_H
#define TW_TOOLS_PARETO_H

#include <stdbool.h>
#include <stdint.h>

#include "tools/outfile.h"
#include "tools/tileworld/report.h"

struct tw_pareto_point {
    enum tw_method method;
    double value;                  /* of the swept parameter */
    double cpu_ms;                 /* mean CPU time per frame */
    double speedup;                /* reference's mean CPU time / cpu_ms (0: no reference) */
    double missed_per_frame;       /* missed pixels, mean per frame */
    double depth_errors_per_frame;
    double lod_fraction;           /* image error: share of the pixels differing from full
                                      detail, mean per frame (0: not measured) */
    bool conservative;             /* tw_method_conservative() at this value (T = 0) */
    bool front;                    /* on the front of CPU time against missed pixels */
    bool front_depth;              /* on the front of CPU time against depth errors */
    bool front_lod;                /* on the front of CPU time against lod_fraction */
};

/* The points of a sweep: for each of count values (values[k], figures[k]
 * by method) and each of the methods, one point (count * method_count
 * into out, value-major). conservative[k][m] says whether method m was
 * conservative at value k. A point's speed-up is against reference[m]
 * (the run with the defaults), or, when reference_value_index is not
 * UINT32_MAX, against the method's point at that value. */
void tw_pareto_points(const double *values, uint32_t count,
                      const struct tw_method_figures (*figures)[TW_METHOD_ALL],
                      const bool (*conservative)[TW_METHOD_ALL], const enum tw_method *methods,
                      uint32_t method_count, const struct tw_method_figures *reference,
                      uint32_t reference_value_index, struct tw_pareto_point *out);

/* Marks the fronts of n points again, each point's time being time[k]
 * instead of its cpu_ms (the charts' GPU time on a real GPU; NULL: cpu_ms,
 * as tw_pareto_points() does); a point whose time is NaN (not known) is on
 * no front and beats none. */
void tw_pareto_mark_fronts(struct tw_pareto_point *points, uint32_t n, const double *time);

/* Writes the sweep's points as markdown into o: one table row per point
 * (by CPU time), then the three fronts named. param: the parameter's name;
 * reference: what the speed-up is against ("T=0"); verified: accuracy was
 * measured (else no front is named). */
void tw_pareto_write_md(struct tw_outfile *o, const char *param, const char *reference,
                        bool verified, const struct tw_pareto_point *points, uint32_t count);

#endif
