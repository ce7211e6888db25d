/* tileworld bake: cells to a 3D Tiles 1.1 tileset (bake.h). */
#include "tools/tileworld/bake.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "tileworld/tiles.h"
#include "tileworld/tilesets.h"
#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"
#include "tools/cli.h"
#include "tools/progress.h"
#include "tools/tileworld/tiles3d.h"

static const char program[] = "tileworld";

/* The default refusal: a rectangle of more cells is most likely a typo. */
#define DEFAULT_MAX_CELLS (1ull << 20)
/* Levels a subtree file covers: a 32 x 32 block of its deepest tiles, bits
 * of a few hundred bytes. */
#define SUBTREE_LEVELS 6u
/* Levels with content at most: the coarsest tiles then span 128 x 128 cells
 * (10 km of city), within reach of float tile-local coordinates. */
#define MAX_CONTENT_LEVELS 8u
/* The deepest quadtree a rectangle may need: x and y fit 32 bits. */
#define MAX_LEAF_LEVEL 31u

static const char synopsis[] =
    "usage: tileworld bake   --tileset NAME|FILE.json --cells I0,J0:I1,J1 --out DIR [--levels N]\n"
    "                        [--shard K/N] [--finish] [--workers N] [--seed N] [--repeat P]\n"
    "                        [--max-cells N] [--quiet]\n";

static const char help[] =
    "Writes the cells I0..I1 x J0..J1 of a tileset or a provider as a 3D Tiles 1.1 tileset\n"
    "with implicit tiling (a quadtree over the cells) into DIR: tileset.json, one binary\n"
    "glTF per cell that shows something (content/LEVEL/X/Y.glb, X = I - I0, Y = J - J0),\n"
    "and the availability of every tile (subtrees/LEVEL/X/Y.subtree). Each file is written\n"
    "whole or not at all; a rerun skips the cells already baked; N machines fill one\n"
    "folder with --shard 0/N .. --shard N-1/N, then one of them runs --finish.\n"
    "--tileset NAME|FILE.json  what to bake: the built-in city (default), forest, hybrid;\n"
    "                      the providers city-gen and forest-gen; or a manifest\n"
    "--cells I0,J0:I1,J1   the rectangle of cells, both corners included (I1 >= I0, J1 >= J0)\n"
    "--out DIR             the tileset's folder, made if missing\n"
    "--levels N            quadtree levels with content, 1..8 and at most the quadtree's\n"
    "                      (default 1: the cells only); each coarser level's tile is its\n"
    "                      four children merged and simplified within their error (a\n"
    "                      tileset's blocks above 2x2 cells: from its cells' own coarser\n"
    "                      levels), made by --finish (or a run without --shard); the\n"
    "                      levels above are tiles without content\n"
    "--shard K/N           bakes only the cells whose index in the rectangle,\n"
    "                      (J - J0) (I1 - I0 + 1) + I - I0, is K modulo N (0 <= K < N <=\n"
    "                      1000000), and writes no tileset.json and no subtrees: --finish\n"
    "                      does, once every shard is done\n"
    "--finish              writes tileset.json and the subtrees from the cells on disk;\n"
    "                      bakes no cell\n"
    "--workers N           threads making and writing cells, 1..64 (default: cores)\n"
    "--seed N              seed of the generators and of the cells' selection (default 1)\n"
    "--repeat P            the selection repeats every P cells\n"
    "--max-cells N         refuses a rectangle of more cells, 1..1099511627776\n"
    "                      (default 1048576)\n"
    "--quiet               no progress line and no summary line\n"
    "Options take their value as --opt VALUE or --opt=VALUE; unique prefixes work; numbers\n"
    "are plain decimal digits.\n"
    "Exit status: 0 done; 1 a failure (memory, a file, a cell that cannot be made); 2 bad\n"
    "input (one line on stderr). Progress (stderr): on a terminal one line rewritten in\n"
    "place; otherwise a line every 10 s, or every TW_PROGRESS_INTERVAL_S seconds.\n";

static void usage(FILE *f)
{
    fprintf(f, "%s\n%s", synopsis, help);
}

enum {
    OPT_CELLS = TW_CLI_OPT_PROGRAM,
    OPT_OUT,
    OPT_LEVELS,
    OPT_SHARD,
    OPT_FINISH,
    OPT_MAX_CELLS,
};

static const struct option options_table[] = {
    TW_CLI_COMMON_OPTIONS,
    {"cells", required_argument, NULL, OPT_CELLS},
    {"out", required_argument, NULL, OPT_OUT},
    {"levels", required_argument, NULL, OPT_LEVELS},
    {"shard", required_argument, NULL, OPT_SHARD},
    {"finish", no_argument, NULL, OPT_FINISH},
    {"max-cells", required_argument, NULL, OPT_MAX_CELLS},
    {NULL, 0, NULL, 0},
};

struct bake {
    struct tw_cli cli;
    const char *cells_text;       /* --cells as given */
    struct tw_cell first, last;   /* the rectangle's corners */
    const char *out;
    uint32_t levels;              /* levels with content */
    uint32_t shard, shards;       /* --shard K/N; 0/1: all */
    bool shard_given;
    bool finish;
    uint64_t max_cells;

    uint64_t nx, ny;              /* cells along i and j */
    const struct tw_lods *cell_lods;   /* a prototype tileset's levels, for its blocks; or NULL */
    uint32_t leaf;                /* the finest level */
    struct tw_cli_world world;
    struct tw_log log;

    /* The jobs of this step (cells, or the blocks of one coarser level),
     * shared by the workers. */
    uint32_t block_level;         /* 0 .. leaf - 1: blocks of this level; leaf: cells */
    uint64_t jobs;                /* this step's jobs */
    _Atomic uint64_t next;        /* the next linear index to look at */
    _Atomic uint64_t done;        /* this run's cells looked at */
    _Atomic uint64_t written, empty, skipped;
    _Atomic bool failed;
    pthread_mutex_t lock;         /* guards message */
    char message[1400];           /* the first failure */
};

/* "I,J" into *c; the whole text names the option in messages. */
static void parse_corner(const char *opt, const char *whole, const char *s, size_t n,
                         struct tw_cell *c)
{
    char buf[64];
    if (n == 0 || n >= sizeof(buf))
        tw_cli_fail(program, opt, "'%s' is not I0,J0:I1,J1 (two corners of the rectangle)",
                    whole);
    memcpy(buf, s, n);
    buf[n] = '\0';
    tw_cli_cell(program, opt, buf, c);
}

