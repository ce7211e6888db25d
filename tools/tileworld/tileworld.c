/*
 * The tileworld command (DESIGN.md §9): a thin client of runtime.h.
 *   tileworld walk | bench | info   [options]
 * Bad input: exit status 2 and one line on stderr naming the place and the
 * reason. Runtime failures: exit status 1.
 */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tools/tileworld/bench.h"
#include "tools/cli.h"
#include "tools/tileworld/report.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

#define EXIT_USAGE TW_CLI_EXIT_USAGE

static const char program[] = "tileworld";

struct options {
    const char *command;
    const char *tileset;
    const char *path;
    const char *out;
    uint64_t seed;
    uint32_t frames;        /* 0: the path's length */
    uint32_t width, height;
    enum tw_method method;
    bool methods_given;
    enum tw_method methods[TW_METHOD_COUNT];
    uint32_t method_count;
    struct tw_cell start_cell;
    int64_t repeat;
    bool verify;
    uint32_t png_every;
    float view_distance;
    uint32_t cluster_triangles;
    bool quiet;
    const char *sweep;
    const char *scenario;
    uint32_t neighbours;
    uint32_t evict_after;
    uint32_t chc_batch;
    uint32_t chc_nav;
    uint32_t threshold;
    bool threshold_given;
};

static const uint32_t default_frames = 300;

static void usage(FILE *f)
{
    fputs("usage: tileworld walk   [--tileset NAME|FILE.json] [--seed N] [--path NAME|FILE.csv]\n"
          "                        [--frames N] [--method M] [--size WxH] [--start-cell I,J]\n"
          "                        [--repeat P] [--verify] [--png-every N] [--out DIR] [--quiet]\n"
          "                        [--view-distance M] [--cluster-triangles N] [--tile-neighbours 4|8]\n"
          "                        [--evict-after N] [--chc-batch N] [--chc-nav N] [--threshold T]\n"
          "       tileworld bench  [same options] [--methods M1,M2,...] [--sweep PARAM=v1,v2,...]\n"
          "                        [--scenario NAME|all]\n"
          "       tileworld info   [--tileset NAME|FILE.json] [--seed N] [--cluster-triangles N]\n"
          "       tileworld import FILE.gltf|FILE.glb\n"
          "tilesets: city, forest, hybrid, or a manifest; paths: street, flyover, forest, teleport,\n"
          "spin, or a CSV file; methods: vfc, tilequery, chc, tilequery+chc (default), oracle\n"
          "sweep parameters: n_av, b, T, cluster_triangles, evict_after, view_distance, neighbours\n"
          "scenarios: teleport, spin, inside-building, inside-common-box, grazing, far-origin,\n"
          "no-occluders, all\n",
          f);
}

/* One line on stderr, then exit: bad input is the user's, so no stack of
 * messages and never a crash. */
static enum tw_method parse_method(const char *opt, const char *s)
{
    enum tw_method m;
    if (tw_method_from_name(s, &m) != TW_OK)
        tw_cli_fail(program, opt, "unknown method '%s' (vfc, tilequery, chc, tilequery+chc, oracle)", s);
    if (!tw_method_available(m))
        tw_cli_fail(program, opt, "method '%s' is not implemented in this build yet", s);
    return m;
}

static void parse_methods(const char *opt, const char *s, struct options *o)
{
    char buf[256];
    if (!s || strlen(s) >= sizeof(buf) || *s == '\0')
        tw_cli_fail(program, opt, "'%s' is not a comma-separated list of methods", s ? s : "");
    strcpy(buf, s);
    o->method_count = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        enum tw_method m = parse_method(opt, tok);
        for (uint32_t k = 0; k < o->method_count; k++)
            if (o->methods[k] == m)
                tw_cli_fail(program, opt, "method '%s' is listed twice", tok);
        o->methods[o->method_count++] = m;
    }
    if (o->method_count == 0)
        tw_cli_fail(program, opt, "'%s' names no method", s);
    o->methods_given = true;
}

