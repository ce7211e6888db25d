/* tileworld memtest: memory against distance travelled (memtest.h). */
#include "tools/tileworld/memtest.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/progress.h"
#include "tools/tileworld/glcontext.h"
#include "tools/tileworld/memtest-private.h"
#include "tools/tileworld/outputs.h"
#include "tools/tileworld/report.h"

static const char program[] = TW_MEMTEST_PROGRAM;

static void usage(FILE *f)
{
    fputs("usage: tileworld memtest [--tileset NAME|FILE.json] [--path straight|wander|FILE.csv]\n"
          "                         [--distance KM] [--every METRES] [--budget BYTES]\n"
          "                         [--sweep budget=B1,B2,...] [--size WxH] [--workers N]\n"
          "                         [--policy wait|skip] [--method M] [--view-distance M]\n"
          "                         [--max-screen-error PX]\n"
          "                         [--upload-budget BYTES] [--start-cell I,J] [--repeat P]\n"
          "                         [--seed N] [--out DIR] [--quiet]\n"
          "                         [--gl auto|egl|osmesa] [--gpu N]\n"
          "                         [--http-cache DIR] [--http-cache-bytes BYTES] [--http-timeout MS]\n"
          "\n"
          "Walks a long path through a tileset and records the tile cache's memory against\n"
          "the distance travelled: every --every metres a row of DIR/memory.csv (the cache's\n"
          "bytes, tiles, loads, evictions, reloads, load latency, holes, the process's RSS,\n"
          "the frame time), then DIR/summary.json, DIR/summary.md and charts (with gnuplot).\n"
          "Exit status 0 when every check held or was not applicable, 3 when one did not\n"
          "(cache bytes within the budget except where the view alone needs more, RSS flat\n"
          "in distance, no leak, load latency bounded), 2 for bad input, 1 for a failure.\n"
          "--tileset NAME|FILE.json  what the world shows (default city-gen): the providers\n"
          "                      city-gen and forest-gen, the built-in city, forest, hybrid,\n"
          "                      a manifest, or a baked tileset's http://.../tileset.json or\n"
          "                      file:///.../tileset.json\n"
          TW_CLI_HTTP_HELP
          "--path straight|wander|FILE.csv  the walk (default straight: along one street;\n"
          "                      wander turns at crossings, seeded by --seed; a CSV is\n"
          "                      repeated end to end)\n"
          "--distance KM         kilometres to walk, 0.001..10000 (default 5; about 2500\n"
          "                      frames, tens of minutes on a CPU: the progress line says)\n"
          "--every METRES        a row of memory.csv every METRES metres, 1..1000000\n"
          "                      (default 100)\n"
          "--budget BYTES        the tile cache's budget, CPU and GPU bytes, with an optional\n"
          "                      binary suffix K, M, G, T (64M = 64 MiB); 0: none (the default)\n"
          "--sweep budget=B1,B2,...  one run per budget into DIR/sweep-budget-VALUE/, and\n"
          "                      DIR/sweep.csv and chart-sweep-budget.png (not with --budget)\n"
          "--size WxH            image size, each side 16..8192 (default 320x180)\n"
          "--workers N           threads generating tiles, 1..64 (default: cores - 1)\n"
          "--policy wait|skip    a visible tile not ready: the frame waits for it (wait,\n"
          "                      default) or draws without it, a hole (skip)\n"
          "--method M            the culling method (default tilequery+chc)\n"
          "--view-distance M     metres, 1..100000 (default 600)\n"
          "--max-screen-error PX  levels of detail: each tile drawn at its coarsest level whose\n"
          "                      error projects to at most PX pixels, 0..1000; 0: full detail\n"
          "                      (default 1); kept on disk in TW_LEVELS_CACHE (environment;\n"
          "                      default ~/.cache/tileworld/levels; off: nowhere)\n"
          "--upload-budget BYTES per frame, bytes of finished tiles uploaded ahead of need\n"
          "                      (default 32M)\n"
          "--start-cell I,J      moves the whole path by that many cells (default 0,0)\n"
          "--repeat P            the cells' selection repeats every P cells (default: none)\n"
          "--seed N              seed of the generators, the selection and wander (default 1)\n"
          "--out DIR             output folder (default out-memtest)\n"
          "--quiet               no progress line and no summary lines\n",
          f);
    fputs(tw_gl_usage, f);
    fputs("Options take their value as --opt VALUE or --opt=VALUE; unique prefixes work;\n"
          "numbers are plain decimal digits.\n"
          "Limits: at most 10000000 frames (the distance over what the path moves a frame)\n"
          "and 1000000 rows of memory.csv, refused before the walk starts (exit status 2).\n"
          "Progress (stderr): on a terminal one line rewritten in place; otherwise a line\n"
          "every 10 s, or every TW_PROGRESS_INTERVAL_S seconds (environment; 0: every frame).\n",
          f);
}