static void parse_cells(const char *opt, const char *s, struct bake *b)
{
    const char *colon = strchr(s, ':');
    if (!colon || strchr(colon + 1, ':'))
        tw_cli_fail(program, opt, "'%s' is not I0,J0:I1,J1 (two corners of the rectangle)", s);
    parse_corner(opt, s, s, (size_t)(colon - s), &b->first);
    parse_corner(opt, s, colon + 1, strlen(colon + 1), &b->last);
    if (b->last.i < b->first.i || b->last.j < b->first.j)
        tw_cli_fail(program, opt, "'%s': the second corner must not lie before the first "
                    "(I1 >= I0 and J1 >= J0)", s);
    b->cells_text = s;
}

static void parse_shard(const char *opt, const char *s, struct bake *b)
{
    const char *slash = strchr(s, '/');
    char k[32];
    if (!slash || (size_t)(slash - s) >= sizeof(k) || slash == s)
        tw_cli_fail(program, opt, "'%s' is not K/N (this machine's part K of N, 0 <= K < N)", s);
    memcpy(k, s, (size_t)(slash - s));
    k[slash - s] = '\0';
    b->shards = (uint32_t)tw_cli_u64(program, opt, slash + 1, 1, 1000000);
    b->shard = (uint32_t)tw_cli_u64(program, opt, k, 0, 999999);
    if (b->shard >= b->shards)
        tw_cli_fail(program, opt, "'%s': K must be below N (parts 0 to %u)", s, b->shards - 1);
    b->shard_given = true;
}

static void apply_option(void *user, int opt, const char *name, const char *v)
{
    struct bake *b = user;
    switch (opt) {
    case OPT_CELLS: parse_cells(name, v, b); break;
    case OPT_OUT:
        if (*v == '\0')
            tw_cli_fail(program, name, "the output folder name is empty");
        b->out = v;
        break;
    case OPT_LEVELS: b->levels = (uint32_t)tw_cli_u64(program, name, v, 1, MAX_CONTENT_LEVELS); break;
    case OPT_SHARD: parse_shard(name, v, b); break;
    case OPT_FINISH: b->finish = true; break;
    case OPT_MAX_CELLS: b->max_cells = tw_cli_u64(program, name, v, 1, 1ull << 40); break;
    default:
        tw_cli_fail(program, name, "unknown option '%s' (see tileworld bake --help)", name);
    }
}

static void parse_options(int argc, char **argv, struct bake *b)
{
    tw_cli_init(&b->cli, program);
    b->levels = 1;
    b->shards = 1;
    b->max_cells = DEFAULT_MAX_CELLS;
    tw_cli_parse(&b->cli, argc, argv, options_table, apply_option, b, usage);
    /* The shared options that mean nothing to a bake. */
    static const struct { int opt; const char *name; } walks[] = {
        {TW_CLI_OPT_PATH, "--path"}, {TW_CLI_OPT_FRAMES, "--frames"},
        {TW_CLI_OPT_METHOD, "--method"}, {TW_CLI_OPT_SIZE, "--size"},
        {TW_CLI_OPT_START_CELL, "--start-cell"}, {TW_CLI_OPT_VIEW_DISTANCE, "--view-distance"},
        {TW_CLI_OPT_POLICY, "--policy"}, {TW_CLI_OPT_BUDGET, "--budget"},
        {TW_CLI_OPT_UPLOAD_BUDGET, "--upload-budget"},
        {TW_CLI_OPT_MAX_SCREEN_ERROR, "--max-screen-error"},
    };
    for (size_t k = 0; k < sizeof(walks) / sizeof(walks[0]); k++)
        if (tw_cli_given(&b->cli, walks[k].opt))
            tw_cli_fail(program, walks[k].name, "bake takes no %s (it renders nothing)",
                        walks[k].name);
    if (!b->cells_text)
        tw_cli_fail(program, "--cells", "which cells to bake: give --cells I0,J0:I1,J1");
    if (!b->out)
        tw_cli_fail(program, "--out", "where to bake: give --out DIR");
    if (b->finish && b->shard_given)
        tw_cli_fail(program, "--finish", "--finish writes what every shard baked: it takes no "
                    "--shard");
    /* Differences of corners within +-2^62 fit in 64 bits. */
    b->nx = (uint64_t)(b->last.i - b->first.i) + 1;
    b->ny = (uint64_t)(b->last.j - b->first.j) + 1;
    const bool too_many = b->nx > b->max_cells || b->ny > b->max_cells ||
                          b->nx * b->ny > b->max_cells;
    if (too_many)
        tw_cli_fail(program, "--cells", "'%s' holds %.0f cells, more than %llu (--max-cells N "
                    "raises the limit)", b->cells_text, (double)b->nx * (double)b->ny,
                    (unsigned long long)b->max_cells);
    const uint64_t side = b->nx > b->ny ? b->nx : b->ny;
    b->leaf = 0;
    while ((1ull << b->leaf) < side)
        b->leaf++;
    if (b->leaf > MAX_LEAF_LEVEL)
        tw_cli_fail(program, "--cells", "'%s' is %llu cells long: at most 2^%u", b->cells_text,
                    (unsigned long long)side, MAX_LEAF_LEVEL);
    if (b->levels > b->leaf + 1)
        tw_cli_fail(program, "--levels", "'%u': the quadtree over '%s' has %u level%s", b->levels,
                    b->cells_text, b->leaf + 1, b->leaf ? "s" : "");
    if (b->cli.world.workers == 0) {
        const long cores = sysconf(_SC_NPROCESSORS_ONLN);
        b->cli.world.workers = cores < 1 ? 1 : cores > 64 ? 64 : (uint32_t)cores;
    }
}

/* ---- paths ---------------------------------------------------------------------- */

static int tile_path(const struct bake *b, char *out, size_t size, const char *kind,
                     uint32_t level, uint64_t x, uint64_t y, const char *ext)
{
    const int n = snprintf(out, size, "%s/%s/%u/%llu/%llu.%s", b->out, kind, level,
                           (unsigned long long)x, (unsigned long long)y, ext);
    return n > 0 && (size_t)n < size ? TW_OK : TW_ERR_IO;
}

/* The tiles of level `level` that overlap the rectangle: w x h of them. */
static void level_size(const struct bake *b, uint32_t level, uint64_t *w, uint64_t *h)
{
    const uint32_t up = b->leaf - level;
    *w = ((b->nx - 1) >> up) + 1;
    *h = ((b->ny - 1) >> up) + 1;
}