static void parse_options(int argc, char **argv, struct options *o)
{
    memset(o, 0, sizeof(*o));
    o->tileset = "city";
    o->path = "street";
    o->out = "out";
    o->seed = 1;
    o->width = 640;
    o->height = 360;
    o->method = TW_METHOD_TILEQUERY_CHC;
    o->png_every = 50;
    o->view_distance = 600.0f;
    o->command = argv[1];
    for (int k = 2; k < argc; k++) {
        const char *a = argv[k];
        const char *v = k + 1 < argc ? argv[k + 1] : NULL;
        bool takes = true;
        if (strcmp(a, "--verify") == 0) {
            o->verify = true;
            takes = false;
        } else if (strcmp(a, "--quiet") == 0) {
            o->quiet = true;
            takes = false;
        } else if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(stdout);
            exit(0);
        } else if (strncmp(a, "--", 2) != 0) {
            tw_cli_fail(program, a, "unexpected argument '%s'", a);
        } else if (!v) {
            tw_cli_fail(program, a, "%s needs a value", a);
        } else if (strcmp(a, "--tileset") == 0) {
            o->tileset = v;
        } else if (strcmp(a, "--seed") == 0) {
            o->seed = tw_cli_u64(program, a, v, 0, UINT64_MAX);
        } else if (strcmp(a, "--path") == 0) {
            o->path = v;
        } else if (strcmp(a, "--frames") == 0) {
            o->frames = (uint32_t)tw_cli_u64(program, a, v, 1, 10000000);
        } else if (strcmp(a, "--method") == 0) {
            o->method = parse_method(a, v);
        } else if (strcmp(a, "--methods") == 0) {
            parse_methods(a, v, o);
        } else if (strcmp(a, "--size") == 0) {
            tw_cli_size(program, a, v, &o->width, &o->height);
        } else if (strcmp(a, "--start-cell") == 0) {
            tw_cli_cell(program, a, v, &o->start_cell);
        } else if (strcmp(a, "--repeat") == 0) {
            o->repeat = (int64_t)tw_cli_u64(program, a, v, 1, (uint64_t)1 << 62);
        } else if (strcmp(a, "--png-every") == 0) {
            o->png_every = (uint32_t)tw_cli_u64(program, a, v, 0, 10000000);
        } else if (strcmp(a, "--view-distance") == 0) {
            o->view_distance = tw_cli_float(program, a, v, 1.0f, 100000.0f);
        } else if (strcmp(a, "--cluster-triangles") == 0) {
            o->cluster_triangles = (uint32_t)tw_cli_u64(program, a, v, 16, 1000000);
        } else if (strcmp(a, "--sweep") == 0) {
            char why[300];
            if (tw_run_sweep_check(v, why, sizeof(why)))
                tw_cli_fail(program, a, "%s", why + strlen("--sweep: "));
            o->sweep = v;
        } else if (strcmp(a, "--scenario") == 0) {
            bool known = strcmp(v, "all") == 0;
            for (const char *const *n = tw_scenario_names; *n; n++)
                known |= strcmp(*n, v) == 0;
            if (!known)
                tw_cli_fail(program, a, "unknown scenario '%s' (all, teleport, spin, inside-building, "
                              "inside-common-box, grazing, far-origin, no-occluders)", v);
            o->scenario = v;
        } else if (strcmp(a, "--tile-neighbours") == 0) {
            o->neighbours = (uint32_t)tw_cli_u64(program, a, v, 4, 8);
            if (o->neighbours != 4 && o->neighbours != 8)
                tw_cli_fail(program, a, "'%s' is neither 4 nor 8", v);
        } else if (strcmp(a, "--evict-after") == 0) {
            o->evict_after = (uint32_t)tw_cli_u64(program, a, v, 1, 1000000);
        } else if (strcmp(a, "--chc-batch") == 0) {
            o->chc_batch = (uint32_t)tw_cli_u64(program, a, v, 1, 100000);
        } else if (strcmp(a, "--chc-nav") == 0) {
            o->chc_nav = (uint32_t)tw_cli_u64(program, a, v, 1, 1000);
        } else if (strcmp(a, "--threshold") == 0) {
            o->threshold = (uint32_t)tw_cli_u64(program, a, v, 0, 1000000);
            o->threshold_given = true;
        } else if (strcmp(a, "--out") == 0) {
            if (*v == '\0')
                tw_cli_fail(program, a, "%sthe output folder name is empty", "");
            o->out = v;
        } else {
            tw_cli_fail(program, a, "unknown option '%s' (see tileworld --help)", a);
        }
        if (takes)
            k++;
    }
}