enum {
    OPT_DISTANCE = TW_CLI_OPT_PROGRAM,
    OPT_EVERY,
    OPT_OUT,
    OPT_SWEEP,
};

static const struct option options_table[] = {
    TW_CLI_COMMON_OPTIONS,
    {"distance", required_argument, NULL, OPT_DISTANCE},
    {"every", required_argument, NULL, OPT_EVERY},
    {"out", required_argument, NULL, OPT_OUT},
    {"sweep", required_argument, NULL, OPT_SWEEP},
    TW_GL_OPTIONS,
    {NULL, 0, NULL, 0},
};

static void parse_sweep(const char *opt, const char *v, struct tw_memtest_options *o)
{
    if (strncmp(v, "budget=", 7) != 0)
        tw_cli_fail(program, opt, "'%s' is not of the form budget=B1,B2,... (memtest sweeps the "
                    "cache budget only)", v);
    const char *s = v + 7;
    o->sweep_count = 0;
    for (;;) {
        const char *end = strchr(s, ',');
        const size_t n = end ? (size_t)(end - s) : strlen(s);
        if (n == 0)
            tw_cli_fail(program, opt, "'%s' has an empty value", v);
        if (o->sweep_count == TW_MEMTEST_MAX_SWEEP)
            tw_cli_fail(program, opt, "more than %d values", TW_MEMTEST_MAX_SWEEP);
        if (n >= sizeof(o->sweep_text[0]))
            tw_cli_fail(program, opt, "'%.*s' is not a byte count", (int)n, s);
        char *text = o->sweep_text[o->sweep_count];
        memcpy(text, s, n);
        text[n] = '\0';
        o->sweep[o->sweep_count] = tw_cli_bytes(program, opt, text, (uint64_t)1 << 50);
        for (uint32_t k = 0; k < o->sweep_count; k++)
            if (o->sweep[k] == o->sweep[o->sweep_count])
                tw_cli_fail(program, opt, "the budget '%s' is listed twice", text);
        o->sweep_count++;
        if (!end)
            break;
        s = end + 1;
    }
}

static void apply_option(void *user, int opt, const char *name, const char *v)
{
    struct tw_memtest_options *o = user;
    if (tw_gl_option(&o->gl, opt, name, v))
        return;
    switch (opt) {
    case OPT_DISTANCE:
        /* Checked as a float, taken in double: 0.2 km is 200 m, not 200.000003. */
        tw_cli_float(program, name, v, 0.001f, 10000.0f);
        o->distance_m = 1000.0 * strtod(v, NULL);
        break;
    case OPT_EVERY:
        tw_cli_float(program, name, v, 1.0f, 1000000.0f);
        o->every_m = strtod(v, NULL);
        break;
    case OPT_OUT:
        if (*v == '\0')
            tw_cli_fail(program, name, "the output folder name is empty");
        o->out = v;
        break;
    case OPT_SWEEP: parse_sweep(name, v, o); break;
    default: tw_cli_fail(program, name, "unknown option '%s' (see tileworld memtest --help)", name);
    }
}

