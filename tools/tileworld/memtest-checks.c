/* tileworld memtest: what must hold, judged from a run's figures, and the
 * verdict over the runs (memtest-private.h). */
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>

#include "tools/tileworld/memtest-private.h"

/* Check 4: the p99 of load latency (frames from a tile's request to its
 * being ready) over the run, at the default speed (2 m a frame). Measured
 * on llvmpipe, two shared cores, city-gen, straight, 320x180, policy wait,
 * default workers (1), 5 km (tileworld memtest --distance 5 --budget B):
 * median 2 frames at every budget; p99 32 at 64M, 57 at 64M with a test
 * running beside it, 79 at 16M, 103 at 4M (a budget below what one view
 * needs: nearly every load is a reload and the queue backs up); max 141-226.
 * Most tiles are requested by the look-ahead, well before they are needed,
 * and a tile a frame needs is made on the spot, so a long latency means the
 * workers are behind. 90 frames is 180 m of walking, more than two tiles:
 * a queue that keeps up stays under it, one that backs up does not. */
#define LATENCY_P99_BOUND 90.0
/* Check 2: RSS flat in distance. */
#define RSS_GROWTH_BOUND 1.05

/* why: for TW_MEMTEST_NOT_APPLICABLE, why not (else NULL). */
static void add_check(struct tw_memtest_result *r, enum tw_memtest_verdict v, const char *name,
                      const char *what, const char *figure, const char *why)
{
    struct tw_memtest_check *c = &r->checks[r->check_count++];
    snprintf(c->name, sizeof(c->name), "%s", name);
    snprintf(c->what, sizeof(c->what), "%s", what);
    snprintf(c->figure, sizeof(c->figure), "%s", figure);
    snprintf(c->why, sizeof(c->why), "%s", why ? why : "");
    c->verdict = v;
}

/* Check 1: cache bytes within the budget, except where the view needs more. */
static void check_budget(struct tw_memtest_result *r)
{
    char what[200], figure[400];
    if (r->budget == 0) {
        snprintf(figure, sizeof(figure), "no --budget: peak %.1f MiB of cache",
                 r->peak_total / TW_MEMTEST_MIB);
        add_check(r, TW_MEMTEST_NOT_APPLICABLE, "within the budget",
                  "cache bytes <= the budget on every frame", figure, "no --budget given");
        return;
    }
    snprintf(what, sizeof(what), "cache bytes <= the budget (%.1f MiB) on every frame, except "
             "frames whose visible set alone needs more", r->budget / TW_MEMTEST_MIB);
    int n = snprintf(figure, sizeof(figure), "peak %.1f MiB; %u of %u frames over the budget: "
                     "%u where the view needed more (peak need %.1f MiB), %u otherwise",
                     r->peak_total / TW_MEMTEST_MIB, r->frames_over, r->frames,
                     r->frames_over_needed, r->peak_needed / TW_MEMTEST_MIB, r->frames_over_other);
    if (r->frames_over_other && n > 0 && (size_t)n < sizeof(figure))
        snprintf(figure + n, sizeof(figure) - (size_t)n, " (worst %.2f MiB over at frame %u)",
                 r->worst_over / TW_MEMTEST_MIB, r->worst_over_frame);
    add_check(r, r->frames_over_other == 0 ? TW_MEMTEST_HELD : TW_MEMTEST_FAILED,
              "within the budget", what, figure, NULL);
}

/* Check 2: RSS flat in distance. */
static void check_rss(struct tw_memtest_result *r)
{
    char what[200], figure[400];
    snprintf(what, sizeof(what), "RSS flat: peak over the last 10 %% of the distance <= %.2f x the "
             "peak over 40-50 %% of it (memory.csv's rows; the first part lets the cache fill "
             "and the allocator's heap settle)", RSS_GROWTH_BOUND);
    const double growth = r->rss_first ? (double)r->rss_last / (double)r->rss_first : 0.0;
    snprintf(figure, sizeof(figure), "40-50 %%: %.1f MiB, last 10 %%: %.1f MiB (%+.1f %%); "
             "the allocator's heap at the end: %.1f MiB in use, %.1f MiB held free",
             r->rss_first / TW_MEMTEST_MIB, r->rss_last / TW_MEMTEST_MIB, 100.0 * (growth - 1.0),
             r->heap_used / TW_MEMTEST_MIB, r->heap_free / TW_MEMTEST_MIB);
    if (r->rss_first_rows < 2 || r->rss_last_rows < 2) {
        snprintf(figure, sizeof(figure), "%u and %u rows at 40-50 %% and in the last 10 %%: "
                 "--every is too coarse for --distance to see a trend", r->rss_first_rows,
                 r->rss_last_rows);
        add_check(r, TW_MEMTEST_NOT_APPLICABLE, "RSS flat", what, figure, "too few rows of "
                  "memory.csv for a trend: give a smaller --every or a longer --distance");
    } else {
        add_check(r, r->rss_first && growth <= RSS_GROWTH_BOUND ? TW_MEMTEST_HELD
                                                                : TW_MEMTEST_FAILED,
                  "RSS flat", what, figure, NULL);
    }
}

