/* tileworld memtest: summary.json, summary.md, the sweep's table and the
 * charts (memtest-private.h). */
#include <stdio.h>
#include <string.h>

#include <json-c/json.h>

#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/memtest-gp.h"   /* TW_MEMTEST_GP: tools/tileworld/memtest.gp, built in */
#include "tools/outfile.h"
#include "tools/tileworld/charts.h"
#include "tools/tileworld/memtest-private.h"
#include "tools/tileworld/report.h"

static const char program[] = TW_MEMTEST_PROGRAM;

static const char *verdict_name(enum tw_memtest_verdict v)
{
    return v == TW_MEMTEST_HELD ? "yes" : v == TW_MEMTEST_FAILED ? "no" : "not applicable";
}

static json_object *number(double v, int decimals)
{
    char text[64];
    snprintf(text, sizeof(text), "%.*f", decimals, v);
    return json_object_new_double_s(v, text);
}

static json_object *u64(uint64_t v)
{
    return json_object_new_int64(v > (uint64_t)INT64_MAX ? INT64_MAX : (int64_t)v);
}

static const char *policy_name(enum tw_stream_policy p)
{
    return p == TW_STREAM_SKIP ? "skip" : "wait";
}

static json_object *result_json(const struct tw_memtest_options *o,
                                const struct tw_cli_world *shown, const struct tw_memtest_result *r)
{
    json_object *root = json_object_new_object();
    json_object_object_add(root, "tileset", json_object_new_string(shown->name));
    json_object_object_add(root, "path", json_object_new_string(o->cli.path));
    char size[64];
    snprintf(size, sizeof(size), "%ux%u", o->cli.world.width, o->cli.world.height);
    json_object_object_add(root, "size", json_object_new_string(size));
    json_object_object_add(root, "seed", u64(o->cli.world.selection.seed));
    json_object_object_add(root, "heap_used_bytes", u64(r->heap_used));
    json_object_object_add(root, "heap_free_bytes", u64(r->heap_free));
    json_object_object_add(root, "peak_heap_free_bytes", u64(r->heap_free_peak));
    json_object_object_add(root, "budget_bytes", u64(r->budget));
    json_object_object_add(root, "workers", json_object_new_int64(o->cli.world.workers));
    json_object_object_add(root, "policy", json_object_new_string(policy_name(o->cli.world.policy)));
    json_object_object_add(root, "view_distance", number(o->cli.world.view_distance, 1));
    json_object_object_add(root, "distance_m", number(r->distance_m, 1));
    json_object_object_add(root, "every_m", number(o->every_m, 1));
    json_object_object_add(root, "frames", json_object_new_int64(r->frames));
    json_object_object_add(root, "wall_s", number(r->wall_s, 1));
    json_object_object_add(root, "peak_cache_bytes", u64(r->peak_total));
    json_object_object_add(root, "final_cache_bytes", u64(r->final_total));
    json_object_object_add(root, "peak_needed_bytes", u64(r->peak_needed));
    json_object_object_add(root, "frames_over_budget", json_object_new_int64(r->frames_over));
    json_object_object_add(root, "frames_over_budget_view_needed",
                           json_object_new_int64(r->frames_over_needed));
    json_object_object_add(root, "frames_over_budget_otherwise",
                           json_object_new_int64(r->frames_over_other));
    json_object_object_add(root, "rss_start_bytes", u64(r->rss_start));
    json_object_object_add(root, "peak_rss_bytes", u64(r->peak_rss));
    json_object_object_add(root, "final_rss_bytes", u64(r->final_rss));
    json_object *km = json_object_new_array();
    for (uint32_t k = 0; k < r->rss_km_count; k++)
        json_object_array_add(km, u64(r->rss_km[k]));
    json_object_object_add(root, "rss_bytes_by_km", km);
    json_object_object_add(root, "loads_requested", u64(r->loads_requested));
    json_object_object_add(root, "loads_done", u64(r->loads_done));
    json_object_object_add(root, "evictions", u64(r->evictions));
    json_object_object_add(root, "tile_evictions", u64(r->tile_evictions));
    json_object_object_add(root, "reloads", u64(r->reloads));
    json_object_object_add(root, "reloads_library", u64(r->totals_reloads));
    json_object_object_add(root, "refused", u64(r->refused));
    json_object_object_add(root, "holes", u64(r->holes));
    json_object_object_add(root, "latency_median_frames", number(r->lat_median, 0));
    json_object_object_add(root, "latency_p99_frames", number(r->lat_p99, 0));
    json_object_object_add(root, "latency_max_frames", number(r->lat_max, 0));
    json_object_object_add(root, "mean_ms", number(r->mean_ms, 3));
    json_object_object_add(root, "median_ms", number(r->median_ms, 3));
    json_object_object_add(root, "p99_ms", number(r->p99_ms, 3));
    json_object_object_add(root, "mean_cpu_ms", number(r->mean_cpu_ms, 3));
    json_object *checks = json_object_new_array();
    for (uint32_t k = 0; k < r->check_count; k++) {
        json_object *c = json_object_new_object();
        json_object_object_add(c, "must_hold", json_object_new_string(r->checks[k].what));
        json_object_object_add(c, "figure", json_object_new_string(r->checks[k].figure));
        json_object_object_add(c, "held", json_object_new_string(verdict_name(r->checks[k].verdict)));
        json_object_array_add(checks, c);
    }
    json_object_object_add(root, "checks", checks);
    json_object_object_add(root, "all_held", json_object_new_boolean(r->all_held));
    return root;
}