/* One run into dir: stale outputs removed, the walk, summaries, charts. The
 * progress line is finished after the last run's walk, cleared after the
 * others' (what a run prints goes on lines of its own). */
static int memtest_run(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                       struct tw_memtest_walk *walk, struct tw_context *ctx, const char *dir,
                       struct tw_memtest_result *r, const struct tw_memtest_progress *progress,
                       bool last, int *world_error, char *err, size_t err_size)
{
    int rc = tw_outputs_remove_stale(dir, err, err_size);
    if (rc)
        return rc;
    const int e = tw_report_make_dirs(dir);
    if (e) {
        snprintf(err, err_size, "%s: cannot create the output folder: %s", dir, strerror(e));
        return TW_ERR_INVALID;
    }
    rc = tw_memtest_walk_once(o, shown, walk, ctx, dir, r, progress, world_error, err, err_size);
    if (rc)
        return rc;
    if (last)
        tw_progress_finish(progress->line);
    else
        tw_progress_clear(progress->line);
    tw_memtest_judge(r);
    rc = tw_memtest_write_run_summary(o, shown, dir, r, err, err_size);
    if (!rc)
        rc = tw_memtest_draw_charts(o, shown, dir, r->budget, false, err, err_size);
    if (!rc && !o->cli.quiet)
        tw_memtest_print_checks(dir, r);
    return rc;
}

/* The command line into o: the defaults, the options, the rules between them. */
static void parse_options(int argc, char **argv, struct tw_memtest_options *o)
{
    memset(o, 0, sizeof(*o));
    tw_cli_init(&o->cli, program);
    o->cli.tileset = "city-gen";
    o->cli.world.width = 320;
    o->cli.world.height = 180;
    o->distance_m = 5000.0;
    o->every_m = 100.0;
    o->out = "out-memtest";
    tw_cli_parse(&o->cli, argc, argv, options_table, apply_option, o, usage);
    if (!o->cli.path)
        o->cli.path = "straight";
    if (tw_cli_given(&o->cli, TW_CLI_OPT_FRAMES))
        tw_cli_fail(program, "--frames", "memtest walks a distance: give --distance KM");
    if (o->sweep_count && tw_cli_given(&o->cli, TW_CLI_OPT_BUDGET))
        tw_cli_fail(program, "--sweep", "--sweep budget=... and --budget are two kinds of run; "
                    "give one");
}

/* The sweep's folder o->out, emptied of a former run's outputs. */
static int prepare_sweep_dir(const struct tw_memtest_options *o, char *msg, size_t msg_size)
{
    int err = tw_outputs_remove_stale(o->out, msg, msg_size);
    const int e = err ? 0 : tw_report_make_dirs(o->out);
    if (e) {
        snprintf(msg, msg_size, "%s: cannot create the output folder: %s", o->out, strerror(e));
        err = TW_ERR_INVALID;
    }
    return err;
}

/* Run k of runs: its budget (and the budget's text), its folder dir (size
 * bytes) and what the progress line says of it. */
static void name_run(const struct tw_memtest_options *o, uint32_t k, uint32_t runs,
                     struct tw_memtest_result *r, char *dir, size_t size,
                     struct tw_memtest_progress *progress)
{
    if (o->sweep_count) {
        r->budget = o->sweep[k];
        snprintf(r->budget_text, sizeof(r->budget_text), "%s", o->sweep_text[k]);
        snprintf(dir, size, "%s/sweep-budget-%s", o->out, o->sweep_text[k]);
        snprintf(progress->what, sizeof(progress->what), "budget %s, run %u of %u; ",
                 o->sweep_text[k], k + 1, runs);
    } else {
        r->budget = o->cli.world.cache_budget_bytes;
        if (r->budget && r->budget % (1u << 20) == 0)
            snprintf(r->budget_text, sizeof(r->budget_text), "%lluM",
                     (unsigned long long)(r->budget >> 20));
        else
            snprintf(r->budget_text, sizeof(r->budget_text), "%llu",
                     (unsigned long long)r->budget);
        snprintf(dir, size, "%s", o->out);
    }
}

