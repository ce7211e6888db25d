/*
 * The tileworld command (DESIGN.md §9): a thin client of runtime.h.
 *   tileworld walk | bench | info   [options]
 * Bad input: exit status 2 and one line on stderr naming the place and the
 * reason. Runtime failures: exit status 1. A check that did not hold (a
 * scenario's, or a conservative method's missed pixels under --verify
 * without --allow-missed): exit status 3. walk and bench end with their
 * verdict on stdout (report.h).
 */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tiles/clock.h"
#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"
#include "tools/tileworld/bake.h"
#include "tools/tileworld/bench.h"
#include "tools/tileworld/buildinfo.h"
#include "tools/tileworld/glcontext.h"
#include "tools/cli.h"
#include "tools/tileworld/memtest.h"
#include "tools/tileworld/report.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

#define EXIT_USAGE TW_CLI_EXIT_USAGE

static const char program[] = "tileworld";

struct options {
    struct tw_cli cli;          /* tileset, path, frames, quiet and the world's settings */
    const char *command;
    const char *out;
    bool methods_given;
    enum tw_method methods[TW_METHOD_ALL];
    uint32_t method_count;
    uint32_t png_every;
    uint32_t fps;               /* --fps; 0: not paced */
    uint32_t views;             /* --views */
    uint32_t cars;              /* --cars */
    bool cars_given;
    uint32_t cluster_triangles;
    const char *sweep;
    const char *scenario;
    bool calibrate;             /* info --calibrate */
    bool split;                 /* bench --split */
    bool allow_missed;          /* --allow-missed */
    struct tw_context_settings gl; /* --gl, --gpu */
};

static const uint32_t default_frames = 300;

/* Each command's synopsis: the first paragraph of its --help, and the
 * README's "Commands" block, word for word. */
static const char walk_synopsis[] =
    "usage: tileworld walk   [--tileset NAME|FILE.json] [--seed N] [--path NAME|FILE.csv] [--frames N]\n"
    "                        [--method M] [--size WxH] [--start-cell I,J] [--repeat P] [--view-distance M]\n"
    "                        [--max-screen-error PX] [--hlod-levels N] [--views N] [--cars N]\n"
    "                        [--verify] [--verify-tolerance X] [--allow-missed] [--deterministic]\n"
    "                        [--png-every N] [--out DIR] [--quiet] [--cluster-triangles N]\n"
    "                        [--tile-neighbours 4|8] [--evict-after N] [--chc-batch N] [--chc-nav N]\n"
    "                        [--chc-suspend N] [--threshold T] [--no-cost-model] [--first-sight-draws]\n"
    "                        [--hzb-pyramid auto|gpu|cpu] [--mutate-query-shrink F] [--workers N]\n"
    "                        [--policy wait|skip] [--fps N]\n"
    "                        [--budget BYTES] [--upload-budget BYTES] [--gl auto|egl|osmesa] [--gpu N]\n"
    "                        [--http-cache DIR] [--http-cache-bytes BYTES] [--http-timeout MS]\n";
static const char bench_synopsis[] =
    "usage: tileworld bench  [walk's options] [--methods M1,M2,...] [--sweep PARAM=v1,v2,...]\n"
    "                        [--scenario NAME|all] [--split]\n";
static const char info_synopsis[] =
    "usage: tileworld info   [--tileset NAME|FILE.json] [--seed N] [--cluster-triangles N]\n"
    "                        [--max-screen-error PX] [--hlod-levels N]\n"
    "                        [--calibrate [--size WxH]] [--gl auto|egl|osmesa] [--gpu N]\n"
    "                        [--http-cache DIR] [--http-cache-bytes BYTES] [--http-timeout MS]\n";
static const char import_synopsis[] =
    "usage: tileworld import FILE.gltf|FILE.glb\n";
static const char other_synopses[] =
    "       tileworld memtest [options of tileworld memtest --help]\n"
    "                        (the tile cache's memory against distance travelled)\n"
    "       tileworld view   [options of tileworld view --help] (the windowed viewer)\n"
    "       tileworld bake   [options of tileworld bake --help]\n"
    "                        (cells written as a 3D Tiles tileset, for any 3D Tiles client)\n";

static const char world_help[] =
    "What the world shows:\n"
    "--tileset NAME|FILE.json  built-in city (default), forest, hybrid; the providers city-gen\n"
    "                      and forest-gen (every cell generated on demand); a manifest; or\n"
    "                      http://.../tileset.json, file:///.../tileset.json: a tileset\n"
    "                      baked by tileworld bake, streamed back\n"
    "--seed N              seed of the generators and of the cells' selection (default 1)\n"
    "--repeat P            the selection repeats every P cells\n"
    "--cluster-triangles N draw clusters of at most N triangles, 16..1000000 (default 2048)\n"
    TW_CLI_HTTP_HELP;

