/* The forest's stand generator (tilesets-private.h), which the forest, the
 * hybrid and forest-gen share: materials, and stands of trees, rocks, logs
 * and undergrowth patches placed from the models of trees.c.
 *
 * A forest hides things only through many weak occluders together: every
 * tree is small next to the tile (a few metres wide, thin trunk, gaps
 * between and inside canopies), but a stand of 150 to 300 of them closes up
 * along a line of sight of a few tiles. Every tree is an instance of its
 * canopy mesh, plus one of its trunk mesh where the canopy does not hide
 * it, turned about y and scaled. Undergrowth patches tile the stand in
 * quarter turns, so the instance count stays a few hundred.
 *
 * Placement keeps two promises that the tests check: every vertex stays
 * inside the stand's rectangle (so inside the footprint), and within the
 * walking band along the tile borders nothing stands between 0.05 m and
 * TW_FOREST_HEADROOM above the ground. Every candidate placement of a tree
 * is tested exactly against its model's profile. */
#include "tilesets/mesh-builder.h"
#include "tilesets/shapes.h"
#include "tilesets/tilesets-private.h"
#include "tilesets/trees.h"
#include "tiles/array.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- materials ------------------------------------------------------------------ */

enum material {
    MAT_BARK,
    MAT_BIRCH_BARK,
    MAT_SPRUCE,
    MAT_SPRUCE_DARK,
    MAT_FIR,
    MAT_PINE,
    MAT_BEECH,
    MAT_BEECH_LIGHT,
    MAT_BIRCH_LEAVES,
    MAT_BUSH,
    MAT_FERN,
    MAT_ROCK,
    MAT_FLOOR,
    MAT_COUNT,
};

static const float material_colours[MAT_COUNT][4] = {
    [MAT_BARK] = {0.42f, 0.31f, 0.21f, 1.0f},
    [MAT_BIRCH_BARK] = {0.86f, 0.84f, 0.78f, 1.0f},
    [MAT_SPRUCE] = {0.17f, 0.38f, 0.22f, 1.0f},
    [MAT_SPRUCE_DARK] = {0.13f, 0.31f, 0.20f, 1.0f},
    [MAT_FIR] = {0.20f, 0.43f, 0.25f, 1.0f},
    [MAT_PINE] = {0.29f, 0.44f, 0.19f, 1.0f},
    [MAT_BEECH] = {0.32f, 0.54f, 0.18f, 1.0f},
    [MAT_BEECH_LIGHT] = {0.43f, 0.62f, 0.21f, 1.0f},
    [MAT_BIRCH_LEAVES] = {0.55f, 0.70f, 0.27f, 1.0f},
    [MAT_BUSH] = {0.28f, 0.47f, 0.16f, 1.0f},
    [MAT_FERN] = {0.44f, 0.66f, 0.22f, 1.0f},
    [MAT_ROCK] = {0.58f, 0.57f, 0.54f, 1.0f},
    [MAT_FLOOR] = {0.40f, 0.32f, 0.21f, 1.0f},
};

/* The trail along the borders (tw_forest_stands_add_floor()); the hybrid has none. */
static const float trail_colour[4] = {0.62f, 0.53f, 0.38f, 1.0f};

/* ---- placement ranges -------------------------------------------------------------- */

/* The ranges that placements scale meshes by; tw_forest_stands_max_top()
 * bounds heights with their upper ends. */
static const float tree_scale[2] = {0.85f, 1.15f};      /* horizontal, and vertical with: */
static const float tree_stretch[2] = {0.92f, 1.08f};    /* vertical over horizontal */
static const float outcrop_size[2] = {3.0f, 4.6f};
static const float boulder_size[2] = {0.5f, 1.1f}, boulder_spread[2] = {0.6f, 2.0f};
static const float rock_stretch[2] = {0.85f, 1.15f};    /* vertical over horizontal */
static const float log_scale[2] = {0.6f, 1.1f};

/* ---- the generator's state ------------------------------------------------------------ */

/* Something placed in a stand: a tree, a rock or a piece of a log. */
struct placed {
    float x, z;
    float crown;    /* crown radius for spacing between trees; 0 for rocks */
    float base;     /* radius of what stands on the ground */
};