static void md_checks(struct tw_outfile *f, const struct tw_memtest_result *r)
{
    tw_outfile_printf(f, "| what must hold | figure | held |\n|---|---|---|\n");
    for (uint32_t k = 0; k < r->check_count; k++) {
        const struct tw_memtest_check *c = &r->checks[k];
        tw_outfile_printf(f, "| %s | %s | %s |\n", c->what, c->figure,
                          c->verdict == TW_MEMTEST_FAILED ? "**no**" : verdict_name(c->verdict));
    }
}

static void md_rss_km(struct tw_outfile *f, const struct tw_memtest_result *r)
{
    tw_outfile_printf(f, "RSS when each kilometre was reached (MiB):");
    for (uint32_t k = 0; k < r->rss_km_count; k++)
        tw_outfile_printf(f, "%s %u km %.1f", k ? "," : "", k, r->rss_km[k] / TW_MEMTEST_MIB);
    tw_outfile_printf(f, ".\n");
}

int tw_memtest_write_run_summary(const struct tw_memtest_options *o,
                                 const struct tw_cli_world *shown, const char *dir,
                                 const struct tw_memtest_result *r, char *err, size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/summary.json", dir);
    json_object *root = result_json(o, shown, r);
    int rc = tw_report_write_json(file, root, JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED,
                                  err, err_size);
    json_object_put(root);
    if (rc)
        return rc;
    snprintf(file, sizeof(file), "%s/summary.md", dir);
    struct tw_outfile f;
    rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char name[512];
    tw_outfile_printf(&f, "# tileworld memtest: %s, path %s, %.2f km, budget %s, %ux%u, seed %llu\n\n",
                      tw_cli_escape(shown->name, name, sizeof(name)), o->cli.path,
                      r->distance_m / 1000.0, r->budget ? r->budget_text : "none",
                      o->cli.world.width, o->cli.world.height,
                      (unsigned long long)o->cli.world.selection.seed);
    char workers[32];
    if (o->cli.world.workers)
        snprintf(workers, sizeof(workers), "%u", o->cli.world.workers);
    else
        snprintf(workers, sizeof(workers), "the default number of");
    tw_outfile_printf(&f, "%u frames in %.1f s (policy %s, %s workers, view distance %g m); one "
                          "row of memory.csv every %g m.\n\n", r->frames, r->wall_s,
                      policy_name(o->cli.world.policy), workers, o->cli.world.view_distance,
                      o->every_m);
    md_checks(&f, r);
    tw_outfile_printf(&f, "\n| figure | value |\n|---|---|\n");
    tw_outfile_printf(&f, "| cache bytes, peak / final | %.1f / %.1f MiB |\n",
                      r->peak_total / TW_MEMTEST_MIB, r->final_total / TW_MEMTEST_MIB);
    tw_outfile_printf(&f, "| the view's need, peak | %.1f MiB |\n",
                      r->peak_needed / TW_MEMTEST_MIB);
    tw_outfile_printf(&f, "| RSS, start / peak / final | %.1f / %.1f / %.1f MiB |\n",
                      r->rss_start / TW_MEMTEST_MIB, r->peak_rss / TW_MEMTEST_MIB,
                      r->final_rss / TW_MEMTEST_MIB);
    tw_outfile_printf(&f, "| heap in use / held free by the allocator, final (peak free) | %.1f / "
                      "%.1f (%.1f) MiB |\n", r->heap_used / TW_MEMTEST_MIB,
                      r->heap_free / TW_MEMTEST_MIB, r->heap_free_peak / TW_MEMTEST_MIB);
    tw_outfile_printf(&f, "| loads requested / done | %llu / %llu |\n",
                      (unsigned long long)r->loads_requested, (unsigned long long)r->loads_done);
    tw_outfile_printf(&f, "| evictions: generated tiles / with culling state | %llu / %llu |\n",
                      (unsigned long long)r->tile_evictions, (unsigned long long)r->evictions);
    tw_outfile_printf(&f, "| reloads (a cell loaded again after its eviction) | %llu |\n",
                      (unsigned long long)r->reloads);
    tw_outfile_printf(&f, "| load latency median / p99 / max | %.0f / %.0f / %.0f frames |\n",
                      r->lat_median, r->lat_p99, r->lat_max);
    tw_outfile_printf(&f, "| holes (policy skip) | %llu |\n", (unsigned long long)r->holes);
    tw_outfile_printf(&f, "| frame time mean / median / p99 | %.2f / %.2f / %.2f ms |\n\n",
                      r->mean_ms, r->median_ms, r->p99_ms);
    md_rss_km(&f, r);
    tw_outfile_printf(&f, "\nCharts: chart-memory.png (bytes and RSS against distance), "
                          "chart-loads.png (loads, evictions, reloads).\n");
    return tw_outfile_commit(&f, err, err_size);
}