static void log_to_stderr(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    if (level <= TW_LOG_WARN)
        fprintf(stderr, "tileworld: %s\n", msg);
}

static struct tw_tileset *load_tileset(const struct options *o, const struct tw_log *log)
{
    for (const char *const *n = tw_tilesets_builtin_names; *n; n++) {
        if (strcmp(*n, o->tileset) == 0) {
            struct tw_tileset *ts = NULL;
            int err = tw_tilesets_builtin(o->tileset, o->seed, o->cluster_triangles, log, &ts);
            if (err) {
                fprintf(stderr, "tileworld: --tileset %s: generation failed: %s\n", o->tileset,
                        tw_error_to_str(err));
                exit(1);
            }
            return ts;
        }
    }
    if (access(o->tileset, F_OK) != 0)
        tw_cli_fail(program, "--tileset", "unknown tileset '%s' (built-in: city, forest, hybrid; or a "
                                "manifest file)", o->tileset);
    /* A manifest: its loader logs one line naming the file, the place and the reason. */
    const struct tw_manifest_settings ms = {.max_cluster_triangles = o->cluster_triangles};
    struct tw_tileset *ts = NULL;
    const int err = tw_tilesets_load_manifest_ex(o->tileset, &ms, log, &ts);
    if (err)
        exit(err == TW_ERR_NOMEM ? 1 : EXIT_USAGE);
    return ts;
}

/* tileworld import FILE: validate one glTF file and summarise it. */
static int import(int argc, char **argv)
{
    if (argc != 3 || argv[2][0] == '-') {
        fprintf(stderr, "tileworld: import: expected one file: tileworld import FILE.gltf|FILE.glb\n");
        return EXIT_USAGE;
    }
    const struct tw_log log = {log_to_stderr, NULL};
    struct tw_gltf_scene *scene = NULL;
    const int err = tw_gltf_import(argv[2], NULL, &log, &scene);
    if (err)
        return err == TW_ERR_NOMEM ? 1 : EXIT_USAGE;
    tw_gltf_print_summary(scene, stdout);
    tw_gltf_scene_destroy(scene);
    return 0;
}

static void load_path(const struct options *o, const struct tw_tileset *ts, struct tw_path *p)
{
    const float w = ts->footprint[0], d = ts->footprint[1];
    int err;
    for (const char *const *n = tw_path_builtin_names; *n; n++) {
        if (strcmp(*n, o->path) == 0) {
            err = tw_path_builtin(o->path, o->seed, o->frames ? o->frames : default_frames, w, d, p);
            if (err) {
                fprintf(stderr, "tileworld: --path %s: %s\n", o->path, tw_error_to_str(err));
                exit(1);
            }
            goto translate;
        }
    }
    char msg[1400];
    err = tw_path_load_csv(o->path, o->frames, w, d, p, msg, sizeof(msg));
    if (err) {
        if (err == TW_ERR_IO && access(o->path, F_OK) != 0 && !strchr(o->path, '/') &&
            !strstr(o->path, ".csv"))
            tw_cli_fail(program, "--path", "unknown path '%s' (built-in: street, flyover; or a CSV file)",
                       o->path);
        fprintf(stderr, "tileworld: %s\n", msg);
        exit(EXIT_USAGE);
    }
translate:
    if (tw_path_translate(p, o->start_cell.i, o->start_cell.j)) {
        fprintf(stderr, "tileworld: --start-cell: the translated path overflows the grid\n");
        exit(EXIT_USAGE);
    }
}

struct maker {
    const struct options *o;
    const struct tw_log *log;
};

/* The same tileset again with another cluster size (for --sweep). */
static struct tw_tileset *remake_tileset(void *user, uint32_t cluster_triangles, char *err,
                                         size_t err_size)
{
    const struct maker *mk = user;
    struct tw_tileset *ts = NULL;
    const int rc = tw_tilesets_builtin(mk->o->tileset, mk->o->seed, cluster_triangles, mk->log, &ts);
    if (rc)
        snprintf(err, err_size, "--sweep: cluster_triangles needs a built-in tileset (%s)",
                 tw_error_to_str(rc));
    return rc ? NULL : ts;
}