struct tw_forest_stands {
    struct tw_tileset *ts;
    struct tw_forest_settings set;
    uint32_t mat[MAT_COUNT];
    struct tw_forest_models models;

    struct tw_mesh_builder builder;
    struct placed *placed;
    uint32_t placed_count, placed_cap;

    /* Made by the first tw_forest_stands_add_floor(). */
    bool has_floor;
    float floor_band;
    uint32_t floor_mesh, trail_mesh, trail_material;

    /* A generator made by tw_forest_stands_create_from(): the mesh indices
     * of models are source's, and local maps each to its copy in ts,
     * not_copied until first placed. NULL: they are ts's own. */
    const struct tw_tileset *source;
    uint32_t *local;
};

static const uint32_t not_copied = UINT32_MAX;

/* The tileset that holds the generator's meshes. */
static const struct tw_tileset *mesh_home(const struct tw_forest_stands *f)
{
    return f->source ? f->source : f->ts;
}

/* The index in ts of the generator's mesh, copied there on first use. */
static int placed_mesh(struct tw_forest_stands *f, uint32_t mesh, uint32_t *out)
{
    if (!f->source) {
        *out = mesh;
        return TW_OK;
    }
    if (f->local[mesh] == not_copied) {
        const struct tw_mesh *m = &f->source->meshes[mesh];
        const int index = tw_tileset_add_mesh(f->ts, m->positions, m->normals, m->vertex_count,
                                              m->indices, m->triangle_count);
        if (index < 0)
            return index;
        f->local[mesh] = (uint32_t)index;
    }
    *out = f->local[mesh];
    return TW_OK;
}

static int add_materials(struct tw_forest_stands *f)
{
    for (int k = 0; k < MAT_COUNT; k++) {
        const int m = tw_tileset_add_material(f->ts, material_colours[k]);
        if (m < 0)
            return m;
        f->mat[k] = (uint32_t)m;
    }
    return TW_OK;
}

/* ---- stands ------------------------------------------------------------------------ */

struct stand_recipe {
    const char *name;
    float trees;                    /* per 6400 m^2 at density 1 */
    float mix[TW_FOREST_SPECIES_COUNT];       /* species weights */
    float big;                      /* share of the largest size */
    float spacing;                  /* trunks at least spacing x (crown_a + crown_b) apart */
    uint32_t boulders, outcrops, logs;
    float clearing;                 /* glade radius over the area's smaller side; 0: none */
    uint32_t undergrowth;           /* patch level, 0 to TW_PATCH_LEVELS - 1 */
    float fern_share;               /* share of fern patches */
};

static const struct stand_recipe stand_recipes[TW_FOREST_STAND_KIND_COUNT] = {
    [TW_FOREST_STAND_SPRUCE] = {"spruce", 240.0f, {0.74f, 0.14f, 0.04f, 0.02f, 0.06f}, 0.3f, 0.42f,
                                4, 0, 4, 0.0f, 0, 0.5f},
    [TW_FOREST_STAND_MIXED] = {"mixed", 195.0f, {0.36f, 0.16f, 0.12f, 0.22f, 0.14f}, 0.35f, 0.42f,
                               6, 0, 4, 0.0f, 1, 0.5f},
    [TW_FOREST_STAND_BEECH] = {"beech", 175.0f, {0.25f, 0.06f, 0.0f, 0.55f, 0.14f}, 0.6f, 0.38f,
                               5, 0, 5, 0.0f, 0, 0.6f},
    [TW_FOREST_STAND_BIRCH] = {"birch", 180.0f, {0.14f, 0.06f, 0.18f, 0.04f, 0.58f}, 0.45f, 0.45f,
                               5, 0, 3, 0.0f, 2, 0.6f},
    [TW_FOREST_STAND_THIN] = {"thin", 150.0f, {0.22f, 0.14f, 0.30f, 0.14f, 0.20f}, 0.45f, 0.6f,
                              8, 0, 6, 0.0f, 2, 0.5f},
    [TW_FOREST_STAND_CLEARING] = {"clearing", 175.0f, {0.40f, 0.14f, 0.10f, 0.20f, 0.16f}, 0.35f,
                                  0.42f, 8, 1, 3, 0.24f, 1, 0.7f},
    [TW_FOREST_STAND_ROCKY] = {"rocky", 160.0f, {0.32f, 0.10f, 0.38f, 0.04f, 0.16f}, 0.4f, 0.5f,
                               42, 3, 2, 0.0f, 1, 0.4f},
};