static const char run_help[] =
    "Camera, image and methods:\n"
    "--path NAME|FILE.csv  built-in street (default), flyover, forest, teleport, spin, straight,\n"
    "                      wander, or a CSV file with the header cell_i,cell_j,x,y,z,yaw,pitch\n"
    "--frames N            frames to render, 1..10000000 (default 300; a CSV: all its rows)\n"
    "--start-cell I,J      moves the whole path by that many cells\n"
    "--size WxH            image size, each side 16..8192 (default 640x360)\n"
    "--view-distance M     metres, 1..100000 (default 600)\n"
    "--max-screen-error PX  levels of detail: each tile drawn at its coarsest level whose\n"
    "                      error projects to at most PX pixels, 0..1000; 0: full detail\n"
    "                      (default 1); kept on disk in TW_LEVELS_CACHE (environment;\n"
    "                      default ~/.cache/tileworld/levels; off: nowhere)\n"
    "--hlod-levels N       hierarchical cells, experimental: far away, blocks of 2x2, 4x4, ...\n"
    "                      up to 2^(N-1) cells each drawn as one merged proxy, made on the\n"
    "                      workers, where the block projects to at most 16 pixels across;\n"
    "                      1..12, 1: cells only; needs a tileset the library selects (not\n"
    "                      city-gen, forest-gen) and levels of detail. A baked tileset with\n"
    "                      coarser levels (bake --levels) draws its own blocks where their\n"
    "                      error projects to at most --max-screen-error pixels, up to N.\n"
    "                      Default: a baked tileset's own levels, else 1\n"
    "--views N             cameras on one world, 1..2 (default 1); 2: after every frame a\n"
    "                      chase camera 25 m behind and 12 m above the path's draws as a\n"
    "                      viewport of the same world (same method; not in frames.csv; its\n"
    "                      tiles and culling state are in the memory figures)\n"
    "--cars N              moving cars, 0..100000 (default 0): N cars in two lanes of every\n"
    "                      street within the view distance of the path's first cell, moved\n"
    "                      before every frame to where they are at frame / 30 s; tilesets\n"
    "                      with the city's streets (city, hybrid, city-gen)\n"
    "--method M            vfc, tilequery, chc, tilequery+chc (default), oracle, hzb,\n"
    "                      tilequery+hzb, box-oracle\n"
    "--tile-neighbours 4|8 the grid neighbours tile propagation visits (default 4)\n"
    "--evict-after N       frames a tile may stay unseen before it leaves the cache (default 60)\n"
    "--chc-batch N         CHC++ multiquery batch (default 50)\n"
    "--chc-nav N           frames a visible node is assumed visible (default 8)\n"
    "--chc-suspend N       tilequery+chc flushes and waits tile by tile, N CHC++ passes\n"
    "                      suspended at once, 1..4 (1: a tile's pass ends before the next\n"
    "                      starts); default: one flush per wavefront of the propagation,\n"
    "                      passes suspended until it\n"
    "--threshold T         a node is visible when more than T samples pass (default 0;\n"
    "                      T > 0 is approximate, not conservative)\n"
    "--no-cost-model       CHC++ counts every query as one unit, as the paper does, and\n"
    "                      ignores the measured costs (what the cost model buys)\n"
    "--first-sight-draws   CHC++ draws a new tile's leaves in view before it queries them,\n"
    "                      as the paper does (default: queried first, one round trip)\n"
    "--hzb-pyramid auto|gpu|cpu  where hzb and tilequery+hzb build and test the depth\n"
    "                      pyramid: gpu (compute passes, indirect draws, answers read back\n"
    "                      a frame later; needs GL 4.3), cpu (the depth read back each\n"
    "                      frame), auto (default): gpu on a GPU, cpu on a software renderer\n"
    "Accuracy:\n"
    "--verify              the oracle's ID pass after every frame (untimed): missed pixels,\n"
    "                      depth errors and overdraw; a conservative method that misses a\n"
    "                      pixel makes the exit status 3\n"
    "--verify-tolerance X  relative eye-distance difference that --verify counts as a real\n"
    "                      one, 0 < X < 1 (default 0.00001)\n"
    "--allow-missed        under --verify, missed pixels of a conservative method are\n"
    "                      reported (loudly) but the exit status stays 0\n"
    "--deterministic       no query result is ready before it is waited on: counts do not\n"
    "                      depend on GPU timing (slower; not for timings)\n"
    "--mutate-query-shrink F  testing only: every query box shrunk by F of its size,\n"
    "                      0 <= F < 1, a broken culler that --verify must catch\n"
    "Outputs:\n"
    "--out DIR             output folder, made if missing (default out)\n"
    "--png-every N         a PNG every N frames, 0 for none (default 50)\n"
    "--quiet               no progress and no 'wrote' line on stderr; the verdict (what ran,\n"
    "                      how fast, how accurate) still ends the run on stdout\n"
    "Providers and streaming:\n"
    "--workers N           threads generating a provider's tiles, 1..64 (default: cores - 1)\n"
    "--policy wait|skip    a visible tile not ready: the frame waits for it (wait, default)\n"
    "                      or draws without it, a hole counted in tiles_pending (skip)\n"
    "--fps N               frames paced to at most N a second, 1..10000, as a real-time\n"
    "                      walk shows them (with --policy skip: what streams in while it\n"
    "                      walks); default: each frame as soon as the last is done\n"
    "--budget BYTES        the tile cache's budget, every byte a tile costs, CPU and GPU;\n"
    "                      a number with an optional binary suffix K, M, G or T (also KiB,\n"
    "                      MiB, GiB, TiB; 64M = 64 MiB); 0: none (the default)\n"
    "--upload-budget BYTES per frame, bytes of finished tiles uploaded ahead of need\n"
    "                      (default 32M)\n";

static const char bench_help[] =
    "bench:\n"
    "--methods M1,M2,...   the methods run side by side, frame by frame (default: all)\n"
    "--sweep PARAM=v1,v2,...  one setting varied: n_av, b, T, cluster_triangles, evict_after,\n"
    "                      view_distance, neighbours, max_screen_error, cars\n"
    "                      (cluster_triangles: a prototype tileset; cars: as --cars)\n"
    "--scenario NAME|all   the stability suite: teleport, spin, inside-building,\n"
    "                      inside-common-box, grazing, far-origin, no-occluders, all; each\n"
    "                      runs its own path (no --path, --start-cell, --repeat, --sweep) for\n"
    "                      --frames N frames (default: its own number) at --size, under\n"
    "                      --verify, with a prototype tileset; exit 3 when a check does not hold\n"
    "--split               after every frame, its set of clusters drawn again from its camera\n"
    "                      with no culling, timed apart: frames.csv's set_* columns and\n"
    "                      summary.md's split of each method's CPU time into drawing what it\n"
    "                      drew and the rest, where the two can be told apart (not with\n"
    "                      --sweep or --scenario)\n";