static int run(const struct options *o, bool bench)
{
    const struct tw_log log = {log_to_stderr, NULL};
    struct tw_tileset *ts = load_tileset(o, &log);
    struct tw_path path = {0};
    if (!o->scenario)
        load_path(o, ts, &path);

    struct tw_run r = {0};
    r.tileset = ts;
    r.tileset_name = o->tileset;
    r.path = &path;
    r.path_name = o->path;
    r.out = o->out;
    r.png_every = o->png_every;
    r.bench = bench;
    r.quiet = o->quiet;
    if (!bench) {
        r.methods[0] = o->method;
        r.method_count = 1;
    } else if (o->methods_given) {
        memcpy(r.methods, o->methods, sizeof(r.methods));
        r.method_count = o->method_count;
    } else {
        for (int m = TW_METHOD_FIRST; m < TW_METHOD_COUNT; m++)
            r.methods[r.method_count++] = (enum tw_method)m;
    }
    struct tw_world_settings *ws = &r.world;
    ws->selection.seed = o->seed;
    ws->selection.repeat = o->repeat;
    ws->width = o->width;
    ws->height = o->height;
    ws->view_distance = o->view_distance;
    ws->verify = o->verify;
    ws->log = log;
    ws->tilequery.neighbours = o->neighbours;
    ws->evict_after_frames = o->evict_after;
    ws->chc.batch_size = o->chc_batch;
    ws->chc.assumed_visible = o->chc_nav;
    if (o->threshold_given) {
        ws->chc.threshold = o->threshold;
        ws->tilequery.threshold = o->threshold;
    }

    int rc = 1;
    char msg[1400];
    struct tw_context *ctx = NULL;
    int err = tw_context_create_headless(o->width, o->height, &log, &ctx);
    if (err) {
        fprintf(stderr, "tileworld: cannot create the headless OpenGL context: %s\n",
                tw_error_to_str(err));
        goto out;
    }
    if (o->scenario) {
        bool held = false;
        err = tw_run_scenarios(&r, ctx, o->scenario, &held, msg, sizeof(msg));
        if (!err && !o->quiet)
            fprintf(stderr, "tileworld: wrote %s/scenarios.md: %s\n", o->out,
                    held ? "everything that must hold held" : "SOME CHECKS DID NOT HOLD");
        if (!err && !held)
            rc = 3;
    } else if (o->sweep) {
        struct maker mk = {o, &log};
        err = tw_run_sweep(&r, ctx, o->sweep, remake_tileset, &mk, msg, sizeof(msg));
    } else {
        err = tw_run_execute(&r, ctx, msg, sizeof(msg));
    }
    if (err) {
        fprintf(stderr, "tileworld: %s\n", msg);
        rc = err == TW_ERR_IO ? EXIT_USAGE : 1;
        goto out;
    }
    if (rc == 3)
        goto out;
    if (!o->quiet && !o->scenario)
        fprintf(stderr, "tileworld: wrote %s/frames.csv and %s/summary.json\n", o->out, o->out);
    rc = 0;
out:
    tw_context_destroy(ctx);
    tw_path_finish(&path);
    tw_tileset_destroy(ts);
    return rc;
}