const char *tw_forest_stand_name(enum tw_forest_stand_kind kind)
{
    return (unsigned)kind < TW_FOREST_STAND_KIND_COUNT ? stand_recipes[kind].name : "unknown";
}

static int push_placed(struct tw_forest_stands *f, float x, float z, float crown, float base)
{
    const int err = tw_array_reserve_u32((void **)&f->placed, &f->placed_cap,
                                         f->placed_count + 1, sizeof(*f->placed), 256);
    if (err)
        return err;
    f->placed[f->placed_count++] = (struct placed){x, z, crown, base};
    return TW_OK;
}

/* Whether a footprint of radius base at (x, z), of a tree with crown radius
 * crown (0: not a tree), keeps its distance from everything placed. */
static bool spot_free(const struct tw_forest_stands *f, float x, float z, float crown,
                      float base, float spacing)
{
    for (uint32_t k = 0; k < f->placed_count; k++) {
        const struct placed *p = &f->placed[k];
        const float dx = p->x - x, dz = p->z - z, d2 = dx * dx + dz * dz;
        float need = base + p->base + 0.3f;
        if (crown > 0.0f && p->crown > 0.0f)
            need = fmaxf(need, spacing * (crown + p->crown));
        if (d2 < need * need)
            return false;
    }
    return true;
}

/* Distance from (x, z) to the nearest tile border line. */
static float border_distance(const struct tw_forest_stands *f, float x, float z)
{
    const float w = f->ts->footprint[0], d = f->ts->footprint[1];
    return fminf(fminf(x, w - x), fminf(z, d - z));
}

/* Whether something of full reach `reach` and low reach `low` (what comes
 * below the headroom) fits at (x, z): inside the area, out of the band. */
static bool fits(const struct tw_forest_stands *f, const struct tw_forest_area *area, float x,
                 float z, float reach, float low)
{
    const float eps = 0.02f;
    if (x - reach < area->rect[0] + eps || x + reach > area->rect[2] - eps ||
        z - reach < area->rect[1] + eps || z + reach > area->rect[3] - eps)
        return false;
    return !(area->band > 0.0f && low > 0.0f && border_distance(f, x, z) - low < area->band + eps);
}

static bool in_clearing(const float clearing[3], float x, float z, float r)
{
    const float dx = x - clearing[0], dz = z - clearing[1], d = clearing[2] + r;
    return clearing[2] > 0.0f && dx * dx + dz * dz < d * d;
}

static int add_turned(struct tw_forest_stands *f, uint32_t proto, uint32_t mesh,
                      uint32_t material, float x, float y, float z, float angle, float sxz,
                      float sy)
{
    const float co = sxz * cosf(angle), si = sxz * sinf(angle);
    const float m[12] = {co, 0.0f, si, x, 0.0f, sy, 0.0f, y, -si, 0.0f, co, z};
    uint32_t local = 0;
    const int err = placed_mesh(f, mesh, &local);
    if (err)
        return err;
    const int k = tw_tileset_add_instance(f->ts, proto, local, material, m);
    return k < 0 ? k : TW_OK;
}

static uint32_t pick_weighted(struct tw_rng *r, const float *weights, uint32_t n)
{
    float total = 0.0f;
    for (uint32_t k = 0; k < n; k++)
        total += weights[k];
    float x = tw_rng_float(r) * total;
    for (uint32_t k = 0; k < n; k++) {
        if (x < weights[k])
            return k;
        x -= weights[k];
    }
    return n - 1;
}

/* The model of species: sizes in order, the largest with probability big,
 * the others evenly. */
static uint32_t pick_model(struct tw_rng *r, uint32_t species, float big)
{
    uint32_t first, count;
    tw_tree_species_models(species, &first, &count);
    if (count <= 1 || tw_rng_chance(r, big))
        return first + count - 1;
    return first + tw_rng_below(r, count - 1);
}