/* o->out/sweep.csv: a row per run. */
static int write_sweep_csv(const struct tw_memtest_options *o,
                           const struct tw_memtest_result *results, uint32_t count, char *err,
                           size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/sweep.csv", o->out);
    struct tw_outfile csv;
    int rc = tw_outfile_open(&csv, file, err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&csv, "budget_bytes,frames,distance_m,loads_done,tile_evictions,reloads,"
                            "peak_cache_bytes,final_cache_bytes,peak_rss_bytes,latency_p99,holes,"
                            "mean_ms,p99_ms,all_held,mean_cpu_ms\n");
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_memtest_result *r = &results[k];
        tw_outfile_printf(&csv, "%llu,%u,%.1f,%llu,%llu,%llu,%llu,%llu,%llu,%.0f,%llu,%.3f,%.3f,%d,%.3f\n",
                          (unsigned long long)r->budget, r->frames, r->distance_m,
                          (unsigned long long)r->loads_done, (unsigned long long)r->tile_evictions,
                          (unsigned long long)r->reloads, (unsigned long long)r->peak_total,
                          (unsigned long long)r->final_total, (unsigned long long)r->peak_rss,
                          r->lat_p99, (unsigned long long)r->holes, r->mean_ms, r->p99_ms,
                          r->all_held, r->mean_cpu_ms);
    }
    return tw_outfile_commit(&csv, err, err_size);
}

/* o->out/summary.json: every run's result. */
static int write_sweep_json(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                            const struct tw_memtest_result *results, uint32_t count, char *err,
                            size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    json_object *root = json_object_new_object();
    json_object *runs = json_object_new_array();
    bool all = true;
    for (uint32_t k = 0; k < count; k++) {
        json_object_array_add(runs, result_json(o, shown, &results[k]));
        all &= results[k].all_held;
    }
    json_object_object_add(root, "sweep", json_object_new_string("budget"));
    json_object_object_add(root, "runs", runs);
    json_object_object_add(root, "all_held", json_object_new_boolean(all));
    snprintf(file, sizeof(file), "%s/summary.json", o->out);
    const int rc = tw_report_write_json(file, root,
                                        JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED, err,
                                        err_size);
    json_object_put(root);
    return rc;
}