static bool exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* ---- one cell ----------------------------------------------------------------- */

static void fail_run(struct bake *b, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void fail_run(struct bake *b, const char *fmt, ...)
{
    pthread_mutex_lock(&b->lock);
    if (!atomic_load(&b->failed)) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(b->message, sizeof(b->message), fmt, ap);
        va_end(ap);
        atomic_store(&b->failed, true);
    }
    pthread_mutex_unlock(&b->lock);
}

/* Whether instance in of ts is drawn as it is: not merged into another
 * mesh, and of some triangles. */
static bool draws(const struct tw_tileset *ts, const struct tw_instance *in)
{
    return in->merged_into == TW_INSTANCE_NONE && ts->meshes[in->mesh].triangle_count > 0;
}

/* Writes prototype p of ts (finished) as the glTF file path, placed at
 * translation: what the renderer draws of it, as it draws it. Every
 * instance that draws (merged_into TW_INSTANCE_NONE: the large instances
 * and the merged meshes' identity placements) is a node with its exact
 * transform and material, every mesh they use is written once with its
 * vertex colours and its finished triangle order, so that the 3D Tiles
 * provider rebuilds the same tile (tilesets/tiles3d-glb.c). The used meshes
 * and materials keep their order. */
static int write_prototype(const struct tw_tileset *ts, uint32_t p, const char *path,
                           const double translation[3], double error, char *err, size_t err_size)
{
    const struct tw_prototype *proto = &ts->prototypes[p];
    const uint32_t ni = proto->instance_count;
    struct tw_tiles3d_node *nodes = malloc(sizeof(*nodes) * (ni ? ni : 1));
    uint32_t *mesh_map = malloc(sizeof(*mesh_map) * (ts->mesh_count ? ts->mesh_count : 1));
    uint32_t *material_map = malloc(sizeof(*material_map) *
                                    (ts->material_count ? ts->material_count : 1));
    struct tw_tiles3d_mesh *meshes = malloc(sizeof(*meshes) * (ts->mesh_count ? ts->mesh_count : 1));
    float (*materials)[4] = malloc(sizeof(*materials) * (ts->material_count ? ts->material_count : 1));
    int rc = TW_OK;
    if (!nodes || !mesh_map || !material_map || !meshes || !materials) {
        snprintf(err, err_size, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
        rc = TW_ERR_NOMEM;
        goto out;
    }
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        mesh_map[k] = UINT32_MAX;
    for (uint32_t k = 0; k < ts->material_count; k++)
        material_map[k] = UINT32_MAX;
    for (uint32_t k = 0; k < ni; k++) {
        const struct tw_instance *in = &proto->instances[k];
        if (draws(ts, in)) {
            mesh_map[in->mesh] = 0;
            material_map[in->material] = 0;
        }
    }
    uint32_t mesh_count = 0, material_count = 0, node_count = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        if (mesh_map[k] == UINT32_MAX)
            continue;
        const struct tw_mesh *m = &ts->meshes[k];
        mesh_map[k] = mesh_count;
        meshes[mesh_count++] = (struct tw_tiles3d_mesh){
            .positions = m->positions, .normals = m->normals, .colors = m->colors,
            .indices = m->indices, .vertex_count = m->vertex_count,
            .triangle_count = m->triangle_count,
        };
    }
    for (uint32_t k = 0; k < ts->material_count; k++) {
        if (material_map[k] == UINT32_MAX)
            continue;
        material_map[k] = material_count;
        memcpy(materials[material_count++], ts->materials[k].base_color, sizeof(materials[0]));
    }
    for (uint32_t k = 0; k < ni; k++) {
        const struct tw_instance *in = &proto->instances[k];
        if (!draws(ts, in))
            continue;
        struct tw_tiles3d_node *n = &nodes[node_count++];
        n->mesh = mesh_map[in->mesh];
        n->material = material_map[in->material];
        memcpy(n->transform, in->transform, sizeof(n->transform));
    }
    const struct tw_tiles3d_scene scene = {
        .meshes = meshes, .mesh_count = mesh_count, .materials = (const float (*)[4])materials,
        .material_count = material_count, .nodes = nodes, .node_count = node_count,
        .error = error,
    };
    rc = tw_tiles3d_make_parents(path, err, err_size);
    if (!rc)
        rc = tw_tiles3d_write_glb(path, &scene, translation, err, err_size);
out:
    free(nodes);
    free(mesh_map);
    free(material_map);
    free(meshes);
    free(materials);
    return rc;
}

/* Bakes the cell at linear index k of the rectangle: skipped when its file
 * exists; nothing for an empty cell. */
static void bake_cell(struct bake *b, uint64_t k)
{
    const uint64_t x = k % b->nx, y = k / b->nx;
    const struct tw_cell cell = {b->first.i + (int64_t)x, b->first.j + (int64_t)y};
    char path[4096], err[1200];
    if (tile_path(b, path, sizeof(path), "content", b->leaf, x, y, "glb")) {
        fail_run(b, "%s/content/...: %s", b->out, strerror(ENAMETOOLONG));
        return;
    }
    if (exists(path)) {
        atomic_fetch_add(&b->skipped, 1);
        return;
    }
    /* Cell-relative geometry, placed by its node at its offset from the
     * rectangle's first cell: the numbers stay small wherever the cell is. */
    const double translation[3] = {(double)x * b->world.footprint[0], 0.0,
                                   (double)y * b->world.footprint[1]};
    int rc;
    if (b->world.tileset) {
        const uint32_t p = tw_tiles_select(b->world.tileset, &b->cli.world.selection, cell);
        if (p == TW_TILE_EMPTY) {
            atomic_fetch_add(&b->empty, 1);
            return;
        }
        rc = write_prototype(b->world.tileset, p, path, translation, 0.0, err, sizeof(err));
    } else {
        const struct tw_tile_provider *src = b->world.source;
        const uint32_t c = src->content ? src->content(src->user, cell) : TW_TILE_OWN;
        if (c == TW_TILE_EMPTY) {
            atomic_fetch_add(&b->empty, 1);
            return;
        }
        if (c != TW_TILE_OWN) {
            rc = write_prototype(src->shared, c, path, translation, 0.0, err, sizeof(err));
        } else {
            /* As a world makes it: the same checks (one prototype, the
             * provider's bound, the default cap on triangles), the
             * provider's own reason when it fails. */
            struct tw_tileset *ts = NULL;
            char why[512];
            rc = tw_provider_make_tile(src, cell, TW_MAX_TILE_TRIANGLES, &ts, why, sizeof(why));
            if (rc == TW_GENERATE_EMPTY) {
                atomic_fetch_add(&b->empty, 1);
                return;
            }
            if (rc)
                snprintf(err, sizeof(err), "cell %lld,%lld: %s: %s", (long long)cell.i,
                         (long long)cell.j, src->name ? src->name : "the provider", why);
            else
                rc = write_prototype(ts, 0, path, translation, 0.0, err, sizeof(err));
            tw_tileset_destroy(ts);
        }
    }
    if (rc)
        fail_run(b, "%s", err);
    else
        atomic_fetch_add(&b->written, 1);
}