static uint32_t canopy_material(const struct tw_forest_stands *f, struct tw_rng *r,
                                uint32_t species)
{
    switch (species) {
    case TW_FOREST_SPECIES_SPRUCE:
        return f->mat[tw_rng_chance(r, 0.5f) ? MAT_SPRUCE : MAT_SPRUCE_DARK];
    case TW_FOREST_SPECIES_FIR: return f->mat[MAT_FIR];
    case TW_FOREST_SPECIES_PINE: return f->mat[MAT_PINE];
    case TW_FOREST_SPECIES_BEECH:
        return f->mat[tw_rng_chance(r, 0.6f) ? MAT_BEECH : MAT_BEECH_LIGHT];
    default: return f->mat[MAT_BIRCH_LEAVES];
    }
}

static int place_rocks(struct tw_forest_stands *f, uint32_t proto, struct tw_rng *r,
                       const struct stand_recipe *sr, const struct tw_forest_area *area,
                       const float clearing[3], float scale)
{
    const uint32_t boulders = (uint32_t)floorf((float)sr->boulders * scale + 0.5f);
    const uint32_t total = sr->outcrops + boulders;
    int err = TW_OK;
    for (uint32_t k = 0; k < total && !err; k++) {
        const bool outcrop = k < sr->outcrops;
        for (int attempt = 0; attempt < 60; attempt++) {
            const uint32_t shape = outcrop ? TW_ROCK_SHAPES - 1 : tw_rng_below(r, TW_ROCK_SHAPES);
            const float size = outcrop ? tw_rng_range(r, outcrop_size[0], outcrop_size[1])
                                       : tw_rng_range(r, boulder_size[0], boulder_size[1]) *
                                             tw_rng_range(r, boulder_spread[0], boulder_spread[1]);
            const float sy = size * tw_rng_range(r, rock_stretch[0], rock_stretch[1]);
            const float reach = f->models.rock_reach[shape] * size;
            const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
            const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
            const float angle = tw_rng_range(r, 0.0f, TW_TAU);
            if (!fits(f, area, x, z, reach, reach))
                continue;
            /* Outcrops stay out of the glade; boulders may lie in it. */
            if (outcrop && in_clearing(clearing, x, z, reach))
                continue;
            if (!spot_free(f, x, z, 0.0f, reach, 0.0f))
                continue;
            err = add_turned(f, proto, f->models.rock[shape], f->mat[MAT_ROCK], x,
                             area->ground_y, z, angle, size, sy);
            if (!err)
                err = push_placed(f, x, z, 0.0f, reach);
            break;
        }
    }
    return err;
}

static int place_logs(struct tw_forest_stands *f, uint32_t proto, struct tw_rng *r,
                      const struct stand_recipe *sr, const struct tw_forest_area *area,
                      float scale)
{
    const uint32_t logs = (uint32_t)floorf((float)sr->logs * scale + 0.5f);
    int err = TW_OK;
    for (uint32_t k = 0; k < logs && !err; k++) {
        for (int attempt = 0; attempt < 60; attempt++) {
            const float s = tw_rng_range(r, log_scale[0], log_scale[1]);
            const float half = 0.5f * f->models.log_length * s, rad = f->models.log_radius * s;
            const float reach = sqrtf(half * half + rad * rad);
            const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
            const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
            const float angle = tw_rng_range(r, 0.0f, TW_TAU);
            if (!fits(f, area, x, z, reach, reach))
                continue;
            /* Three discs along the log keep it off trunks and rocks. */
            const float dx = cosf(angle), dz = -sinf(angle);
            bool ok = true;
            for (int j = -1; j <= 1 && ok; j++) {
                const float along = (float)j * 0.66f * half;
                ok = spot_free(f, x + along * dx, z + along * dz, 0.0f, 0.34f * half + rad, 0.0f);
            }
            if (!ok)
                continue;
            err = add_turned(f, proto, f->models.log, f->mat[MAT_BARK], x, area->ground_y, z,
                             angle, s, s);
            for (int j = -1; j <= 1 && !err; j++)
                err = push_placed(f, x + (float)j * 0.66f * half * dx,
                                  z + (float)j * 0.66f * half * dz, 0.0f, 0.34f * half + rad);
            break;
        }
    }
    return err;
}