/* o->out/summary.md: the runs side by side, then each run's checks. */
static int write_sweep_md(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                          const struct tw_memtest_result *results, uint32_t count, char *err,
                          size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/summary.md", o->out);
    struct tw_outfile f;
    const int rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char name[512];
    tw_outfile_printf(&f, "# tileworld memtest sweep of the cache budget: %s, path %s, %.2f km, "
                          "%ux%u, seed %llu\n\n", tw_cli_escape(shown->name, name, sizeof(name)),
                      o->cli.path, o->distance_m / 1000.0, o->cli.world.width, o->cli.world.height,
                      (unsigned long long)o->cli.world.selection.seed);
    tw_outfile_printf(&f, "One run per budget, each in sweep-budget-VALUE/ (memory.csv, summaries, "
                          "charts); chart-sweep-budget.png: reloads and frame time against the "
                          "budget.\n\n| budget | peak cache MiB | final MiB | peak RSS MiB | loads | "
                          "evictions | reloads | latency p99 | holes | mean ms | p99 ms | checks |\n"
                          "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_memtest_result *r = &results[k];
        tw_outfile_printf(&f, "| %s | %.1f | %.1f | %.1f | %llu | %llu | %llu | %.0f | %llu | %.2f | "
                              "%.2f | %s |\n", r->budget_text, r->peak_total / TW_MEMTEST_MIB,
                          r->final_total / TW_MEMTEST_MIB, r->peak_rss / TW_MEMTEST_MIB,
                          (unsigned long long)r->loads_done, (unsigned long long)r->tile_evictions,
                          (unsigned long long)r->reloads, r->lat_p99,
                          (unsigned long long)r->holes, r->mean_ms, r->p99_ms,
                          r->all_held ? "held" : "**some did not hold**");
    }
    for (uint32_t k = 0; k < count; k++) {
        tw_outfile_printf(&f, "\n## budget %s\n\n", results[k].budget_text);
        md_checks(&f, &results[k]);
    }
    return tw_outfile_commit(&f, err, err_size);
}

int tw_memtest_write_sweep(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                           const struct tw_memtest_result *results, uint32_t count, char *err,
                           size_t err_size)
{
    int rc = write_sweep_csv(o, results, count, err, err_size);
    if (!rc)
        rc = write_sweep_json(o, shown, results, count, err, err_size);
    if (!rc)
        rc = write_sweep_md(o, shown, results, count, err, err_size);
    return rc;
}

/* chart-data/run.gp and charts.gp (memtest.gp), then gnuplot: missing or
 * failing is a warning. */
int tw_memtest_draw_charts(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                           const char *dir, uint64_t budget, bool sweep, char *err,
                           size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA, dir);
    const int e = tw_report_make_dirs(file);
    if (e) {
        snprintf(err, err_size, "%s: cannot create: %s", file, strerror(e));
        return TW_ERR_IO;
    }
    snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA "/run.gp", dir);
    struct tw_outfile f;
    int rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char title[600];
    snprintf(title, sizeof(title), "%s, path %s, %.2f km, %ux%u, policy %s", shown->name,
             o->cli.path, o->distance_m / 1000.0, o->cli.world.width, o->cli.world.height,
             policy_name(o->cli.world.policy));
    tw_outfile_printf(&f, "# What the run was, for charts.gp (written by tileworld memtest)\n"
                          "run_title = '");
    for (const char *c = title; *c; c++) {
        const char ch = (unsigned char)*c < 0x20 || *c == 0x7f ? '?' : *c;
        tw_outfile_printf(&f, ch == '\'' ? "''" : "%c", ch);
    }
    tw_outfile_printf(&f, "'\nbudget = %llu.0\nsweep = %d\n", (unsigned long long)budget, sweep);
    rc = tw_outfile_commit(&f, err, err_size);
    if (rc)
        return rc;
    snprintf(file, sizeof(file), "%s/charts.gp", dir);
    rc = tw_outfile_write_all(file, TW_MEMTEST_GP, strlen(TW_MEMTEST_GP), err, err_size);
    if (rc)
        return rc;
    rc = tw_charts_run_gnuplot(dir, err, err_size);
    if (rc == TW_CHARTS_NOT_DRAWN) {
        tw_cli_message(program, "warning: %s", err);
        rc = TW_OK;
    }
    return rc;
}

void tw_memtest_print_checks(const char *dir, const struct tw_memtest_result *r)
{
    printf("%s (budget %s):\n", dir, r->budget ? r->budget_text : "none");
    for (uint32_t k = 0; k < r->check_count; k++)
        printf("  %-14s %s: %s\n", verdict_name(r->checks[k].verdict), r->checks[k].what,
               r->checks[k].figure);
}