static int info(const struct options *o)
{
    const struct tw_log log = {log_to_stderr, NULL};
    struct tw_tileset *ts = load_tileset(o, &log);
    struct tw_bvh_builder *b = NULL;
    int err = tw_bvh_builder_create(&log, &b);
    if (err) {
        tw_tileset_destroy(ts);
        fprintf(stderr, "tileworld: cannot start Embree: %s\n", tw_error_to_str(err));
        return 1;
    }
    printf("tileset %s: %u prototypes, footprint %g x %g m, clusters of <= %u triangles\n",
           ts->name, ts->prototype_count, ts->footprint[0], ts->footprint[1],
           ts->max_cluster_triangles);
    printf("%-16s %10s %9s %9s %6s %6s %9s %10s\n", "tile", "triangles", "instances", "clusters",
           "nodes", "depth", "build_ms", "bvh_bytes");
    uint64_t clusters = 0, triangles = 0;
    double build_ms = 0.0;
    for (uint32_t p = 0; p < ts->prototype_count && !err; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        struct tw_bvh *bvh = NULL;
        err = tw_bvh_build(b, proto, NULL, &bvh);
        if (err)
            break;
        printf("%-16s %10llu %9u %9u %6u %6u %9.3f %10llu\n", proto->name,
               (unsigned long long)proto->triangle_count, proto->instance_count,
               proto->cluster_count, bvh->node_count, bvh->depth, bvh->build_ms,
               (unsigned long long)bvh->bytes);
        clusters += proto->cluster_count;
        triangles += proto->triangle_count;
        build_ms += bvh->build_ms;
        tw_bvh_destroy(bvh);
    }
    tw_bvh_builder_destroy(b);
    if (err) {
        fprintf(stderr, "tileworld: BVH build failed: %s\n", tw_error_to_str(err));
        tw_tileset_destroy(ts);
        return 1;
    }
    const struct tw_box *cb = &ts->common_box;
    printf("total: %llu triangles, %llu clusters, BVH build %.3f ms (%.0f clusters/s)\n",
           (unsigned long long)triangles, (unsigned long long)clusters, build_ms,
           build_ms > 0.0 ? clusters / (build_ms / 1000.0) : 0.0);
    printf("common box: [%.2f, %.2f, %.2f] .. [%.2f, %.2f, %.2f]\n", cb->min[0], cb->min[1],
           cb->min[2], cb->max[0], cb->max[1], cb->max[2]);
    printf("geometry: %llu bytes uploaded once\n",
           (unsigned long long)tw_tileset_geometry_bytes(ts));
    tw_tileset_destroy(ts);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "tileworld: no command given (walk, bench, info, view, import; "
                        "tileworld --help for the options)\n");
        return EXIT_USAGE;
    }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0 ||
        strcmp(argv[1], "help") == 0) {
        usage(stdout);
        return 0;
    }
    struct options o;
    if (strcmp(argv[1], "walk") == 0 || strcmp(argv[1], "bench") == 0 ||
        strcmp(argv[1], "info") == 0) {
        parse_options(argc, argv, &o);
    } else if (strcmp(argv[1], "import") == 0) {
        return import(argc, argv);
    } else if (strcmp(argv[1], "view") == 0) {
        /* The window is tileworld-view, beside this program and built only
         * with GLFW: a process of its own that links libGL, never libOSMesa. */
        char viewer[PATH_MAX];
        ssize_t n = readlink("/proc/self/exe", viewer, sizeof(viewer) - sizeof("tileworld-view"));
        char *slash = n > 0 ? memchr(viewer, '/', (size_t)n) : NULL;
        if (slash) {
            viewer[n] = '\0';
            strcpy(strrchr(viewer, '/') + 1, "tileworld-view");
        }
        if (!slash || access(viewer, X_OK) != 0) {
            fprintf(stderr, "tileworld: view: this build has no viewer (no tileworld-view beside "
                            "tileworld: GLFW was not found when it was built)\n");
            return EXIT_USAGE;
        }
        argv[1] = viewer;
        execv(viewer, argv + 1);
        fprintf(stderr, "tileworld: view: cannot run %s: %s\n", viewer, strerror(errno));
        return 1;
    } else {
        fprintf(stderr, "tileworld: unknown command '%s' (walk, bench, info, view, import)\n",
                argv[1]);
        return EXIT_USAGE;
    }
    if (strcmp(o.command, "info") == 0)
        return info(&o);
    if (strcmp(o.command, "walk") == 0) {
        if (o.methods_given)
            tw_cli_fail(program, "--methods", "%s belongs to bench; walk takes --method", "--methods");
        if (o.sweep)
            tw_cli_fail(program, "--sweep", "%s belongs to bench", "--sweep");
        if (o.scenario)
            tw_cli_fail(program, "--scenario", "%s belongs to bench", "--scenario");
    }
    return run(&o, strcmp(o.command, "bench") == 0);
}