static int place_trees(struct tw_forest_stands *f, uint32_t proto, struct tw_rng *r,
                       const struct stand_recipe *sr, const struct tw_forest_area *area,
                       const float clearing[3], float scale)
{
    const uint32_t target = (uint32_t)floorf(sr->trees * scale * f->set.density + 0.5f);
    uint32_t placed = 0;
    int err = TW_OK;
    for (uint32_t attempt = 0; placed < target && attempt < 60 * target && !err; attempt++) {
        const uint32_t species = pick_weighted(r, sr->mix, TW_FOREST_SPECIES_COUNT);
        const uint32_t model = pick_model(r, species, sr->big);
        const struct tw_tree_model *m = &f->models.trees[model];
        const float sxz = tw_rng_range(r, tree_scale[0], tree_scale[1]);
        const float sy = sxz * tw_rng_range(r, tree_stretch[0], tree_stretch[1]);
        const float angle = tw_rng_range(r, 0.0f, TW_TAU);
        const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
        const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
        const float reach = m->reach * sxz;
        /* A sapling or two may stand at the glade's edge, nothing inside. */
        if (in_clearing(clearing, x, z, -0.3f * clearing[2]) ||
            (in_clearing(clearing, x, z, 0.0f) && model != 0))
            continue;
        const float low = tw_tree_reach_below(m, TW_FOREST_HEADROOM, sxz, sy);
        if (!fits(f, area, x, z, reach, low))
            continue;
        /* Crowns may interleave (spruce skirts do); trunks keep clear of
         * rocks and logs. */
        const float crown = tw_tree_recipes[model].radius * sxz;
        const float base = 1.5f * tw_tree_recipes[model].trunk_radius * sxz;
        if (!spot_free(f, x, z, crown, base, sr->spacing))
            continue;
        err = add_turned(f, proto, m->canopy, canopy_material(f, r, species), x, area->ground_y,
                         z, angle, sxz, sy);
        const bool birch = species == TW_FOREST_SPECIES_BIRCH;
        if (!err && m->trunk != TW_TREE_NO_TRUNK)
            err = add_turned(f, proto, m->trunk, f->mat[birch ? MAT_BIRCH_BARK : MAT_BARK], x,
                             area->ground_y, z, angle, sxz, sy);
        if (!err)
            err = push_placed(f, x, z, crown, base);
        placed++;
    }
    return err;
}

/* Undergrowth patches on a grid of patch_size squares centred in the area,
 * each a bush or fern patch in a quarter turn. A patch that the walking
 * band would cut is left out. */
static int place_undergrowth(struct tw_forest_stands *f, uint32_t proto, struct tw_rng *r,
                             const struct stand_recipe *sr, const struct tw_forest_area *area,
                             const float clearing[3])
{
    const float p = f->models.patch_size;
    const float aw = area->rect[2] - area->rect[0], ad = area->rect[3] - area->rect[1];
    const uint32_t nx = (uint32_t)floorf(aw / p), nz = (uint32_t)floorf(ad / p);
    const float x0 = area->rect[0] + 0.5f * (aw - (float)nx * p);
    const float z0 = area->rect[1] + 0.5f * (ad - (float)nz * p);
    static const float turn_cos[4] = {1.0f, 0.0f, -1.0f, 0.0f};
    static const float turn_sin[4] = {0.0f, 1.0f, 0.0f, -1.0f};
    int err = TW_OK;
    for (uint32_t j = 0; j < nz && !err; j++) {
        for (uint32_t i = 0; i < nx && !err; i++) {
            const float cx = x0 + p * ((float)i + 0.5f), cz = z0 + p * ((float)j + 0.5f);
            const bool fern = tw_rng_chance(r, sr->fern_share) || in_clearing(clearing, cx, cz, 0.0f);
            int level = (int)sr->undergrowth + (int)tw_rng_below(r, 3) - 1;
            if (in_clearing(clearing, cx, cz, 0.0f))
                level = TW_PATCH_LEVELS - 1;
            level = level < 0 ? 0 : level >= TW_PATCH_LEVELS ? TW_PATCH_LEVELS - 1 : level;
            const uint32_t k = tw_rng_below(r, 4);
            if (area->band > 0.0f &&
                border_distance(f, cx, cz) - 0.5f * p + TW_PATCH_MARGIN < area->band)
                continue;
            const float m[12] = {turn_cos[k], 0.0f, turn_sin[k], cx,
                                 0.0f, 1.0f, 0.0f, area->ground_y,
                                 -turn_sin[k], 0.0f, turn_cos[k], cz};
            uint32_t mesh = fern ? f->models.fern_patch[level] : f->models.bush_patch[level];
            if ((err = placed_mesh(f, mesh, &mesh)))
                break;
            const int index = tw_tileset_add_instance(
                f->ts, proto, mesh, f->mat[fern ? MAT_FERN : MAT_BUSH], m);
            err = index < 0 ? index : TW_OK;
        }
    }
    return err;
}