/* Clusters of the blocks' tilesets (what tw_tileset_finish() splits). */
#define BLOCK_CLUSTER_TRIANGLES 2048u

/* The triangles of prototype p's instances (unfinished). */
static uint64_t instance_triangles(const struct tw_tileset *ts, uint32_t p)
{
    uint64_t n = 0;
    for (uint32_t k = 0; k < ts->prototypes[p].instance_count; k++)
        n += ts->meshes[ts->prototypes[p].instances[k].mesh].triangle_count;
    return n;
}

/* Adds the .glb file path (a tile of the level below, in the bake's own
 * layout: tilesets/tiles3d-glb.c) to prototype proto of ts, moved by
 * -origin. *error: the geometric error written into it (0: none). */
static int read_child(const char *path, struct tw_tileset *ts, uint32_t proto,
                      const double origin[3], double *error, char *err, size_t err_size)
{
    FILE *f = fopen(path, "rb");
    uint8_t *data = NULL;
    long n = -1;
    if (f && fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (data = malloc(n > 0 ? (size_t)n : 1)) && fread(data, 1, (size_t)n, f) != (size_t)n)
        n = -1;
    if (f)
        fclose(f);
    if (!data || n < 0) {
        snprintf(err, err_size, "%.900s: %s", path, data ? "cannot read it" : strerror(errno));
        free(data);
        return TW_ERR_IO;
    }
    const double shift[3] = {-origin[0], -origin[1], -origin[2]};
    char why[512];
    const int rc = tw_tiles3d_glb_read(data, (size_t)n, ts, proto, shift, error, why, sizeof(why));
    free(data);
    if (rc)
        snprintf(err, err_size, "%.600s: %.500s", path, why);
    return rc;
}

/* Writes block (its one prototype, full detail, or the coarsest of its
 * levels lods whose error is within allowed) to path, placed at origin; the
 * error written is base_error (what the block's input already has) plus
 * the level's. Counts it written, or fails the run. */
static void write_block(struct bake *b, const struct tw_tileset *block, const struct tw_lods *lods,
                        double base_error, double allowed, const double origin[3],
                        const char *path)
{
    const float *err_of = lods->error ? lods->error + lods->first[0] : NULL;
    const uint32_t count = lods->count ? lods->count[0] : 0;
    uint32_t pick = 0;
    while (pick < count && err_of[pick] <= allowed)
        pick++;
    const double error = base_error + (pick ? err_of[pick - 1] : 0.0);
    char err[1200];
    if (write_prototype(pick ? lods->levels : block, pick ? lods->first[0] + pick - 1 : 0, path,
                        origin, error > 0.0 ? error : 1e-6, err, sizeof(err)))
        fail_run(b, "%s", err);
    else
        atomic_fetch_add(&b->written, 1);
}

/* The most triangles (a bound: the heaviest cell's, times the cells) a block
 * made from its cells' levels takes in: four times what the runtime's
 * proxies do (TW_HLOD_MAX_INPUT), a bake being made once. */
#define BAKE_BLOCK_MAX_INPUT (4 * (uint64_t)TW_HLOD_MAX_INPUT)

/* Bakes block (x, y) of side 2^up cells of a prototype tileset from its
 * cells' own coarser levels, as the library's proxies are (tiles/hlod.c),
 * rather than from its children's files: each cell at its coarsest level
 * within the children's error, merged, then simplified to the coarsest
 * level within the rest of twice that error. Its children's files, already
 * simplified within their error, merged and simplified again within the
 * same error, kept what the children kept (tree crowns, a city's blocks
 * clustered into patches larger than that error): every level of blocks
 * above the 2x2 ones held as much as the one below. The error written is
 * the cells' levels' plus the simplification's, at most twice the
 * children's, so errors still double from level to level. Whether the
 * block was made so (written, or the run failed); false where its cells'
 * input could pass BAKE_BLOCK_MAX_INPUT triangles even at twice the
 * children's error: the caller merges the children's files instead. */