/* The runs, then the sweep's table and chart. Returns 0 or an error with a
 * line in msg; *world_error as tw_memtest_walk_once's. */
static int run_all(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                   struct tw_memtest_walk *walk, struct tw_context *ctx,
                   struct tw_memtest_result *results, uint32_t runs, struct tw_progress *line,
                   int *world_error, char *msg, size_t msg_size)
{
    int err = o->sweep_count ? prepare_sweep_dir(o, msg, msg_size) : TW_OK;
    tw_progress_init(line, o->out, o->distance_m * runs, "m", 0, o->cli.quiet);
    for (uint32_t k = 0; k < runs && !err; k++) {
        struct tw_memtest_result *r = &results[k];
        struct tw_memtest_progress progress = {line, o->distance_m * k, ""};
        char dir[1000];
        name_run(o, k, runs, r, dir, sizeof(dir), &progress);
        err = memtest_run(o, shown, walk, ctx, dir, r, &progress, k + 1 == runs, world_error,
                          msg, msg_size);
    }
    if (!err && o->sweep_count) {
        err = tw_memtest_write_sweep(o, shown, results, runs, msg, msg_size);
        if (!err)
            err = tw_memtest_draw_charts(o, shown, o->out, 0, true, msg, msg_size);
    }
    return err;
}

/* The exit status of a failure err, said in msg. */
static int failure_status(const struct tw_memtest_options *o, int err, int world_error,
                          const char *msg)
{
    /* A world refused for the user's settings has said why in one line. */
    if (world_error) {
        if (o->cli.errors_logged == 0)
            tw_cli_message(program, "%s", msg);
        return tw_cli_world_exit_status(world_error);
    }
    tw_cli_message(program, "%s", msg);
    return err == TW_ERR_INVALID ? TW_CLI_EXIT_USAGE : 1;
}

int tw_memtest_main(int argc, char **argv)
{
    struct tw_memtest_options o;
    parse_options(argc, argv, &o);
    const struct tw_log log = {tw_cli_log, &o.cli};
    struct tw_cli_world shown;
    tw_cli_world_load(&o.cli, 0, &log, &shown);
    struct tw_memtest_walk walk;
    tw_memtest_walk_init(&o, &shown, &walk);

    const uint32_t runs = o.sweep_count ? o.sweep_count : 1;
    struct tw_progress line;
    memset(&line, 0, sizeof(line));
    struct tw_memtest_result *results = calloc(runs, sizeof(*results));
    struct tw_context *ctx = NULL;
    char msg[1400];
    int status = 1, world_error = 0;
    int err = results ? tw_gl_context_create(&o.gl, o.cli.world.width, o.cli.world.height, &log,
                                             &ctx)
                      : TW_ERR_NOMEM;
    if (err) {
        if (err == TW_ERR_NOMEM)
            tw_cli_message(program, "out of memory");
        goto out;
    }
    err = run_all(&o, &shown, &walk, ctx, results, runs, &line, &world_error, msg, sizeof(msg));
    if (err) {
        tw_progress_finish(&line);
        status = failure_status(&o, err, world_error, msg);
        goto out;
    }
    bool all = true;
    for (uint32_t k = 0; k < runs; k++)
        all &= results[k].all_held;
    if (!o.cli.quiet) {
        char verdict[1000];
        tw_memtest_verdict_text(results, runs, verdict, sizeof(verdict));
        tw_cli_message(program, "wrote %s/summary.md: %s", o.out, verdict);
        tw_cli_world_tiles3d_line(program, &shown);
    }
    status = all ? 0 : 3;
out:
    tw_context_destroy(ctx);
    for (uint32_t k = 0; results && k < runs; k++)
        free(results[k].rss_km);
    free(results);
    tw_path_finish(&walk.path);
    tw_cli_world_finish(&shown);
    return status;
}