static bool stand_args_valid(const struct tw_forest_stands *f, uint32_t proto,
                             enum tw_forest_stand_kind kind, const struct tw_forest_area *area)
{
    return f && area && proto < f->ts->prototype_count &&
           (unsigned)kind < TW_FOREST_STAND_KIND_COUNT && area->rect[2] > area->rect[0] &&
           area->rect[3] > area->rect[1] && area->band >= 0.0f;
}

static int add_stand(struct tw_forest_stands *f, uint32_t proto, const struct stand_recipe *sr,
                     uint64_t stream, const struct tw_forest_area *area)
{
    struct tw_rng r = {stream};
    const float aw = area->rect[2] - area->rect[0], ad = area->rect[3] - area->rect[1];
    const float scale = aw * ad / 6400.0f;
    f->placed_count = 0;

    float clearing[3] = {0.0f, 0.0f, 0.0f};
    if (sr->clearing > 0.0f) {
        const float side = fminf(aw, ad);
        clearing[2] = sr->clearing * side;
        clearing[0] = area->rect[0] + 0.5f * aw + tw_rng_range(&r, -0.08f, 0.08f) * side;
        clearing[1] = area->rect[1] + 0.5f * ad + tw_rng_range(&r, -0.08f, 0.08f) * side;
    }
    int err = place_rocks(f, proto, &r, sr, area, clearing, scale);
    if (!err)
        err = place_trees(f, proto, &r, sr, area, clearing, scale);
    if (!err)
        err = place_logs(f, proto, &r, sr, area, scale);
    if (!err)
        err = place_undergrowth(f, proto, &r, sr, area, clearing);
    return err;
}

int tw_forest_stands_add(struct tw_forest_stands *f, uint32_t proto,
                         enum tw_forest_stand_kind kind, uint64_t stream,
                         const struct tw_forest_area *area)
{
    if (!stand_args_valid(f, proto, kind, area))
        return TW_ERR_INVALID;
    return add_stand(f, proto, &stand_recipes[kind], stream, area);
}

uint32_t tw_forest_stands_floor_material(const struct tw_forest_stands *f)
{
    return f->mat[MAT_FLOOR];
}

int tw_forest_stands_create(struct tw_tileset *ts, uint64_t seed,
                            const struct tw_forest_settings *settings,
                            struct tw_forest_stands **out)
{
    if (!ts || !settings || !out || ts->finished)
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_forest_stands *f = calloc(1, sizeof(*f));
    if (!f)
        return TW_ERR_NOMEM;
    f->ts = ts;
    f->set = *settings;
    int err = add_materials(f);
    if (!err)
        err = tw_forest_models_build(&f->models, &f->builder, ts, seed);
    if (err) {
        tw_forest_stands_destroy(f);
        return err;
    }
    *out = f;
    return TW_OK;
}

void tw_forest_stands_destroy(struct tw_forest_stands *f)
{
    if (!f)
        return;
    tw_forest_models_finish(&f->models);
    tw_mesh_builder_release(&f->builder);
    free(f->placed);
    free(f->local);
    free(f);
}

/* ---- the floor and the trail ------------------------------------------------------- */

/* The forest floor, and the trail along the borders as a pinwheel of four
 * strips (no overlaps), a hair above it. */