static const char info_help[] =
    "info:\n"
    "--calibrate           also create a world in a headless context of --size and print\n"
    "                      the cost model it measures\n";

static const char import_help[] =
    "Validates one glTF file (.gltf or .glb) and summarises it: meshes, instances, materials,\n"
    "vertices, triangles, bounds.\n";

static const char exit_help[] =
    "Options take their value as --opt VALUE or --opt=VALUE; unique prefixes work; numbers\n"
    "are plain decimal digits.\n"
    "Exit status: 0 done; 1 a failure of the machine (memory, a file, no GL context); 2 bad\n"
    "input (one line on stderr); 3 a check that did not hold: a scenario's, or under --verify\n"
    "a conservative method that missed pixels (unless --allow-missed).\n";

/* The command whose --help is asked for (NULL: every command's). */
static const char *help_command;

static void usage(FILE *f)
{
    const char *c = help_command ? help_command : "";
    if (strcmp(c, "walk") == 0) {
        fprintf(f, "%s\n%s%s%s%s", walk_synopsis, world_help, run_help, tw_gl_usage, exit_help);
    } else if (strcmp(c, "bench") == 0) {
        fprintf(f, "%s\n%s%s%s%s%s", bench_synopsis, bench_help, world_help, run_help,
                tw_gl_usage, exit_help);
    } else if (strcmp(c, "info") == 0) {
        fprintf(f, "%s\n%s%s--size WxH            the calibration's image size (default 640x360)\n"
                   "--max-screen-error PX  also build the levels of detail a world would (0: none)\n"
                   "                      and list each prototype's triangles and geometric\n"
                   "                      errors (default 1); read from and kept in\n"
                   "                      TW_LEVELS_CACHE (see walk --help)\n"
                   "--hlod-levels N       also say which levels of hierarchical cells a world\n"
                   "                      would use, each one's error, from what distance at\n"
                   "                      --size, and its proxies' size\n"
                   "%s%s", info_synopsis, info_help, world_help, tw_gl_usage, exit_help);
    } else if (strcmp(c, "import") == 0) {
        fprintf(f, "%s\n%s", import_synopsis, import_help);
    } else {
        /* Every synopsis, then every explanation. */
        fprintf(f, "%s       %s       %s       %s%s\n%s%s%s%s%s%s", walk_synopsis,
                bench_synopsis + strlen("usage: "), info_synopsis + strlen("usage: "),
                import_synopsis + strlen("usage: "), other_synopses, world_help, run_help,
                bench_help, info_help, tw_gl_usage, exit_help);
    }
}

enum {
    OPT_OUT = TW_CLI_OPT_PROGRAM,
    OPT_VERIFY,
    OPT_PNG_EVERY,
    OPT_METHODS,
    OPT_CLUSTER_TRIANGLES,
    OPT_SWEEP,
    OPT_SCENARIO,
    OPT_NEIGHBOURS,
    OPT_EVICT_AFTER,
    OPT_CHC_BATCH,
    OPT_CHC_SUSPEND,
    OPT_HZB_PYRAMID,
    OPT_HLOD_LEVELS,
    OPT_CHC_NAV,
    OPT_THRESHOLD,
    OPT_DETERMINISTIC,
    OPT_VERIFY_TOLERANCE,
    OPT_MUTATE_QUERY_SHRINK,
    OPT_CALIBRATE,
    OPT_SPLIT,
    OPT_NO_COST_MODEL,
    OPT_FIRST_SIGHT_DRAWS,
    OPT_ALLOW_MISSED,
    OPT_VIEWS,
    OPT_CARS,
    OPT_FPS,
};

static const struct option options_table[] = {
    TW_CLI_COMMON_OPTIONS,
    {"out", required_argument, NULL, OPT_OUT},
    {"verify", no_argument, NULL, OPT_VERIFY},
    {"png-every", required_argument, NULL, OPT_PNG_EVERY},
    {"views", required_argument, NULL, OPT_VIEWS},
    {"cars", required_argument, NULL, OPT_CARS},
    {"fps", required_argument, NULL, OPT_FPS},
    {"methods", required_argument, NULL, OPT_METHODS},
    {"cluster-triangles", required_argument, NULL, OPT_CLUSTER_TRIANGLES},
    {"sweep", required_argument, NULL, OPT_SWEEP},
    {"scenario", required_argument, NULL, OPT_SCENARIO},
    {"tile-neighbours", required_argument, NULL, OPT_NEIGHBOURS},
    {"evict-after", required_argument, NULL, OPT_EVICT_AFTER},
    {"chc-batch", required_argument, NULL, OPT_CHC_BATCH},
    {"chc-suspend", required_argument, NULL, OPT_CHC_SUSPEND},
    {"hzb-pyramid", required_argument, NULL, OPT_HZB_PYRAMID},
    {"hlod-levels", required_argument, NULL, OPT_HLOD_LEVELS},
    {"chc-nav", required_argument, NULL, OPT_CHC_NAV},
    {"threshold", required_argument, NULL, OPT_THRESHOLD},
    {"deterministic", no_argument, NULL, OPT_DETERMINISTIC},
    {"verify-tolerance", required_argument, NULL, OPT_VERIFY_TOLERANCE},
    {"mutate-query-shrink", required_argument, NULL, OPT_MUTATE_QUERY_SHRINK},
    {"calibrate", no_argument, NULL, OPT_CALIBRATE},
    {"split", no_argument, NULL, OPT_SPLIT},
    {"no-cost-model", no_argument, NULL, OPT_NO_COST_MODEL},
    {"first-sight-draws", no_argument, NULL, OPT_FIRST_SIGHT_DRAWS},
    {"allow-missed", no_argument, NULL, OPT_ALLOW_MISSED},
    TW_GL_OPTIONS,
    {NULL, 0, NULL, 0},
};