/* Check 3: no leak, by the cache's own count against the tile events. */
static void check_leak(struct tw_memtest_result *r)
{
    char figure[400];
    const bool leak_free = r->accounting_mismatch_frames == 0 && r->live_tiles == r->event_tiles &&
                           r->live_bytes == r->event_bytes &&
                           r->totals_loads_done == r->loads_done &&
                           r->totals_evictions == r->tile_evictions &&
                           r->live_tiles + r->totals_evictions == r->totals_loads_done;
    snprintf(figure, sizeof(figure), "at the end %u tiles, %llu bytes live in the cache; loaded "
             "less evicted: %u tiles, %llu bytes (%llu loaded - %llu evicted); %u frames where "
             "they differed",
             r->live_tiles, (unsigned long long)r->live_bytes, r->event_tiles,
             (unsigned long long)r->event_bytes, (unsigned long long)r->loads_done,
             (unsigned long long)r->tile_evictions, r->accounting_mismatch_frames);
    add_check(r, leak_free ? TW_MEMTEST_HELD : TW_MEMTEST_FAILED, "no leak",
              "no leak: the live tiles and bytes the cache reports are what was loaded less what "
              "was evicted, on every frame", figure, NULL);
}

/* Check 4: load latency bounded. */
static void check_latency(struct tw_memtest_result *r)
{
    char what[200], figure[400];
    snprintf(what, sizeof(what), "load latency p99 <= %.0f frames (request to ready, at 2 m a "
             "frame)", LATENCY_P99_BOUND);
    if (r->lat_count == 0) {
        snprintf(figure, sizeof(figure), "no tile was loaded: nothing to time");
        add_check(r, TW_MEMTEST_NOT_APPLICABLE, "load latency", what, figure, "no tile was "
                  "loaded in the walk: only providers such as city-gen load tiles");
    } else {
        snprintf(figure, sizeof(figure), "median %.0f, p99 %.0f, max %.0f frames over %u loads",
                 r->lat_median, r->lat_p99, r->lat_max, r->lat_count);
        add_check(r, r->lat_p99 <= LATENCY_P99_BOUND ? TW_MEMTEST_HELD : TW_MEMTEST_FAILED,
                  "load latency", what, figure, NULL);
    }
}

void tw_memtest_judge(struct tw_memtest_result *r)
{
    r->check_count = 0;
    check_budget(r);
    check_rss(r);
    check_leak(r);
    check_latency(r);
    r->all_held = true;
    for (uint32_t k = 0; k < r->check_count; k++)
        r->all_held &= r->checks[k].verdict != TW_MEMTEST_FAILED;
}

/* Appends printf text to out (size bytes, *len used), cut to fit. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static void append(char *out, size_t size, size_t *len, const char *fmt, ...)
{
    if (*len + 1 >= size)
        return;
    va_list ap;
    va_start(ap, fmt);
    const int n = vsnprintf(out + *len, size - *len, fmt, ap);
    va_end(ap);
    if (n > 0)
        *len = *len + (size_t)n < size ? *len + (size_t)n : size - 1;
}

/* The verdict over the runs, for the last line: how many checks held, which
 * did not, which were not applicable and why. Every run has the same checks
 * in the same order. */
void tw_memtest_verdict_text(const struct tw_memtest_result *results, uint32_t runs, char *out,
                             size_t size)
{
    uint32_t held = 0, failed = 0, not_applicable = 0, total = 0;
    for (uint32_t k = 0; k < runs; k++)
        for (uint32_t c = 0; c < results[k].check_count; c++) {
            const enum tw_memtest_verdict v = results[k].checks[c].verdict;
            held += v == TW_MEMTEST_HELD;
            failed += v == TW_MEMTEST_FAILED;
            not_applicable += v == TW_MEMTEST_NOT_APPLICABLE;
            total++;
        }
    size_t len = 0;
    out[0] = '\0';
    if (failed)
        append(out, size, &len, "SOME CHECKS DID NOT HOLD: ");
    if (held == total)
        append(out, size, &len, "all %u checks held", total);
    else
        append(out, size, &len, "%u of %u checks held", held, total);
    if (runs > 1)
        append(out, size, &len, " over %u runs", runs);
    for (int pass = 0; pass < 2; pass++) {
        const enum tw_memtest_verdict want = pass == 0 ? TW_MEMTEST_FAILED
                                                       : TW_MEMTEST_NOT_APPLICABLE;
        const uint32_t count = pass == 0 ? failed : not_applicable;
        if (count == 0)
            continue;
        append(out, size, &len, pass == 0 ? "; %u did not: " : "; %u not applicable: ", count);
        bool first = true;
        for (uint32_t c = 0; c < results[0].check_count; c++) {
            uint32_t in = 0;
            const struct tw_memtest_check *example = NULL;
            for (uint32_t k = 0; k < runs; k++)
                if (c < results[k].check_count && results[k].checks[c].verdict == want) {
                    in++;
                    if (!example)
                        example = &results[k].checks[c];
                }
            if (!in)
                continue;
            append(out, size, &len, "%s%s", first ? "" : ", ", example->name);
            if (runs > 1)
                append(out, size, &len, " in %u of %u runs", in, runs);
            if (want == TW_MEMTEST_NOT_APPLICABLE)
                append(out, size, &len, " (%s)", example->why);
            first = false;
        }
    }
}