static int build_ground(struct tw_forest_stands *f, float band, uint32_t *floor_mesh,
                        uint32_t *trail_mesh)
{
    struct tw_mesh_builder *b = &f->builder;
    const float w = f->ts->footprint[0], d = f->ts->footprint[1], up[3] = {0, 1, 0};
    tw_mesh_builder_reset(b, false);
    {
        const float p0[3] = {0, 0, 0}, p1[3] = {w, 0, 0}, p2[3] = {w, 0, d}, p3[3] = {0, 0, d};
        tw_shape_triangle(b, p0, p1, p2, up);
        tw_shape_triangle(b, p0, p2, p3, up);
    }
    int err = tw_mesh_builder_add_to(b, f->ts, floor_mesh);
    if (err)
        return err;
    tw_mesh_builder_reset(b, false);
    const float y = 0.01f;
    const float strips[4][4] = {
        {0.0f, 0.0f, w - band, band}, {w - band, 0.0f, w, d - band},
        {band, d - band, w, d}, {0.0f, band, band, d},
    };
    for (int k = 0; k < 4; k++) {
        const float *q = strips[k];
        const float p0[3] = {q[0], y, q[1]}, p1[3] = {q[2], y, q[1]};
        const float p2[3] = {q[2], y, q[3]}, p3[3] = {q[0], y, q[3]};
        tw_shape_triangle(b, p0, p1, p2, up);
        tw_shape_triangle(b, p0, p2, p3, up);
    }
    return tw_mesh_builder_add_to(b, f->ts, trail_mesh);
}

/* ---- stands for generated tiles (tilesets-private.h) --------------------------------- */

int tw_forest_stands_create_from(const struct tw_forest_stands *model, struct tw_tileset *ts,
                                 struct tw_forest_stands **out)
{
    if (!model || !ts || !out || ts->finished || model->source ||
        ts->footprint[0] != model->ts->footprint[0] ||
        ts->footprint[1] != model->ts->footprint[1])
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_forest_stands *f = calloc(1, sizeof(*f));
    if (!f)
        return TW_ERR_NOMEM;
    const struct tw_tileset *from = model->ts;
    f->ts = ts;
    f->set = model->set;
    f->source = from;
    int err = tw_forest_models_copy(&f->models, &model->models);
    if (!err &&
        !(f->local = malloc(sizeof(*f->local) * (from->mesh_count ? from->mesh_count : 1))))
        err = TW_ERR_NOMEM;
    for (uint32_t k = 0; !err && k < from->mesh_count; k++)
        f->local[k] = not_copied;
    for (int k = 0; k < MAT_COUNT && !err; k++) {
        const int m = tw_tileset_add_material(ts, from->materials[model->mat[k]].base_color);
        err = m < 0 ? m : TW_OK;
        f->mat[k] = (uint32_t)m;
    }
    if (err) {
        tw_forest_stands_destroy(f);
        return err;
    }
    *out = f;
    return TW_OK;
}

int tw_forest_stands_add_floor(struct tw_forest_stands *f, uint32_t proto, float band)
{
    if (!f || proto >= f->ts->prototype_count || !isfinite(band) || !(band > 0.0f) ||
        !(2.0f * band < fminf(f->ts->footprint[0], f->ts->footprint[1])) ||
        (f->has_floor && band != f->floor_band))
        return TW_ERR_INVALID;
    if (!f->has_floor) {
        const int material = tw_tileset_add_material(f->ts, trail_colour);
        if (material < 0)
            return material;
        f->trail_material = (uint32_t)material;
        const int err = build_ground(f, band, &f->floor_mesh, &f->trail_mesh);
        if (err)
            return err;
        f->has_floor = true;
        f->floor_band = band;
    }
    int k = tw_tileset_add_instance(f->ts, proto, f->floor_mesh, f->mat[MAT_FLOOR], NULL);
    if (k >= 0)
        k = tw_tileset_add_instance(f->ts, proto, f->trail_mesh, f->trail_material, NULL);
    return k < 0 ? k : TW_OK;
}

void tw_forest_stand_mix(enum tw_forest_stand_kind kind, float mix[TW_FOREST_SPECIES_COUNT])
{
    const enum tw_forest_stand_kind k =
        (unsigned)kind < TW_FOREST_STAND_KIND_COUNT ? kind : TW_FOREST_STAND_MIXED;
    memcpy(mix, stand_recipes[k].mix, sizeof(stand_recipes[k].mix));
}