static void parse_methods(const char *opt, const char *s, struct options *o)
{
    char buf[256];
    if (!s || strlen(s) >= sizeof(buf) || *s == '\0')
        tw_cli_fail(program, opt, "'%s' is not a comma-separated list of methods", s ? s : "");
    strcpy(buf, s);
    o->method_count = 0;
    for (char *save = NULL, *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        enum tw_method m = tw_cli_method(program, opt, tok);
        for (uint32_t k = 0; k < o->method_count; k++)
            if (o->methods[k] == m)
                tw_cli_fail(program, opt, "method '%s' is listed twice", tok);
        o->methods[o->method_count++] = m;
    }
    if (o->method_count == 0)
        tw_cli_fail(program, opt, "'%s' names no method", s);
    o->methods_given = true;
}

static void apply_option(void *user, int opt, const char *name, const char *v)
{
    struct options *o = user;
    struct tw_world_settings *ws = &o->cli.world;
    struct tw_world_tuning *wt = &o->cli.tuning;
    if (tw_gl_option(&o->gl, opt, name, v))
        return;
    switch (opt) {
    case OPT_OUT:
        if (*v == '\0')
            tw_cli_fail(program, name, "the output folder name is empty");
        o->out = v;
        break;
    case OPT_VERIFY: ws->verify = true; break;
    case OPT_PNG_EVERY: o->png_every = (uint32_t)tw_cli_u64(program, name, v, 0, 10000000); break;
    case OPT_FPS: o->fps = (uint32_t)tw_cli_u64(program, name, v, 1, 10000); break;
    case OPT_VIEWS: o->views = (uint32_t)tw_cli_u64(program, name, v, 1, 2); break;
    case OPT_CARS:
        o->cars = (uint32_t)tw_cli_u64(program, name, v, 0, TW_RUN_MAX_CARS);
        o->cars_given = true;
        break;
    case OPT_METHODS: parse_methods(name, v, o); break;
    case OPT_CLUSTER_TRIANGLES:
        o->cluster_triangles = (uint32_t)tw_cli_u64(program, name, v, 16, 1000000);
        break;
    case OPT_SWEEP: {
        char why[300];
        if (tw_run_sweep_check(v, why, sizeof(why)))
            tw_cli_fail(program, name, "%s", why + strlen("--sweep: "));
        o->sweep = v;
        break;
    }
    case OPT_SCENARIO: {
        bool known = strcmp(v, "all") == 0;
        for (const char *const *n = tw_scenario_names; *n; n++)
            known |= strcmp(*n, v) == 0;
        if (!known)
            tw_cli_fail(program, name, "unknown scenario '%s' (all, teleport, spin, inside-building, "
                        "inside-common-box, grazing, far-origin, no-occluders)", v);
        o->scenario = v;
        break;
    }
    case OPT_NEIGHBOURS:
        wt->tilequery.neighbours = (uint32_t)tw_cli_u64(program, name, v, 4, 8);
        if (wt->tilequery.neighbours != 4 && wt->tilequery.neighbours != 8)
            tw_cli_fail(program, name, "'%s' is neither 4 nor 8", v);
        break;
    case OPT_EVICT_AFTER:
        ws->evict_after_frames = (uint32_t)tw_cli_u64(program, name, v, 1, 1000000);
        break;
    case OPT_CHC_BATCH: wt->chc.batch_size = (uint32_t)tw_cli_u64(program, name, v, 1, 100000); break;
    case OPT_CHC_SUSPEND:
        wt->chc.suspended_passes = (uint32_t)tw_cli_u64(program, name, v, 1, TW_CHC_MAX_SUSPENDED);
        wt->chc.per_tile_waits = true;
        break;
    case OPT_HZB_PYRAMID:
        if (strcmp(v, "auto") == 0)
            wt->hzb_pyramid = TW_HZB_PYRAMID_AUTO;
        else if (strcmp(v, "gpu") == 0)
            wt->hzb_pyramid = TW_HZB_PYRAMID_GPU;
        else if (strcmp(v, "cpu") == 0)
            wt->hzb_pyramid = TW_HZB_PYRAMID_CPU;
        else
            tw_cli_fail(program, name, "'%s' is none of auto, gpu, cpu", v);
        break;
    case OPT_HLOD_LEVELS: wt->hlod_levels = (uint32_t)tw_cli_u64(program, name, v, 1, 12); break;
    case OPT_CHC_NAV: wt->chc.assumed_visible = (uint32_t)tw_cli_u64(program, name, v, 1, 1000); break;
    case OPT_THRESHOLD:
        wt->chc.threshold = (uint32_t)tw_cli_u64(program, name, v, 0, 1000000);
        wt->tilequery.threshold = wt->chc.threshold;
        break;
    case OPT_DETERMINISTIC: ws->deterministic = true; break;
    case OPT_VERIFY_TOLERANCE:
        /* The library reads 0 as its default: below 1 and above 0 here. */
        ws->verify_tolerance = tw_cli_float(program, name, v, 0.0f, 1.0f);
        if (!(ws->verify_tolerance > 0.0f && ws->verify_tolerance < 1.0f))
            tw_cli_fail(program, name, "'%s' is not above 0 and below 1", v);
        break;
    case OPT_CALIBRATE: o->calibrate = true; break;
    case OPT_SPLIT: o->split = true; break;
    case OPT_ALLOW_MISSED: o->allow_missed = true; break;
    case OPT_NO_COST_MODEL: wt->chc.no_cost_model = true; break;
    case OPT_FIRST_SIGHT_DRAWS: wt->chc.first_sight_draws = true; break;
    case OPT_MUTATE_QUERY_SHRINK:
        wt->mutate_query_shrink = tw_cli_float(program, name, v, 0.0f, 1.0f);
        if (wt->mutate_query_shrink >= 1.0f)
            tw_cli_fail(program, name, "'%s' is not below 1", v);
        break;
    default:
        tw_cli_fail(program, name, "unknown option '%s' (see tileworld --help)", name);
    }
}