static bool bake_block_of_cells(struct bake *b, uint64_t x, uint64_t y, uint32_t up,
                               double child_error, const double origin[3], const char *path)
{
    const struct tw_tileset *cells = b->world.tileset;
    const struct tw_lods *cell_lods = b->cell_lods;
    const double allowed = 2.0 * child_error;
    /* Half for the cells' levels, half for the block's own simplification;
     * where that input would be too heavy to simplify, all of it for the
     * cells' levels, merged as they are. */
    double input_allowed = 0.5 * allowed;
    uint64_t input = 0;
    tw_hlod_level_pays(cells, cell_lods, up, (float)input_allowed, &input);
    if (input > BAKE_BLOCK_MAX_INPUT) {
        input_allowed = allowed;
        tw_hlod_level_pays(cells, cell_lods, up, (float)input_allowed, &input);
        if (input > BAKE_BLOCK_MAX_INPUT)
            return false;
    }
    const uint64_t side = 1ull << up;
    uint32_t *protos = malloc(sizeof(*protos) * side * side);
    if (!protos) {
        fail_run(b, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
        return true;
    }
    for (uint64_t cy = 0; cy < side; cy++)
        for (uint64_t cx = 0; cx < side; cx++) {
            const uint64_t gx = x * side + cx, gy = y * side + cy;
            uint32_t p = TW_HLOD_EMPTY;
            if (gx < b->nx && gy < b->ny) {
                const struct tw_cell cell = {b->first.i + (int64_t)gx, b->first.j + (int64_t)gy};
                const uint32_t q = tw_tiles_select(cells, &b->cli.world.selection, cell);
                p = q == TW_TILE_EMPTY ? TW_HLOD_EMPTY : q;
            }
            protos[cy * side + cx] = p;
        }
    struct tw_tileset *block = NULL;
    struct tw_lods lods = {0};
    float input_error = 0.0f;
    int rc = tw_hlod_block_build(cells, cell_lods, protos, (uint32_t)side, (float)input_allowed,
                                 BLOCK_CLUSTER_TRIANGLES, &block, &input_error);
    free(protos);
    if (!rc && !block) {
        atomic_fetch_add(&b->empty, 1);
        return true;
    }
    if (!rc)
        rc = tw_lods_build(block, BLOCK_CLUSTER_TRIANGLES, NULL, NULL, &lods);
    if (rc) {
        fail_run(b, "%s: cannot simplify the block: %s", path, tw_error_to_str(rc));
        tw_tileset_destroy(block);
        return true;
    }
    write_block(b, block, &lods, input_error, allowed - input_error, origin, path);
    tw_lods_free(&lods);
    tw_tileset_destroy(block);
    return true;
}

/* Bakes tile k (row-major) of the coarser level b->block_level: its
 * children's .glb files (the level below) merged into one tile-local mesh
 * and simplified by the levels of detail (tiles/lod.c, meshoptimizer) to
 * the coarsest level within the error the level may add (see below). Its
 * geometric error, the simplification's plus its children's, goes into the
 * file (asset.extras.geometricError) for --finish's tileset.json. Skipped
 * when its file exists; nothing when no child has content. */
static void bake_block(struct bake *b, uint64_t k)
{
    const uint32_t level = b->block_level, up = b->leaf - level;
    uint64_t w, h;
    level_size(b, level, &w, &h);
    const uint64_t x = k % w, y = k / w;
    const uint64_t side = 1ull << up;
    const double origin[3] = {(double)(x * side) * b->world.footprint[0], 0.0,
                              (double)(y * side) * b->world.footprint[1]};
    char path[4096], child[4096], err[1200];
    if (tile_path(b, path, sizeof(path), "content", level, x, y, "glb")) {
        fail_run(b, "%s/content/...: %s", b->out, strerror(ENAMETOOLONG));
        return;
    }
    if (exists(path)) {
        atomic_fetch_add(&b->skipped, 1);
        return;
    }
    struct tw_tileset *ts = NULL;
    struct tw_lods lods = {0};
    double child_error = 0.0;
    int rc = tw_tileset_create("block", (float)side * b->world.footprint[0],
                               (float)side * b->world.footprint[1], &ts);
    const int proto = rc ? rc : tw_tileset_add_prototype(ts, "block", 1.0f);
    if (rc || proto < 0) {
        fail_run(b, "%s: %s", path, tw_error_to_str(rc ? rc : proto));
        goto out;
    }
    for (uint32_t c = 0; c < 4; c++) {
        const uint64_t cx = 2 * x + (c & 1), cy = 2 * y + (c >> 1);
        if (tile_path(b, child, sizeof(child), "content", level + 1, cx, cy, "glb") ||
            !exists(child))
            continue;
        double e = 0.0;
        rc = read_child(child, ts, (uint32_t)proto, origin, &e, err, sizeof(err));
        if (rc) {
            fail_run(b, "%s: cannot merge %s", path, err);
            goto out;
        }
        child_error = e > child_error ? e : child_error;
    }
    /* The block's prototype holds its children's instances only. */
    const uint64_t input = instance_triangles(ts, (uint32_t)proto);
    if (input == 0) {
        atomic_fetch_add(&b->empty, 1);
        goto out;
    }
    if (up >= 2 && b->cell_lods && child_error > 0.0) {
        if (bake_block_of_cells(b, x, y, up, child_error, origin, path))
            goto out;   /* written, or the run failed */
    }
    rc = tw_tileset_finish(ts, BLOCK_CLUSTER_TRIANGLES);
    if (!rc)
        rc = tw_lods_build(ts, BLOCK_CLUSTER_TRIANGLES, NULL, NULL, &lods);
    if (rc) {
        fail_run(b, "%s: cannot simplify the block: %s", path, tw_error_to_str(rc));
        goto out;
    }
    /* Each level's blocks may add the error its children have (so the
     * errors double from level to level, as the blocks' sides do): the
     * coarsest simplification within it. Above the cells, whose error is
     * 0, the error of the first simplification of at most a quarter of the
     * input (else of the coarsest). */
    const float *err_of = lods.error + lods.first[0];
    double allowed = child_error;
    if (up == 1) {
        allowed = 0.0;
        for (uint32_t l = 1; l <= lods.count[0]; l++) {
            allowed = err_of[l - 1];
            if (4 * lods.levels->prototypes[lods.first[0] + l - 1].triangle_count <= input)
                break;
        }
    }
    write_block(b, ts, &lods, child_error, allowed, origin, path);
out:
    tw_lods_free(&lods);
    tw_tileset_destroy(ts);
}

static void *worker(void *user)
{
    struct bake *b = user;
    while (!atomic_load(&b->failed)) {
        const uint64_t n = atomic_fetch_add(&b->next, 1);
        if (n >= b->jobs)
            break;
        if (b->block_level < b->leaf)
            bake_block(b, n);
        else
            bake_cell(b, b->shard + n * b->shards);
        atomic_fetch_add(&b->done, 1);
    }
    return NULL;
}

/* Runs the step's jobs on the workers (b->block_level < b->leaf: the blocks
 * of that level; else this run's cells), the progress line on this thread. */
static int run_jobs(struct bake *b)
{
    const bool cells = b->block_level >= b->leaf;
    const uint64_t total = b->nx * b->ny;
    uint64_t mine;
    if (cells) {
        mine = total > b->shard ? (total - b->shard + b->shards - 1) / b->shards : 0;
    } else {
        uint64_t w, h;
        level_size(b, b->block_level, &w, &h);
        mine = w * h;
    }
    if (mine == 0)
        return 0;
    b->jobs = mine;
    atomic_store(&b->next, 0);
    atomic_store(&b->done, 0);
    atomic_store(&b->written, 0);
    atomic_store(&b->empty, 0);
    atomic_store(&b->skipped, 0);
    const char *unit = cells ? "cells" : "blocks";
    char label[1200];
    if (cells)
        snprintf(label, sizeof(label), "%s", b->out);
    else
        snprintf(label, sizeof(label), "%s level %u", b->out, b->block_level);
    struct tw_progress progress;
    tw_progress_init(&progress, label, (double)mine, unit, 0, b->cli.quiet);
    const double t0 = tw_progress_now_s();
    uint32_t n = b->cli.world.workers;
    if ((uint64_t)n > mine)
        n = (uint32_t)mine;
    pthread_t threads[64];
    uint32_t started = 0;
    for (; started < n; started++)
        if (pthread_create(&threads[started], NULL, worker, b) != 0)
            break;
    if (started == 0)
        worker(b);
    while (started > 0 && atomic_load(&b->done) < mine && !atomic_load(&b->failed)) {
        char note[64];
        const double s = tw_progress_now_s() - t0;
        snprintf(note, sizeof(note), "%.1f %s/s",
                 s > 0.0 ? (double)atomic_load(&b->done) / s : 0.0, unit);
        tw_progress_update(&progress, (double)atomic_load(&b->done), note);
        nanosleep(&(struct timespec){0, 20000000}, NULL);
    }
    for (uint32_t k = 0; k < started; k++)
        pthread_join(threads[k], NULL);
    tw_progress_update(&progress, (double)atomic_load(&b->done), NULL);
    tw_progress_finish(&progress);
    const double s = tw_progress_now_s() - t0;
    if (atomic_load(&b->failed)) {
        tw_cli_message(program, "bake: %s", b->message);
        return 1;
    }
    if (!b->cli.quiet) {
        const uint64_t written = atomic_load(&b->written);
        fprintf(stderr, "%s: baked %llu %s%s in %.1f s (%.1f %s/s, %u workers): %llu written, "
                "%llu empty, %llu already there\n", program, (unsigned long long)mine, unit,
                cells ? "" : label + strlen(b->out), s,
                s > 0.0 ? (double)(mine - atomic_load(&b->skipped)) / s : 0.0, unit, n,
                (unsigned long long)written, (unsigned long long)atomic_load(&b->empty),
                (unsigned long long)atomic_load(&b->skipped));
    }
    return 0;
}

/* ---- the bake's record ------------------------------------------------------- */

/* The rectangle as [I0, J0, I1, J1]. */
static json_object *cells_json(const struct bake *b)
{
    const int64_t corners[4] = {b->first.i, b->first.j, b->last.i, b->last.j};
    json_object *a = json_object_new_array();
    for (int k = 0; k < 4; k++)
        json_object_array_add(a, json_object_new_int64(corners[k]));
    return a;
}

static json_object *footprint_json(const struct bake *b)
{
    const double footprint[2] = {b->world.footprint[0], b->world.footprint[1]};
    return tw_tiles3d_doubles(footprint, 2);
}

/* DIR/bake.json: what decides the cells' files. A rerun, a shard or --finish
 * with other settings would mix two worlds in one folder: refused. --levels
 * is not among them: coarser levels may be added to a bake later. */
static int check_record(struct bake *b)
{
    json_object *rec = json_object_new_object();
    json_object_object_add(rec, "generator", json_object_new_string("tileworld bake"));
    json_object_object_add(rec, "tileset", json_object_new_string(b->cli.tileset));
    json_object_object_add(rec, "seed",
                           json_object_new_uint64(b->cli.world.selection.seed));
    json_object_object_add(rec, "repeat", json_object_new_int64(b->cli.world.selection.repeat));
    json_object_object_add(rec, "cells", cells_json(b));
    json_object_object_add(rec, "footprint", footprint_json(b));
    const char *text = json_object_to_json_string_ext(rec, JSON_C_TO_STRING_PRETTY |
                                                               JSON_C_TO_STRING_NOSLASHESCAPE);
    char path[4096], err[1200];
    snprintf(path, sizeof(path), "%s/bake.json", b->out);
    int rc = 0;
    if (tw_tiles3d_make_parents(path, err, sizeof(err))) {
        tw_cli_message(program, "--out %s: cannot bake there: %s", b->out, err);
        json_object_put(rec);
        return 2;
    }
    FILE *f = fopen(path, "rb");
    if (f) {
        char have[8192];
        const size_t n = fread(have, 1, sizeof(have) - 1, f);
        fclose(f);
        have[n] = '\0';
        if (strcmp(have, text) != 0 && !(n == strlen(text) + 1 && strncmp(have, text, n - 1) == 0)) {
            tw_cli_message(program, "--out %s: this folder holds a bake of other settings (its "
                           "bake.json); bake into another folder, or remove it", b->out);
            rc = 2;
        }
    } else if (errno != ENOENT) {
        tw_cli_message(program, "%s: %s", path, strerror(errno));
        rc = 1;
    } else {
        if (tw_tiles3d_write_text(path, text, err, sizeof(err))) {
            tw_cli_message(program, "--out %s: cannot bake there: %s", b->out, err);
            rc = 2;
        }
    }
    json_object_put(rec);
    return rc;
}

/* ---- --finish: subtrees and tileset.json ------------------------------------------ */

/* Availability of one level's tiles that overlap the rectangle: row-major,
 * w x h of them. */
struct level {
    uint64_t w, h;
    uint8_t *tile;      /* 1: available */
    uint8_t *content;   /* 1: a .glb is there */
};

static void set_bit(uint8_t *s, uint64_t b)
{
    s[b / 8] |= (uint8_t)(1u << (b % 8));
}

static int write_subtrees(struct bake *b, const struct level *lv, uint32_t subtree_levels,
                          uint64_t *subtree_count)
{
    const uint64_t tile_bits = tw_tiles3d_tiles_below(subtree_levels);
    const uint64_t child_bits = 1ull << (2 * subtree_levels);
    uint8_t *tiles = malloc((tile_bits + 7) / 8), *content = malloc((tile_bits + 7) / 8);
    uint8_t *children = malloc((child_bits + 7) / 8);
    char path[4096], err[1200];
    int rc = 0;
    if (!tiles || !content || !children) {
        tw_cli_message(program, "bake --finish: %s", tw_error_to_str(TW_ERR_NOMEM));
        rc = 1;
        goto out;
    }
    for (uint32_t root = 0; root <= b->leaf && !rc; root += subtree_levels) {
        const struct level *r = &lv[root];
        for (uint64_t sy = 0; sy < r->h && !rc; sy++)
            for (uint64_t sx = 0; sx < r->w && !rc; sx++) {
                /* Every subtree down from the root one whose root tile is
                 * available; the root subtree always. */
                if (root > 0 && !r->tile[sy * r->w + sx])
                    continue;
                memset(tiles, 0, (tile_bits + 7) / 8);
                memset(content, 0, (tile_bits + 7) / 8);
                memset(children, 0, (child_bits + 7) / 8);
                for (uint32_t l = 0; l <= subtree_levels; l++) {
                    const uint32_t level = root + l;
                    if (level > b->leaf)
                        break;
                    const struct level *q = &lv[level];
                    const uint64_t side = 1ull << l;
                    for (uint64_t ly = 0; ly < side; ly++) {
                        const uint64_t y = (sy << l) + ly;
                        if (y >= q->h)
                            break;
                        for (uint64_t lx = 0; lx < side; lx++) {
                            const uint64_t x = (sx << l) + lx;
                            if (x >= q->w)
                                break;
                            if (!q->tile[y * q->w + x])
                                continue;
                            const uint64_t m = tw_tiles3d_morton((uint32_t)lx, (uint32_t)ly);
                            if (l == subtree_levels) {
                                set_bit(children, m);
                                continue;
                            }
                            set_bit(tiles, tw_tiles3d_tiles_below(l) + m);
                            if (q->content[y * q->w + x])
                                set_bit(content, tw_tiles3d_tiles_below(l) + m);
                        }
                    }
                }
                const struct tw_tiles3d_subtree s = {subtree_levels, tiles, content, children};
                if (tile_path(b, path, sizeof(path), "subtrees", root, sx, sy, "subtree") ||
                    tw_tiles3d_make_parents(path, err, sizeof(err)) ||
                    tw_tiles3d_write_subtree(path, &s, err, sizeof(err))) {
                    tw_cli_message(program, "bake --finish: %s", err);
                    rc = 1;
                }
                (*subtree_count)++;
            }
    }
out:
    free(tiles);
    free(content);
    free(children);
    return rc;
}

/* The box that every cell's content lies in (cell-local). */
static const struct tw_box *world_bound(const struct bake *b)
{
    return b->world.tileset ? &b->world.tileset->common_box : &b->world.source->bound;
}

/* The height range (glTF y) that every cell's content lies in. */
static void height_range(const struct bake *b, double *lo, double *hi)
{
    const struct tw_box *box = world_bound(b);
    *lo = box->min[1];
    *hi = box->max[1];
    if (!(*hi > *lo)) {
        *lo -= 0.5;
        *hi += 0.5;
    }
}

static int write_tileset_json(struct bake *b, uint32_t subtree_levels, const double *level_error)
{
    const double w = b->world.footprint[0], d = b->world.footprint[1];
    const double side = (double)(1ull << b->leaf);
    double lo, hi;
    height_range(b, &lo, &hi);
    /* 3D Tiles is z-up and turns glTF's y-up content by +90 degrees about x:
     * glTF (x, y, z) is (x, -z, y) in the tileset's frame, so cells run along
     * +x (i) and -y (j). The box's second half-axis points along -y, so that
     * the quadtree's y follows j: tile (level, x, y) of the finest level is
     * the cell (I0 + x, J0 + y). */
    const double box[12] = {
        0.5 * side * w, -0.5 * side * d, 0.5 * (lo + hi),
        0.5 * side * w, 0.0, 0.0,
        0.0, -0.5 * side * d, 0.0,
        0.0, 0.0, 0.5 * (hi - lo),
    };
    /* The large numbers live here, in double: the corner of cell (I0, J0).
     * Column-major, as 3D Tiles wants. */
    const double transform[16] = {
        1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0,
        (double)b->first.i * w, 0.0 - (double)b->first.j * d, 0, 1,
    };
    /* Implicit tiling halves the error at every level: the level above the
     * cells gets the cell's diagonal (its tiles have no content: refine them
     * near the camera), the cells half of it. */
    const double diagonal = sqrt(w * w + d * d);
    double root_error = b->leaf > 0 ? diagonal * (double)(1ull << (b->leaf - 1)) : 0.0;
    /* A level with content of its own says its simplification's error: the
     * root's error is large enough that every level's is at least its own. */
    for (uint32_t l = 0; l < b->leaf; l++)
        if (level_error[l] * (double)(1ull << l) > root_error)
            root_error = level_error[l] * (double)(1ull << l);

    json_object *root = json_object_new_object();
    json_object *asset = json_object_new_object();
    json_object_object_add(asset, "version", json_object_new_string("1.1"));
    json_object_object_add(asset, "generator", json_object_new_string("tileworld bake"));
    json_object_object_add(root, "asset", asset);
    json_object_object_add(root, "geometricError",
                           json_object_new_double(b->leaf > 0 ? 2.0 * root_error : diagonal));
    json_object *tile = json_object_new_object();
    json_object_object_add(tile, "transform", tw_tiles3d_doubles(transform, 16));
    json_object *volume = json_object_new_object();
    json_object_object_add(volume, "box", tw_tiles3d_doubles(box, 12));
    json_object_object_add(tile, "boundingVolume", volume);
    json_object_object_add(tile, "geometricError", json_object_new_double(root_error));
    json_object_object_add(tile, "refine", json_object_new_string("REPLACE"));
    json_object *content = json_object_new_object();
    json_object_object_add(content, "uri", json_object_new_string("content/{level}/{x}/{y}.glb"));
    json_object_object_add(tile, "content", content);
    json_object *implicit = json_object_new_object();
    json_object_object_add(implicit, "subdivisionScheme", json_object_new_string("QUADTREE"));
    json_object_object_add(implicit, "subtreeLevels", json_object_new_int((int)subtree_levels));
    json_object_object_add(implicit, "availableLevels", json_object_new_int((int)b->leaf + 1));
    json_object *subtrees = json_object_new_object();
    json_object_object_add(subtrees, "uri",
                           json_object_new_string("subtrees/{level}/{x}/{y}.subtree"));
    json_object_object_add(implicit, "subtrees", subtrees);
    json_object_object_add(tile, "implicitTiling", implicit);
    json_object_object_add(root, "root", tile);
    /* What a tileworld client needs to map the tiles back to cells (the
     * library's 3D Tiles provider); generic clients ignore extras. */
    const struct tw_box *bound = world_bound(b);
    json_object *tw = json_object_new_object();
    json_object_object_add(tw, "footprint", footprint_json(b));
    json_object_object_add(tw, "cells", cells_json(b));
    const double bmin[3] = {bound->min[0], bound->min[1], bound->min[2]};
    const double bmax[3] = {bound->max[0], bound->max[1], bound->max[2]};
    json_object *bound_json = json_object_new_object();
    json_object_object_add(bound_json, "min", tw_tiles3d_doubles(bmin, 3));
    json_object_object_add(bound_json, "max", tw_tiles3d_doubles(bmax, 3));
    json_object_object_add(tw, "bound", bound_json);
    /* The coarser levels with content, for a tileworld client's far cells:
     * blocks of 2^k x 2^k cells from the rectangle's corner, each level's
     * largest error (3D Tiles' own per-level errors are the implicit
     * halving's, larger). */
    if (b->levels > 1) {
        json_object *levels = json_object_new_array();
        for (uint32_t k = 1; k < b->levels && k <= b->leaf; k++) {
            json_object *lv = json_object_new_object();
            json_object_object_add(lv, "cells", json_object_new_int64((int64_t)1 << k));
            json_object_object_add(lv, "geometricError",
                                   json_object_new_double(level_error[b->leaf - k]));
            json_object_array_add(levels, lv);
        }
        json_object_object_add(tw, "levels", levels);
    }
    json_object_object_add(tw, "tileset", json_object_new_string(b->cli.tileset));
    json_object_object_add(tw, "seed", json_object_new_uint64(b->cli.world.selection.seed));
    json_object *extras = json_object_new_object();
    json_object_object_add(extras, "tileworld", tw);
    json_object_object_add(root, "extras", extras);

    const char *text = json_object_to_json_string_ext(root, JSON_C_TO_STRING_PRETTY |
                                                                JSON_C_TO_STRING_NOSLASHESCAPE);
    char path[4096], err[1200];
    snprintf(path, sizeof(path), "%s/tileset.json", b->out);
    int rc = 0;
    if (tw_tiles3d_write_text(path, text, err, sizeof(err))) {
        tw_cli_message(program, "bake --finish: %s", err);
        rc = 1;
    }
    json_object_put(root);
    return rc;
}

static int finish(struct bake *b)
{
    struct level lv[MAX_LEAF_LEVEL + 1];
    memset(lv, 0, sizeof(lv));
    int rc = 0;
    /* A prototype tileset's blocks above the 2x2 ones are made from the
     * cells' levels (bake_block_of_cells): built once, before the workers
     * ask, and kept in the levels cache as the other programs keep them. */
    if (b->world.tileset && b->levels > 2) {
        struct tw_file_cache *store = NULL;
        char why[320];
        if (b->cli.world.levels_cache_dir &&
            tw_lods_store(b->cli.world.levels_cache_dir, 0, &store, why, sizeof(why)) != TW_OK)
            tw_cli_message(program, "levels of detail are built, not kept on disk: %s", why);
        rc = tw_lods_of_tileset(b->world.tileset, store, &b->cell_lods);
        if (rc) {
            tw_cli_message(program, "bake: cannot build the cells' levels of detail: %s",
                           tw_error_to_str(rc));
            return 1;
        }
    }
    /* The coarser levels, from the finest up: each from the files below it. */
    for (uint32_t k = 1; k < b->levels && !rc; k++) {
        b->block_level = b->leaf - k;
        rc = run_jobs(b);
    }
    if (rc)
        return rc;
    double level_error[MAX_LEAF_LEVEL + 1] = {0};
    uint64_t with_content = 0, subtrees = 0;
    char path[4096];
    for (uint32_t l = 0; l <= b->leaf; l++) {
        level_size(b, l, &lv[l].w, &lv[l].h);
        lv[l].tile = calloc(lv[l].w * lv[l].h, 1);
        lv[l].content = calloc(lv[l].w * lv[l].h, 1);
        if (!lv[l].tile || !lv[l].content) {
            tw_cli_message(program, "bake --finish: %s", tw_error_to_str(TW_ERR_NOMEM));
            rc = 1;
            goto out;
        }
    }
    /* The finest level from the files; above, a tile is there when one of
     * its children, or its own content, is. */
    for (uint32_t l = b->leaf + 1; l-- > 0;) {
        struct level *q = &lv[l];
        const bool has_content = b->leaf - l < b->levels;
        for (uint64_t y = 0; y < q->h; y++)
            for (uint64_t x = 0; x < q->w; x++) {
                uint8_t c = 0;
                if (has_content) {
                    if (tile_path(b, path, sizeof(path), "content", l, x, y, "glb")) {
                        tw_cli_message(program, "--out %s: %s", b->out, strerror(ENAMETOOLONG));
                        rc = 2;
                        goto out;
                    }
                    c = exists(path);
                    double e = 0.0;
                    char err[1200];
                    if (c && l < b->leaf && tw_tiles3d_read_glb_error(path, &e, err, sizeof(err))) {
                        tw_cli_message(program, "bake --finish: %s", err);
                        rc = 1;
                        goto out;
                    }
                    level_error[l] = e > level_error[l] ? e : level_error[l];
                }
                uint8_t t = c;
                if (l < b->leaf) {
                    const struct level *d = &lv[l + 1];
                    for (uint64_t k = 0; k < 4 && !t; k++) {
                        const uint64_t cx = 2 * x + (k & 1), cy = 2 * y + (k >> 1);
                        t = cx < d->w && cy < d->h && d->tile[cy * d->w + cx];
                    }
                }
                q->content[y * q->w + x] = c;
                q->tile[y * q->w + x] = t;
                with_content += c && l == b->leaf;
            }
    }
    const uint32_t subtree_levels = b->leaf + 1 < SUBTREE_LEVELS ? b->leaf + 1 : SUBTREE_LEVELS;
    rc = write_subtrees(b, lv, subtree_levels, &subtrees);
    if (!rc)
        rc = write_tileset_json(b, subtree_levels, level_error);
    if (!rc && !b->cli.quiet)
        fprintf(stderr, "%s: wrote %s/tileset.json: %llu of %llu cells with content, %u levels, "
                "%llu subtree files\n", program, b->out, (unsigned long long)with_content,
                (unsigned long long)(b->nx * b->ny), b->leaf + 1, (unsigned long long)subtrees);
out:
    for (uint32_t l = 0; l <= b->leaf; l++) {
        free(lv[l].tile);
        free(lv[l].content);
    }
    return rc;
}

int tw_bake_main(int argc, char **argv)
{
    struct bake *b = calloc(1, sizeof(*b));
    if (!b) {
        fprintf(stderr, "%s: bake: out of memory\n", program);
        return 1;
    }
    parse_options(argc, argv, b);
    pthread_mutex_init(&b->lock, NULL);
    b->log = (struct tw_log){tw_cli_log, &b->cli};
    tw_cli_world_load(&b->cli, 0, &b->log, &b->world);
    int rc = check_record(b);
    if (!rc && !b->finish) {
        b->block_level = b->leaf;
        rc = run_jobs(b);
    }
    if (!rc && !b->shard_given)
        rc = finish(b);
    tw_cli_world_finish(&b->world);
    pthread_mutex_destroy(&b->lock);
    free(b);
    return rc;
}