static bool mix_valid(const float mix[TW_FOREST_SPECIES_COUNT])
{
    float total = 0.0f;
    for (int s = 0; s < TW_FOREST_SPECIES_COUNT; s++) {
        if (!isfinite(mix[s]) || !(mix[s] >= 0.0f))
            return false;
        total += mix[s];
    }
    return total > 0.0f && isfinite(total);
}

float tw_forest_stands_tree_triangles(const struct tw_forest_stands *f,
                                      enum tw_forest_stand_kind kind,
                                      const float mix[TW_FOREST_SPECIES_COUNT])
{
    if (!f || (unsigned)kind >= TW_FOREST_STAND_KIND_COUNT || !mix || !mix_valid(mix))
        return 0.0f;
    const float big = stand_recipes[kind].big;
    double total = 0.0, weights = 0.0;
    for (uint32_t s = 0; s < TW_FOREST_SPECIES_COUNT; s++) {
        uint32_t first, count;
        tw_tree_species_models(s, &first, &count);
        /* pick_model(): the largest with probability big, the others
         * evenly. */
        double per_tree = 0.0;
        for (uint32_t k = first; k < first + count; k++) {
            const struct tw_tree_model *m = &f->models.trees[k];
            const double p = count <= 1 ? 1.0 : k + 1 == first + count ? big
                                                                       : (1.0 - big) / (count - 1);
            double triangles = mesh_home(f)->meshes[m->canopy].triangle_count;
            if (m->trunk != TW_TREE_NO_TRUNK)
                triangles += mesh_home(f)->meshes[m->trunk].triangle_count;
            per_tree += p * triangles;
        }
        total += mix[s] * per_tree;
        weights += mix[s];
    }
    return (float)(total / weights);
}

int tw_forest_stands_add_varied(struct tw_forest_stands *f, uint32_t proto,
                                enum tw_forest_stand_kind kind, uint64_t stream,
                                const struct tw_forest_area *area,
                                const float mix[TW_FOREST_SPECIES_COUNT], float tree_scale_by)
{
    if (!stand_args_valid(f, proto, kind, area) || !mix || !mix_valid(mix) ||
        !isfinite(tree_scale_by) || !(tree_scale_by > 0.0f) || !(tree_scale_by <= 4.0f))
        return TW_ERR_INVALID;
    struct stand_recipe sr = stand_recipes[kind];
    memcpy(sr.mix, mix, sizeof(sr.mix));
    sr.trees *= tree_scale_by;
    return add_stand(f, proto, &sr, stream, area);
}

/* Every placement scales a mesh vertically by at most the product of its
 * ranges' upper ends (tw_rng_range() may round to the upper end, and the
 * products and the transform round once more each: 1e-5 covers that). */
float tw_forest_stands_max_top(const struct tw_forest_stands *f)
{
    if (!f)
        return 0.0f;
    const struct tw_mesh *meshes = mesh_home(f)->meshes;
    const float tree = tree_scale[1] * tree_stretch[1];
    float top = 0.0f;
    for (uint32_t k = 0; k < TW_TREE_MODELS; k++) {
        top = fmaxf(top, tree * meshes[f->models.trees[k].canopy].box.max[1]);
        if (f->models.trees[k].trunk != TW_TREE_NO_TRUNK)
            top = fmaxf(top, tree * meshes[f->models.trees[k].trunk].box.max[1]);
    }
    const float boulder = boulder_size[1] * boulder_spread[1] * rock_stretch[1];
    for (uint32_t k = 0; k < TW_ROCK_SHAPES; k++)
        top = fmaxf(top, boulder * meshes[f->models.rock[k]].box.max[1]);
    const float outcrop = outcrop_size[1] * rock_stretch[1];
    top = fmaxf(top, outcrop * meshes[f->models.rock[TW_ROCK_SHAPES - 1]].box.max[1]);
    top = fmaxf(top, log_scale[1] * meshes[f->models.log].box.max[1]);
    for (uint32_t k = 0; k < TW_PATCH_LEVELS; k++) {
        top = fmaxf(top, meshes[f->models.bush_patch[k]].box.max[1]);
        top = fmaxf(top, meshes[f->models.fern_patch[k]].box.max[1]);
    }
    return top * (1.0f + 1e-5f);
}