static void parse_options(int argc, char **argv, struct options *o)
{
    memset(o, 0, sizeof(*o));
    tw_cli_init(&o->cli, program);
    o->cli.world.width = 640;
    o->cli.world.height = 360;
    o->out = "out";
    o->png_every = 50;
    o->command = argv[0];
    tw_cli_parse(&o->cli, argc, argv, options_table, apply_option, o, usage);
    if (!o->cli.path)
        o->cli.path = "street";
}

/* What `tileworld import` shows of a scene: meshes, primitives, instances,
 * materials, vertices, triangles (drawn and unique) and the bounds. */
static void print_scene_summary(const struct tw_gltf_scene *scene, FILE *f)
{
    char shown[512];
    fprintf(f, "%s\n", tw_log_escape(scene->source ? scene->source : "(glTF scene)", shown,
                                     sizeof(shown)));
    fprintf(f, "  meshes      %u (%u primitives)\n", scene->mesh_count, scene->primitive_count);
    fprintf(f, "  instances   %u\n", scene->instance_count);
    fprintf(f, "  materials   %u\n", scene->material_count);
    fprintf(f, "  vertices    %llu\n", (unsigned long long)scene->vertex_count);
    fprintf(f, "  triangles   %llu drawn, %llu in meshes\n",
            (unsigned long long)scene->triangle_count,
            (unsigned long long)scene->unique_triangles);
    const struct tw_box *b = &scene->bounds;
    fprintf(f, "  bounds      [%.3f, %.3f, %.3f] .. [%.3f, %.3f, %.3f]\n", b->min[0], b->min[1],
            b->min[2], b->max[0], b->max[1], b->max[2]);
    fprintf(f, "  size        %.3f x %.3f x %.3f\n", b->max[0] - b->min[0],
            b->max[1] - b->min[1], b->max[2] - b->min[2]);
}

/* tileworld import FILE: validate one glTF file and summarise it. */
static int import(int argc, char **argv)
{
    if (argc == 3 && (strcmp(argv[2], "--help") == 0 || strcmp(argv[2], "-h") == 0)) {
        help_command = "import";
        usage(stdout);
        return 0;
    }
    if (argc != 3 || argv[2][0] == '-') {
        tw_cli_message(program, "import: expected one file: tileworld import FILE.gltf|FILE.glb");
        return EXIT_USAGE;
    }
    struct tw_cli cli;
    tw_cli_init(&cli, program);
    const struct tw_log log = {tw_cli_log, &cli};
    struct tw_gltf_scene *scene = NULL;
    const int err = tw_gltf_import(argv[2], NULL, &log, &scene);
    if (err)
        return err == TW_ERR_NOMEM ? 1 : EXIT_USAGE;
    print_scene_summary(scene, stdout);
    tw_gltf_scene_destroy(scene);
    return 0;
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
    const int rc = tw_tilesets_builtin(mk->o->cli.tileset, mk->o->cli.world.selection.seed,
                                       cluster_triangles, mk->log, &ts);
    if (rc)
        snprintf(err, err_size, "--sweep: cluster_triangles needs a built-in tileset (%s)",
                 tw_error_to_str(rc));
    return rc ? NULL : ts;
}

static int run(const struct options *o, bool bench)
{
    const struct tw_log log = {tw_cli_log, (void *)&o->cli};
    struct tw_cli_world shown;
    tw_cli_world_load(&o->cli, o->cluster_triangles, &log, &shown);
    struct tw_path path = {0};
    if (!o->scenario)
        tw_cli_load_path(&o->cli, o->cli.path, o->cli.frames ? o->cli.frames : default_frames,
                         shown.footprint, &path);

    struct tw_run r = {0};
    struct tw_tileset *car_models = NULL;
    if (o->cars > 0 || (o->sweep && strncmp(o->sweep, "cars=", 5) == 0)) {
        /* main() has refused a world without the city's streets. */
        tw_tilesets_streets(o->cli.tileset, &r.traffic, NULL, 0);
        r.traffic.seed = o->cli.world.selection.seed;
        if (tw_tilesets_car_models(&log, &car_models)) {
            tw_cli_message(program, "cannot make the car models");
            tw_path_finish(&path);
            tw_cli_world_finish(&shown);
            return 1;
        }
    }
    r.cars = o->cars;
    r.tiles3d = shown.tiles3d;
    r.car_models = car_models;
    r.tileset = shown.tileset;
    r.provider = shown.source;
    r.tileset_name = o->cli.tileset;
    r.path = &path;
    r.path_name = o->cli.path;
    r.out = o->out;
    r.png_every = o->png_every;
    r.fps = o->fps;
    r.views = o->views;
    r.scenario_frames = o->cli.frames;
    r.bench = bench;
    r.split = o->split;
    r.quiet = o->cli.quiet;
    r.allow_missed = o->allow_missed;
    r.world = o->cli.world;
    r.tuning = o->cli.tuning;
    r.world.log = log;
    if (!bench) {
        r.methods[0] = o->cli.world.method;
        r.method_count = 1;
    } else if (o->methods_given) {
        memcpy(r.methods, o->methods, sizeof(r.methods));
        r.method_count = o->method_count;
    } else {
        for (int m = TW_METHOD_FIRST; m < TW_METHOD_ALL; m++)
            r.methods[r.method_count++] = (enum tw_method)m;
    }

    int rc = 1;
    char msg[1400];
    struct tw_context *ctx = NULL;
    int err = tw_gl_context_create(&o->gl, r.world.width, r.world.height, &log, &ctx);
    if (err)
        goto out;
    if (o->scenario) {
        bool held = false;
        err = tw_run_scenarios(&r, ctx, o->scenario, &held, msg, sizeof(msg));
        if (!err && !o->cli.quiet)
            tw_cli_message(program, "wrote %s/scenarios.md: %s", o->out,
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
        /* Bad input found on the way (an output folder that cannot be
         * made, a sweep the tileset cannot do, settings the world refuses)
         * is the user's; a failed write or frame is not. A world that
         * cannot be created has said why in the library's own line: one
         * line, not two. */
        if (r.world_error) {
            if (o->cli.errors_logged == 0)
                tw_cli_message(program, "%s", msg);
            rc = tw_cli_world_exit_status(r.world_error);
        } else {
            tw_cli_message(program, "%s", msg);
            rc = err == TW_ERR_INVALID ? EXIT_USAGE : 1;
        }
        goto out;
    }
    if (rc == 3)
        goto out;
    rc = 0;
    if (o->scenario)
        goto out;
    char dir[1100];
    tw_report_escape(o->out, false, dir, sizeof(dir));
    if (!o->cli.quiet) {
        tw_cli_message(program, "wrote %s/summary.md, %s/summary.json and %s/frames.csv%s",
                       dir, dir, dir, o->sweep ? " (the base run) and the sweep" : "");
    }
    /* The verdict is the run's answer: on stdout, --quiet or not. */
    struct tw_verdict verdict;
    tw_report_verdict(&r.about, r.figures, bench, TW_VERDICT_TEXT, &verdict);
    for (int k = 0; k < verdict.count; k++)
        printf("%s\n", verdict.lines[k]);
    const bool missed = r.conservative_missed_pixels > 0;
    if (o->sweep) {
        printf("That was the sweep's base run, with the defaults; every value's run: %s/sweep.md.\n",
               dir);
        if (missed && !verdict.failed)
            printf("FAILED: in the sweep a conservative method missed %llu pixels under --verify; "
                   "it must miss none. %s\n", (unsigned long long)r.conservative_missed_pixels,
                   o->allow_missed ? "Accepted by --allow-missed (exit status 0)."
                                   : "Exit status 3 (--allow-missed accepts it).");
    }
    fflush(stdout);
    if (missed && !o->allow_missed)
        rc = 3;
    if (!o->cli.quiet)
        tw_cli_world_tiles3d_line(program, &shown);
out:
    tw_context_destroy(ctx);
    tw_path_finish(&path);
    tw_cli_world_finish(&shown);
    tw_tileset_destroy(car_models);
    return rc;
}

/* What a context is, as info says it. */
static void print_gl(const struct tw_context *ctx)
{
    struct tw_context_info ci;
    tw_context_describe(ctx, &ci);
    char renderer[300], vendor[160], version[160], device[300];
    printf("OpenGL: %s (%s), %s, through %s", tw_cli_escape(ci.renderer, renderer, sizeof(renderer)),
           tw_cli_escape(ci.vendor, vendor, sizeof(vendor)),
           tw_cli_escape(ci.version, version, sizeof(version)), ci.kind);
    if (ci.device_index >= 0)
        printf(" (device %d: %s)", ci.device_index, tw_cli_escape(ci.device, device, sizeof(device)));
    printf("%s\n", ci.software ? "; a software renderer: its GPU time is CPU work" : "");
    printf("build: %s build of %s\n", tw_build_type(), tw_build_commit());
}

/* info --calibrate: the cost model's figures (DESIGN §14) as a world over
 * the tileset measures them at creation in a headless context of --size. */
static int print_calibration(const struct options *o, const struct tw_cli_world *shown,
                             const struct tw_log *log)
{
    struct tw_world_settings ws = o->cli.world;
    if (ws.width == 0 || ws.height == 0) {
        ws.width = 640;
        ws.height = 360;
    }
    struct tw_context *ctx = NULL;
    int err = tw_gl_context_create(&o->gl, ws.width, ws.height, log, &ctx);
    if (err)
        return 1;
    print_gl(ctx);
    tw_cli_world_apply(shown, &ws);
    ws.get_proc = tw_context_get_proc(ctx);
    ws.log = *log;
    struct tw_world *w = NULL;
    err = tw_world_create_tuned(&ws, &o->cli.tuning, &w);
    if (err) {
        tw_cli_message(program, "cannot create the world: %s", tw_error_to_str(err));
        tw_context_destroy(ctx);
        return tw_cli_world_exit_status(err);
    }
    const struct tw_calibration *c = tw_world_calibration(w);
    printf("cost model at %ux%u (%s, %.1f ms of CPU time to measure):\n", ws.width, ws.height,
           c->measured ? "measured" : "nominal", c->calibrate_ms);
    printf("  query          %9.4f ms (issue, one box drawn, result read back)\n", c->query_ms);
    printf("  query batched  %9.4f ms (the same, in a batch read at its end)\n",
           c->query_batched_ms);
    printf("  query box      %9.4f ms (each further box of a query)\n", c->query_box_ms);
    printf("  query pixel    %9.4f ns (each pixel its boxes cover)\n", c->query_pixel_ns);
    printf("  draw call      %9.4f ms (one cluster, hidden: its fragments fail the depth test)\n",
           c->draw_ms);
    printf("  triangle       %9.4f ns (of a hidden cluster)\n", c->triangle_ns);
    printf("  draw pixel     %9.4f ns (each pixel a hidden cluster's box covers)\n",
           c->draw_pixel_ns);
    printf("  a batched query costs as much as %.0f triangles or %.1f draw calls of a hidden "
           "cluster\n",
           c->triangle_ns > 0 ? c->query_batched_ms * 1e6 / c->triangle_ns : 0.0,
           c->draw_ms > 0 ? c->query_batched_ms / c->draw_ms : 0.0);
    tw_cli_world_destroy(w);
    tw_context_destroy(ctx);
    return 0;
}

/* info on a provider: its name, footprint, bound and shared tileset. */
/* The run's world settings with their defaults into *ws, and its focal
 * length in pixels (what a level's error is projected with). */
static double run_focal(const struct options *o, struct tw_world_settings *ws)
{
    *ws = o->cli.world;
    tw_world_default_settings(ws);
    return 0.5 * ws->height / tan(0.5 * ws->fov_y * 3.14159265358979323846 / 180.0);
}

static int info_provider(const struct options *o, const struct tw_cli_world *shown)
{
    const struct tw_tile_provider *p = shown->source;
    char name[1024];
    printf("provider %s: footprint %g x %g m, clusters of <= %u triangles, every cell's content "
           "%s\n", tw_cli_escape(shown->name, name, sizeof(name)),
           p->footprint[0], p->footprint[1],
           p->max_cluster_triangles ? p->max_cluster_triangles : 2048u,
           shown->tiles3d ? "fetched from the baked tileset on demand" : "generated on demand");
    const struct tw_box *b = &p->bound;
    printf("bound (the query box): [%.2f, %.2f, %.2f] .. [%.2f, %.2f, %.2f]\n", b->min[0],
           b->min[1], b->min[2], b->max[0], b->max[1], b->max[2]);
    if (p->shared)
        printf("shared tileset: %s, %u prototypes, %llu bytes of geometry\n",
               tw_cli_escape(p->shared->name, name, sizeof(name)), p->shared->prototype_count,
               (unsigned long long)tw_tileset_geometry_bytes(p->shared));
    else
        printf("shared tileset: none (no two cells share content)\n");
    if (p->levels > 0 && p->generate_level) {
        /* Where a world would draw each level's blocks (README
         * "Hierarchical cells"): from E_k f / PX on, at the run's size. */
        struct tw_world_settings ws;
        const double focal = run_focal(o, &ws);
        printf("coarser levels of its own (used with --max-screen-error %g at %ux%u%s):\n",
               (double)ws.max_screen_error, ws.width, ws.height,
               o->cli.tuning.hlod_levels == 1 ? "; not with --hlod-levels 1" : "");
        for (uint32_t k = 1; k <= p->levels; k++) {
            const double e = p->level_error[k - 1];
            if (ws.max_screen_error > 0.0f)
                printf("  blocks of %ux%u cells: error %.3g m, drawn from %.0f m on\n", 1u << k,
                       1u << k, e, e * focal / ws.max_screen_error);
            else
                printf("  blocks of %ux%u cells: error %.3g m, not drawn at full detail\n",
                       1u << k, 1u << k, e);
        }
    }
    return 0;
}

/* info without --calibrate: the OpenGL a run would get, from a small context
 * (none is a line, not a failure: the tileset's figures stand). */
static void print_gl_of(const struct options *o, const struct tw_log *log)
{
    struct tw_context *ctx = NULL;
    if (tw_gl_context_create(&o->gl, 16, 16, log, &ctx)) {
        printf("OpenGL: none (no headless context could be made)\n");
        return;
    }
    print_gl(ctx);
    tw_context_destroy(ctx);
}

static int info(const struct options *o)
{
    const struct tw_log log = {tw_cli_log, (void *)&o->cli};
    struct tw_cli_world shown;
    tw_cli_world_load(&o->cli, o->cluster_triangles, &log, &shown);
    if (shown.provider || shown.tiles3d) {
        int rc = info_provider(o, &shown);
        if (!rc && o->calibrate)
            rc = print_calibration(o, &shown, &log);
        else if (!rc)
            print_gl_of(o, &log);
        tw_cli_world_finish(&shown);
        return rc;
    }
    struct tw_tileset *ts = shown.tileset;
    struct tw_bvh_builder *b = NULL;
    int err = tw_bvh_builder_create(&log, 0, &b);
    if (err) {
        tw_tileset_destroy(ts);
        fprintf(stderr, "tileworld: cannot start Embree: %s\n", tw_error_to_str(err));
        return 1;
    }
    char name[1024];
    printf("tileset %s: %u prototypes, footprint %g x %g m, clusters of <= %u triangles\n",
           tw_cli_escape(ts->name, name, sizeof(name)), ts->prototype_count, ts->footprint[0], ts->footprint[1],
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
        printf("%-16s %10llu %9u %9u %6u %6u %9.3f %10llu\n",
               tw_cli_escape(proto->name, name, sizeof(name)),
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
    if (o->cli.world.max_screen_error > 0.0f) {
        /* What the world builds for --max-screen-error (DESIGN §17). */
        /* The tileset's own: --calibrate's world shares them. */
        const struct tw_lods *lods = NULL;
        const double t0 = tw_clock_monotonic_ms();
        struct tw_file_cache *store = NULL;
        char why[320];
        if (o->cli.world.levels_cache_dir &&
            tw_lods_store(o->cli.world.levels_cache_dir, 0, &store, why, sizeof(why)) != TW_OK)
            fprintf(stderr, "tileworld: levels of detail are built, not kept on disk: %s\n", why);
        err = tw_lods_of_tileset(ts, store, &lods);
        const double ms = tw_clock_monotonic_ms() - t0;
        if (err) {
            fprintf(stderr, "tileworld: cannot build the levels of detail: %s\n",
                    tw_error_to_str(err));
            tw_tileset_destroy(ts);
            return 1;
        }
        printf("levels of detail (%s in %.0f ms, %llu bytes with their geometry): triangles "
               "(geometric error, m) of each level, full detail first\n",
               lods->stored == 0                      ? "built"
               : lods->stored == ts->prototype_count ? "read from the levels cache"
                                                      : "built or read from the levels cache",
               ms, (unsigned long long)tw_lods_bytes(lods));
        for (uint32_t p = 0; p < ts->prototype_count; p++) {
            printf("%-16s %llu", tw_cli_escape(ts->prototypes[p].name, name, sizeof(name)),
                   (unsigned long long)ts->prototypes[p].triangle_count);
            for (uint32_t k = 0; k < lods->count[p]; k++)
                printf(", %llu (%.2g)",
                       (unsigned long long)lods->levels->prototypes[lods->first[p] + k].triangle_count,
                       lods->error[lods->first[p] + k]);
            printf("\n");
        }
        const uint32_t levels = o->cli.tuning.hlod_levels;
        if (levels > 1) {
            /* What --hlod-levels would do, as the world decides it: each
             * level's error, where it starts at the run's size, whether it
             * pays. */
            struct tw_world_settings ws;
            const double focal = run_focal(o, &ws);
            printf("hierarchical cells (--hlod-levels %u; from where a block is %g px across at "
                   "%ux%u):\n", levels, (double)TW_HLOD_BLOCK_PX, ws.width, ws.height);
            for (uint32_t k = 1; k < levels; k++) {
                const float error =
                    tw_hlod_level_error(ts->footprint, k, ws.max_screen_error, TW_HLOD_BLOCK_PX);
                uint64_t input;
                const bool pays = tw_hlod_level_pays(ts, lods, k, error, &input);
                printf("blocks of %ux%u cells: error %.3g m, from %.0f m, proxies of up to %llu "
                       "triangles: %s\n", 1u << k, 1u << k, (double)error,
                       error * focal / ws.max_screen_error, (unsigned long long)input,
                       pays ? "used" : "too many, always refined");
            }
        }
    }
    int rc = 0;
    if (o->calibrate)
        rc = print_calibration(o, &shown, &log);
    else
        print_gl_of(o, &log);
    tw_tileset_destroy(ts);
    return rc;
}

static int tileworld_main(int argc, char **argv);

int main(int argc, char **argv)
{
    return tw_cli_exit(program, tileworld_main(argc, argv));
}

static int tileworld_main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "tileworld: no command given (walk, bench, info, view, import, memtest, bake; "
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
        help_command = argv[1];
        parse_options(argc - 1, argv + 1, &o);
    } else if (strcmp(argv[1], "import") == 0) {
        return import(argc, argv);
    } else if (strcmp(argv[1], "memtest") == 0) {
        return tw_memtest_main(argc - 1, argv + 1);
    } else if (strcmp(argv[1], "bake") == 0) {
        return tw_bake_main(argc - 1, argv + 1);
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
        tw_cli_message(program, "view: cannot run %s: %s", viewer, strerror(errno));
        return 1;
    } else {
        tw_cli_message(program, "unknown command '%s' (walk, bench, info, view, import, memtest, bake)", argv[1]);
        return EXIT_USAGE;
    }
    if (strcmp(o.command, "info") == 0 && o.cars_given)
        tw_cli_fail(program, "--cars", "--cars belongs to walk and bench");
    if (strcmp(o.command, "info") == 0)
        return info(&o);
    if (strcmp(o.command, "walk") == 0) {
        if (o.methods_given)
            tw_cli_fail(program, "--methods", "--methods belongs to bench; walk takes --method");
        if (o.sweep)
            tw_cli_fail(program, "--sweep", "--sweep belongs to bench");
        if (o.scenario)
            tw_cli_fail(program, "--scenario", "--scenario belongs to bench");
        if (o.split)
            tw_cli_fail(program, "--split", "--split belongs to bench");
    }
    const bool cars_swept = o.sweep && strncmp(o.sweep, "cars=", 5) == 0;
    if (o.cars > 0 || cars_swept) {
        const char *opt = o.cars > 0 ? "--cars" : "--sweep";
        char with_streets[128];
        if (!tw_tilesets_streets(o.cli.tileset, NULL, with_streets, sizeof(with_streets))) {
            char shown[300];
            tw_cli_fail(program, opt, "cars drive on the city's streets, which tileset '%s' does "
                        "not have (%s have them)",
                        tw_cli_escape(o.cli.tileset, shown, sizeof(shown)), with_streets);
        }
        if (o.scenario)
            tw_cli_fail(program, opt, "--scenario runs its own paths without cars; give one of "
                        "the two");
        if (o.cli.tuning.hlod_levels > 1)
            tw_cli_fail(program, opt, "moving cars and hierarchical cells (--hlod-levels %u) do "
                        "not go together: a block's merged proxy cannot move them",
                        o.cli.tuning.hlod_levels);
    }
    if (o.split && (o.sweep || o.scenario))
        tw_cli_fail(program, "--split", "--split parts a bench run's CPU time; it takes no %s",
                    o.sweep ? "--sweep" : "--scenario");
    if (tw_tilesets_is_provider(o.cli.tileset) || tw_cli_is_url(o.cli.tileset)) {
        if (o.scenario)
            tw_cli_fail(program, "--scenario", "scenarios need a prototype tileset (they place the "
                        "camera by its prototypes); '%s' is a provider", o.cli.tileset);
        if (o.sweep && strncmp(o.sweep, "cluster_triangles=", 18) == 0)
            tw_cli_fail(program, "--sweep", "cluster_triangles needs a prototype tileset; '%s' is a "
                        "provider (give --cluster-triangles N for one size)", o.cli.tileset);
    }
    if (o.scenario) {
        /* A scenario makes its own path and selection (far-origin its own
         * period and start cell): what would be ignored is refused. */
        static const struct { int opt; const char *name; } theirs[] = {
            {TW_CLI_OPT_PATH, "--path"},
            {TW_CLI_OPT_START_CELL, "--start-cell"},
            {TW_CLI_OPT_REPEAT, "--repeat"},
        };
        for (size_t k = 0; k < sizeof(theirs) / sizeof(theirs[0]); k++)
            if (tw_cli_given(&o.cli, theirs[k].opt))
                tw_cli_fail(program, theirs[k].name, "--scenario runs its own path and selection; "
                            "it takes no %s", theirs[k].name);
        if (o.sweep)
            tw_cli_fail(program, "--sweep", "--sweep and --scenario are two kinds of run; give one");
    }
    return run(&o, strcmp(o.command, "bench") == 0);
}
