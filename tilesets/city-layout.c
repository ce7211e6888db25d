/* The city's block generator (tilesets-private.h): the streets, sidewalks
 * and lamps along every border, the ground, and a block of buildings
 * (buildings.h), low-rise houses or a park inside them.
 *
 * A tile is one city block seen from the streets around it: the tile spans
 * [0, W] x [0, W], half of every street lies inside each border, so the
 * block's lots cover [s, W - s] with s = street_width / 2. A block's
 * buildings are laid out first and get their final window spacing once the
 * whole block is known, so that the block meets its triangle budget. */
#include "tilesets/buildings.h"
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/shapes.h"
#include "tilesets/tilesets-private.h"
#include "tiles/array.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const float kerb_height = 0.15f;
/* Building heights are drawn in steps of this many metres. */
static const float height_step = 0.5f;

/* ---- the generator's state ---------------------------------------------------- */

enum { FACADE_COLOURS = 6 };

/* A building waiting for its final window spacing. */
struct lot {
    struct tw_building_spec spec;
    float transform[12];
    uint32_t facade_material;
};

struct tw_city_blocks {
    struct tw_tileset *ts;
    struct tw_city_settings set;
    float w;                /* tile side */
    float half_street;      /* s: the block's lots start here */
    float kerb_line;        /* where the road ends and the sidewalk begins */
    float lot_scale;        /* >= 1: lots grow with blocks wider than 66 m */

    uint32_t mat_asphalt, mat_sidewalk, mat_marking, mat_courtyard, mat_grass, mat_glass,
             mat_roof, mat_metal, mat_foliage, mat_bark, mat_water;
    uint32_t mat_facade[FACADE_COLOURS];

    uint32_t mesh_asphalt, mesh_sidewalk, mesh_markings, mesh_lot, mesh_lamps;
    uint32_t mesh_canopy, mesh_trunk, mesh_paths, mesh_fountain, mesh_water;
    bool park_meshes;       /* the five above are made */

    struct tw_mesh_builder ground;  /* builds the meshes above */

    struct tw_buildings buildings;
    struct lot *lots;
    uint32_t lot_count, lot_cap;
};

static int push_lot(struct tw_city_blocks *c, const struct tw_building_spec *sp,
                    const float transform[12], uint32_t facade_material)
{
    const int err = tw_array_reserve_u32((void **)&c->lots, &c->lot_cap, c->lot_count + 1,
                                         sizeof(*c->lots), 32);
    if (err)
        return err;
    struct lot *l = &c->lots[c->lot_count++];
    l->spec = *sp;
    memcpy(l->transform, transform, sizeof(l->transform));
    l->facade_material = facade_material;
    return TW_OK;
}

/* ---- placement ------------------------------------------------------------------ */

/* Quarter turns about y, exact: turn k maps local -z to the street of side
 * k (0: -z, 1: +x, 2: +z, 3: -x), local +x along side k and local +z into
 * the block. */
static const float turn_cos[4] = {1.0f, 0.0f, -1.0f, 0.0f};
static const float turn_sin[4] = {0.0f, -1.0f, 0.0f, 1.0f};

static void turn_transform(uint32_t k, float tx, float ty, float tz, float m[12])
{
    const float co = turn_cos[k & 3], si = turn_sin[k & 3];
    const float r[12] = {co, 0.0f, si, tx, 0.0f, 1.0f, 0.0f, ty, -si, 0.0f, co, tz};
    memcpy(m, r, sizeof(r));
}

/* Turn k about the tile's centre: the pieces of ground built for side 0
 * serve all four sides. */
static void turn_about_centre(const struct tw_city_blocks *c, uint32_t k, float m[12])
{
    const float h = 0.5f * c->w, co = turn_cos[k & 3], si = turn_sin[k & 3];
    turn_transform(k, h - (co * h + si * h), 0.0f, h - (-si * h + co * h), m);
}

static void turn_point(const struct tw_city_blocks *c, uint32_t k, float x, float y, float z,
                       float p[3])
{
    float m[12];
    turn_about_centre(c, k, m);
    p[0] = m[0] * x + m[2] * z + m[3];
    p[1] = y;
    p[2] = m[8] * x + m[10] * z + m[11];
}

/* Side k of the block in tile coordinates: a point a along the side and b
 * into the block. */
static void side_frame(const struct tw_city_blocks *c, uint32_t k, float origin[2], float along[2])
{
    const float lo = c->half_street, hi = c->w - c->half_street;
    const float origins[4][2] = {{lo, lo}, {hi, lo}, {hi, hi}, {lo, hi}};
    static const float alongs[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
    memcpy(origin, origins[k & 3], sizeof(float) * 2);
    memcpy(along, alongs[k & 3], sizeof(float) * 2);
}

static void side_transform(const struct tw_city_blocks *c, uint32_t k, float a, float m[12])
{
    float origin[2], along[2];
    side_frame(c, k, origin, along);
    turn_transform(k, origin[0] + a * along[0], kerb_height, origin[1] + a * along[1], m);
}

/* A turned w x d footprint whose tile-space box starts at (x, z). */
static void rect_transform(uint32_t k, float w, float d, float x, float z, float m[12])
{
    turn_transform(k, 0.0f, kerb_height, 0.0f, m);
    float min_x = 0.0f, min_z = 0.0f;
    const float corners[4][2] = {{0, 0}, {w, 0}, {0, d}, {w, d}};
    for (int i = 0; i < 4; i++) {
        const float px = m[0] * corners[i][0] + m[2] * corners[i][1];
        const float pz = m[8] * corners[i][0] + m[10] * corners[i][1];
        min_x = i == 0 || px < min_x ? px : min_x;
        min_z = i == 0 || pz < min_z ? pz : min_z;
    }
    m[3] = x - min_x;
    m[11] = z - min_z;
}

/* ---- block layouts -------------------------------------------------------------- */

struct block_params {
    uint32_t side_mask;     /* sides of the block lined with buildings */
    float depth;            /* deepest side lot; corners are at least this */
    float corner_size[4];
    bool share_corners;
    float lot_min, lot_max; /* side-lot widths */
    float gap_chance;
    float row_chance;
    float side_h[2], corner_h[2];
    float tall_style_from;  /* buildings above this prefer modern styles */
};

static uint32_t pick_style(struct tw_rng *r, float height, float tall_from)
{
    const uint32_t roll = tw_rng_below(r, 20);
    if (height > tall_from)
        return roll < 8 ? TW_FACADE_RIBBON : roll < 17 ? TW_FACADE_MODERN : TW_FACADE_CLASSIC;
    /* Curtain walls carry few triangles per square metre; low blocks need
     * the punched facades to reach their budget. */
    return roll < 12 ? TW_FACADE_CLASSIC : TW_FACADE_MODERN;
}

static float pick_height(struct tw_rng *r, const float range[2])
{
    return tw_quantize(tw_rng_range(r, range[0], range[1]), height_step);
}

/* Lines side k with buildings from a = start to a = end; reports whether
 * buildings touch both ends (the corner buildings' party walls). */
static int layout_side(struct tw_city_blocks *c, struct tw_rng *r, const struct block_params *bp,
                       uint32_t k, float start, float end, bool corner_before,
                       bool corner_after)
{
    const float avail = end - start;
    if (avail < bp->lot_min)
        return TW_OK;
    int err = TW_OK;
    if (tw_rng_chance(r, bp->row_chance)) {
        /* A terrace of identical houses: one mesh set, instanced. */
        const float target = tw_rng_range(r, bp->lot_min, bp->lot_max);
        const uint32_t n = (uint32_t)fmaxf(1.0f, floorf(avail / target + 0.5f));
        const float lw = avail / (float)n;
        const float depth = tw_quantize(tw_rng_range(r, 0.7f * bp->depth, bp->depth), 0.5f);
        const float h = pick_height(r, bp->side_h);
        const uint32_t style = pick_style(r, h, bp->tall_style_from);
        struct tw_building_spec base;
        tw_building_spec_init(&base, r, lw, depth, h, style, 0, false);
        const uint32_t mat_a = c->mat_facade[tw_rng_below(r, FACADE_COLOURS)];
        const uint32_t mat_b = tw_rng_chance(r, 0.5f) ? c->mat_facade[tw_rng_below(r, FACADE_COLOURS)] : mat_a;
        for (uint32_t i = 0; i < n && !err; i++) {
            struct tw_building_spec sp = base;
            sp.blank_mask = tw_building_party_walls(h, ((i > 0 || corner_before) ? 1u << 3 : 0u) |
                                               ((i + 1 < n || corner_after) ? 1u << 1 : 0u));
            float m[12];
            side_transform(c, k, start + lw * (float)i, m);
            err = push_lot(c, &sp, m, i % 2 ? mat_b : mat_a);
        }
        return err;
    }

    /* Widths first, so that each building knows its neighbours. */
    float widths[64];
    bool gap[64];
    uint32_t n = 0;
    bool gap_used = false;
    float a = start;
    while (end - a > 0.01f && n < 64) {
        const float remaining = end - a;
        if (!gap_used && n > 0 && remaining > 2.0f * bp->lot_min + 6.0f &&
            tw_rng_chance(r, bp->gap_chance)) {
            widths[n] = tw_quantize(tw_rng_range(r, 3.0f, 6.0f), 0.5f);
            gap[n++] = true;
            gap_used = true;
            a += widths[n - 1];
            continue;
        }
        float lw = tw_quantize(tw_rng_range(r, bp->lot_min, bp->lot_max), 0.5f);
        if (remaining - lw < bp->lot_min)
            lw = remaining;
        widths[n] = lw;
        gap[n++] = false;
        a += lw;
    }
    if (end - a > 0.01f && n > 0)
        widths[n - 1] += end - a;
    a = start;
    for (uint32_t i = 0; i < n && !err; i++) {
        if (!gap[i]) {
            const bool before = i > 0 ? !gap[i - 1] : corner_before;
            const bool after = i + 1 < n ? !gap[i + 1] : corner_after;
            const float depth = tw_quantize(tw_rng_range(r, 0.7f * bp->depth, bp->depth), 0.5f);
            const float h = pick_height(r, bp->side_h);
            struct tw_building_spec sp;
            tw_building_spec_init(&sp, r, widths[i], depth, h,
                                  pick_style(r, h, bp->tall_style_from),
                      (before ? 1u << 3 : 0u) | (after ? 1u << 1 : 0u), false);
            float m[12];
            side_transform(c, k, a, m);
            err = push_lot(c, &sp, m, c->mat_facade[tw_rng_below(r, FACADE_COLOURS)]);
        }
        a += widths[i];
    }
    return err;
}

/* Corner buildings and the sides between them. */
static int layout_perimeter(struct tw_city_blocks *c, struct tw_rng *r,
                            const struct block_params *bp)
{
    const float block = c->w - 2.0f * c->half_street;
    bool corner[4];
    for (uint32_t k = 0; k < 4; k++)
        corner[k] = (bp->side_mask >> k & 1u) && (bp->side_mask >> ((k + 3) % 4) & 1u);

    int err = TW_OK;
    for (uint32_t k = 0; k < 4 && !err; k++) {
        if (!(bp->side_mask >> k & 1u))
            continue;
        const float start = corner[k] ? bp->corner_size[k] : 0.0f;
        const float end = block - (corner[(k + 1) % 4] ? bp->corner_size[(k + 1) % 4] : 0.0f);
        err = layout_side(c, r, bp, k, start, end, corner[k], corner[(k + 1) % 4]);
    }

    /* Corner k faces the streets of sides k and k - 1; its walls 1 and 2
     * back onto the neighbouring side lots. */
    struct tw_building_spec shared;
    uint32_t shared_material = 0;
    bool have_shared = false;
    for (uint32_t k = 0; k < 4 && !err; k++) {
        if (!corner[k])
            continue;
        struct tw_building_spec sp;
        uint32_t material;
        if (bp->share_corners && have_shared) {
            sp = shared;
            material = shared_material;
        } else {
            const float h = pick_height(r, bp->corner_h);
            const float size = bp->corner_size[k];
            tw_building_spec_init(&sp, r, size, size, h, pick_style(r, h, bp->tall_style_from),
                      (1u << 1) | (1u << 2), true);
            material = c->mat_facade[tw_rng_below(r, FACADE_COLOURS)];
            shared = sp;
            shared_material = material;
            have_shared = true;
        }
        float m[12];
        side_transform(c, k, 0.0f, m);
        err = push_lot(c, &sp, m, material);
    }
    return err;
}

static int add_instance(struct tw_city_blocks *c, uint32_t proto, uint32_t mesh, uint32_t material,
                        const float m[12])
{
    const int k = tw_tileset_add_instance(c->ts, proto, mesh, material, m);
    return k < 0 ? k : TW_OK;
}

/* Fits the window spacing of all pending lots to a triangle budget, then
 * instantiates them. Triangles fall roughly as 1 / bay, so a few
 * multiplicative corrections converge. */
static int place_lots(struct tw_city_blocks *c, uint32_t proto, uint64_t fixed_triangles,
                      float target)
{
    const float building_target = fmaxf(target - (float)fixed_triangles, 2000.0f);
    for (int pass = 0; pass < 2; pass++) {
        float scale = 1.0f, ratio = 0.0f;
        for (int iter = 0; iter < 12; iter++) {
            uint64_t total = 0;
            for (uint32_t k = 0; k < c->lot_count; k++) {
                struct tw_building_spec *sp = &c->lots[k].spec;
                sp->bay = tw_clampf(tw_quantize(sp->base_bay * scale, 0.05f),
                                    tw_building_min_bay(sp->style), 30.0f);
                total += tw_buildings_triangles(&c->buildings, sp);
            }
            ratio = (float)total / building_target;
            if (total == 0 || (ratio > 0.93f && ratio < 1.07f))
                break;
            scale = tw_clampf(scale * ratio, 0.3f, 20.0f);
        }
        /* Low, sparse blocks cannot reach the budget with windows alone
         * even at the narrowest spacing: give them balconies. */
        if (ratio > 0.93f)
            break;
        for (uint32_t k = 0; k < c->lot_count; k++) {
            struct tw_building_spec *sp = &c->lots[k].spec;
            if (sp->style != TW_FACADE_RIBBON)
                sp->balconies = true;
        }
    }
    int err = TW_OK;
    for (uint32_t k = 0; k < c->lot_count && !err; k++) {
        const uint32_t material[3] = {c->lots[k].facade_material, c->mat_glass, c->mat_roof};
        err = tw_buildings_place(&c->buildings, proto, &c->lots[k].spec, c->lots[k].transform,
                                 material);
    }
    c->lot_count = 0;
    return err;
}

static uint64_t mesh_triangles(const struct tw_city_blocks *c, uint32_t mesh)
{
    return c->ts->meshes[mesh].triangle_count;
}

/* Streets, sidewalks, lamps and the block's ground: the same in every
 * prototype. */
static int add_streets(struct tw_city_blocks *c, uint32_t proto, uint32_t ground_material,
                       uint64_t *triangles)
{
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    int err = add_instance(c, proto, c->mesh_asphalt, c->mat_asphalt, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_sidewalk, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_markings, c->mat_marking, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_lot, ground_material, identity);
    *triangles += mesh_triangles(c, c->mesh_asphalt) + mesh_triangles(c, c->mesh_sidewalk) +
                  mesh_triangles(c, c->mesh_markings) + mesh_triangles(c, c->mesh_lot);
    for (uint32_t k = 0; k < 4 && !err; k++) {
        float m[12];
        turn_about_centre(c, k, m);
        err = add_instance(c, proto, c->mesh_lamps, c->mat_metal, m);
        *triangles += mesh_triangles(c, c->mesh_lamps);
    }
    return err;
}

static float proto_height_cap(const struct tw_city_blocks *c)
{
    return c->set.max_height - kerb_height;
}

static int build_dense(struct tw_city_blocks *c, uint32_t proto, struct tw_rng *r, bool tallest)
{
    const float block = c->w - 2.0f * c->half_street;
    const float cap = proto_height_cap(c);
    const float hp = tallest ? cap : fmaxf(16.0f, cap * tw_rng_range(r, 0.45f, 1.0f));
    struct block_params bp = {0};
    bp.side_mask = 0xf;
    const float k = c->lot_scale;
    bp.depth = tw_quantize(tw_clampf(k * tw_rng_range(r, 13.0f, 20.0f), 6.0f, block * 0.3f), 0.5f);
    bp.share_corners = tw_rng_chance(r, 0.35f);
    const float shared_size = tw_quantize(bp.depth + k * tw_rng_range(r, 0.0f, 5.0f), 0.5f);
    for (int i = 0; i < 4; i++)
        bp.corner_size[i] =
            bp.share_corners ? shared_size
                             : tw_quantize(bp.depth + k * tw_rng_range(r, 0.0f, 5.0f), 0.5f);
    bp.lot_min = 8.0f * k;
    bp.lot_max = 17.0f * k;
    bp.gap_chance = 0.2f;
    bp.row_chance = 0.25f;
    bp.side_h[0] = fmaxf(10.0f, 0.25f * hp);
    bp.side_h[1] = fmaxf(bp.side_h[0], 0.65f * hp);
    bp.corner_h[0] = fmaxf(12.0f, 0.5f * hp);
    bp.corner_h[1] = fmaxf(bp.corner_h[0], 0.85f * hp);
    bp.tall_style_from = 36.0f;
    int err = layout_perimeter(c, r, &bp);

    /* A tower in the courtyard, when the block is deep enough for one. */
    /* Corner lots reach depth + 5 m into the block; keep 2 m clear of them. */
    const float room = block - 2.0f * (bp.depth + 5.0f * k) - 4.0f;
    if (!err && room >= 10.0f && (tallest || tw_rng_chance(r, 0.6f))) {
        const float size = tw_quantize(fminf(k * tw_rng_range(r, 14.0f, 22.0f), room), 0.5f);
        const float range[2] = {0.85f * hp, hp};
        const float h = tallest ? hp : pick_height(r, range);
        struct tw_building_spec sp;
        tw_building_spec_init(&sp, r, size, size, h, pick_style(r, h, bp.tall_style_from), 0, true);
        float m[12];
        const float lo = 0.5f * (c->w - size);
        rect_transform(tw_rng_below(r, 4), size, size, lo, lo, m);
        err = push_lot(c, &sp, m, c->mat_facade[tw_rng_below(r, FACADE_COLOURS)]);
    }
    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_courtyard, &fixed);
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 15000.0f, 34000.0f));
    return err;
}

/* The perimeter of low buildings that low-rise blocks and parks share:
 * lots from 10 m to depth_max deep (times the lot scale) on the sides of
 * side_mask, corners up to 3 m deeper, no tall styles. */
struct low_perimeter {
    uint32_t side_mask;
    float depth_max;
    float lot_min, lot_max;     /* times the lot scale */
    float gap_chance, row_chance;
    float side_top, corner_top; /* tallest side and corner buildings, under the cap */
};

static int layout_low_perimeter(struct tw_city_blocks *c, struct tw_rng *r,
                                const struct low_perimeter *lp, struct block_params *out)
{
    const float block = c->w - 2.0f * c->half_street;
    struct block_params bp = {0};
    bp.side_mask = lp->side_mask;
    const float k = c->lot_scale;
    bp.depth = tw_quantize(tw_clampf(k * tw_rng_range(r, 10.0f, lp->depth_max), 6.0f, block * 0.3f),
                           0.5f);
    for (int i = 0; i < 4; i++)
        bp.corner_size[i] = tw_quantize(bp.depth + k * tw_rng_range(r, 0.0f, 3.0f), 0.5f);
    bp.lot_min = lp->lot_min * k;
    bp.lot_max = lp->lot_max * k;
    bp.gap_chance = lp->gap_chance;
    bp.row_chance = lp->row_chance;
    /* Two floors at least: 9.5 m holds a ground floor, one more and the
     * parapet. */
    bp.side_h[0] = 9.5f;
    bp.side_h[1] = fminf(lp->side_top, proto_height_cap(c));
    bp.corner_h[0] = 10.0f;
    bp.corner_h[1] = fminf(lp->corner_top, proto_height_cap(c));
    bp.tall_style_from = 1e9f;
    *out = bp;
    return layout_perimeter(c, r, out);
}

static int build_lowrise(struct tw_city_blocks *c, uint32_t proto, struct tw_rng *r)
{
    static const struct low_perimeter lowrise = {
        .side_mask = 0xf, .depth_max = 14.0f, .lot_min = 8.0f, .lot_max = 14.0f,
        .gap_chance = 0.35f, .row_chance = 0.4f, .side_top = 15.0f, .corner_top = 17.0f,
    };
    struct block_params bp;
    int err = layout_low_perimeter(c, r, &lowrise, &bp);
    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_courtyard, &fixed);
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 12000.0f, 18000.0f));
    return err;
}

static int build_park_meshes(struct tw_city_blocks *c);

/* A park: lawns, paths, a fountain and trees, with low buildings along two
 * sides (fewer would not carry the triangle budget). */
static int build_park(struct tw_city_blocks *c, uint32_t proto, struct tw_rng *r)
{
    if (!c->park_meshes) {
        const int err = build_park_meshes(c);
        if (err)
            return err;
    }
    static const struct low_perimeter park = {
        .side_mask = (1u << 2) | (1u << 3), .depth_max = 13.0f, .lot_min = 7.0f,
        .lot_max = 12.0f, .gap_chance = 0.2f, .row_chance = 0.3f, .side_top = 18.0f,
        .corner_top = 20.0f,
    };
    struct block_params bp;
    int err = layout_low_perimeter(c, r, &park, &bp);
    const float k = c->lot_scale;

    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_grass, &fixed);
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (!err)
        err = add_instance(c, proto, c->mesh_paths, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_fountain, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_water, c->mat_water, identity);
    fixed += mesh_triangles(c, c->mesh_paths) + mesh_triangles(c, c->mesh_fountain) +
             mesh_triangles(c, c->mesh_water);

    /* Trees on a jittered grid, off the paths, the fountain and the lots.
     * Canopies reach 3.3 m from the trunk: 3.5 m from the lot line keeps
     * them over the block. */
    const float lo = c->half_street + 3.5f, hi = c->w - c->half_street - 3.5f;
    const float centre = 0.5f * c->w, step = 8.5f * k;
    /* Corner lots reach 3 k m deeper than side lots. */
    const float built = c->half_street + bp.depth + 3.0f * k + 1.0f;
    /* Candidates first, then an even subset: the instance count stays
     * moderate while the trees spread over the whole lawn. */
    enum { MAX_CANDIDATES = 256, MAX_TREES = 12 };
    float candidates[MAX_CANDIDATES][4];
    uint32_t count = 0;
    const uint32_t steps = (uint32_t)floorf((hi - lo) / step) + 1;
    for (uint32_t j = 0; j < steps; j++) {
        for (uint32_t i = 0; i < steps && count < MAX_CANDIDATES; i++) {
            const float tx = tw_clampf(lo + step * (float)i + tw_rng_range(r, -1.5f, 1.5f), lo, hi);
            const float tz = tw_clampf(lo + step * (float)j + tw_rng_range(r, -1.5f, 1.5f), lo, hi);
            const float angle = tw_rng_range(r, 0.0f, 6.2831853f);
            const float scale = tw_rng_range(r, 0.8f, 1.2f);
            if (fabsf(tx - centre) < 3.5f || fabsf(tz - centre) < 3.5f)
                continue;
            if (((bp.side_mask >> 2 & 1u) && tz > c->w - built) ||
                ((bp.side_mask >> 3 & 1u) && tx < built))
                continue;
            const float cand[4] = {tx, tz, angle, scale};
            memcpy(candidates[count++], cand, sizeof(cand));
        }
    }
    const uint32_t trees = count < MAX_TREES ? count : MAX_TREES;
    for (uint32_t t = 0; t < trees && !err; t++) {
        const float *cand = candidates[(uint64_t)t * count / trees];
        const float co = cand[3] * cosf(cand[2]), si = cand[3] * sinf(cand[2]);
        const float m[12] = {co, 0.0f, si, cand[0], 0.0f, cand[3], 0.0f, kerb_height,
                             -si, 0.0f, co, cand[1]};
        err = add_instance(c, proto, c->mesh_trunk, c->mat_bark, m);
        if (!err)
            err = add_instance(c, proto, c->mesh_canopy, c->mat_foliage, m);
        fixed += mesh_triangles(c, c->mesh_trunk) + mesh_triangles(c, c->mesh_canopy);
    }
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 11500.0f, 16000.0f));
    return err;
}

/* ---- shared meshes ---------------------------------------------------------------- */

static int finish_shared(struct tw_city_blocks *c, uint32_t *mesh)
{
    return tw_mesh_builder_add_to(&c->ground, c->ts, mesh);
}

/* An axis-aligned horizontal rectangle of side 0, repeated on all four
 * sides by turns about the tile's centre. */
static void emit_ground_rect4(struct tw_city_blocks *c, float x0, float z0, float x1, float z1,
                              float y)
{
    const float up[3] = {0, 1, 0};
    for (uint32_t k = 0; k < 4; k++) {
        float p[4][3];
        turn_point(c, k, x0, y, z0, p[0]);
        turn_point(c, k, x1, y, z0, p[1]);
        turn_point(c, k, x1, y, z1, p[2]);
        turn_point(c, k, x0, y, z1, p[3]);
        tw_shape_polygon(&c->ground, (const float(*)[3])p, 4, up);
    }
}

static int build_ground_meshes(struct tw_city_blocks *c)
{
    const float w = c->w, s = c->half_street, r = c->kerb_line;
    int err;

    /* Asphalt, sidewalk and lot ground as pinwheels: no overlaps. */
    tw_mesh_builder_reset(&c->ground, false);
    emit_ground_rect4(c, 0.0f, 0.0f, w - r, r, 0.0f);
    if ((err = finish_shared(c, &c->mesh_asphalt)))
        return err;

    tw_mesh_builder_reset(&c->ground, false);
    emit_ground_rect4(c, r, r, w - s, s, kerb_height);
    for (uint32_t k = 0; k < 4; k++) {
        float p[4][3];
        turn_point(c, k, r, 0.0f, r, p[0]);
        turn_point(c, k, w - r, 0.0f, r, p[1]);
        turn_point(c, k, w - r, kerb_height, r, p[2]);
        turn_point(c, k, r, kerb_height, r, p[3]);
        /* The kerb faces the road: side 0's -z, turned. */
        const float facing[3] = {-turn_sin[k], 0.0f, -turn_cos[k]};
        tw_shape_polygon(&c->ground, (const float(*)[3])p, 4, facing);
    }
    if ((err = finish_shared(c, &c->mesh_sidewalk)))
        return err;

    tw_mesh_builder_reset(&c->ground, false);
    {
        const float up[3] = {0, 1, 0};
        const float p0[3] = {s, kerb_height, s}, p1[3] = {w - s, kerb_height, s};
        const float p2[3] = {w - s, kerb_height, w - s}, p3[3] = {s, kerb_height, w - s};
        tw_shape_quad(&c->ground, p0, p1, p2, p3, up);
    }
    if ((err = finish_shared(c, &c->mesh_lot)))
        return err;

    /* Markings: half of each centre line and zebra crossing lies in each
     * tile, symmetric about the border, so neighbours complete them. */
    tw_mesh_builder_reset(&c->ground, false);
    const float y = 0.01f, half_line = 0.06f;
    const float cross0 = s + 0.8f, cross1 = s + 3.8f;
    for (float z = 0.25f; z + 0.5f <= r - 0.2f; z += 1.0f) {
        emit_ground_rect4(c, cross0, z, cross1, z + 0.5f, y);
        emit_ground_rect4(c, w - cross1, z, w - cross0, z + 0.5f, y);
    }
    const float dash_lo = cross1 + 1.0f, dash_hi = w - cross1 - 1.0f;
    for (float x = 0.5f * w - 1.5f; x >= dash_lo; x -= 6.0f)
        emit_ground_rect4(c, x, 0.0f, x + 3.0f, half_line, y);
    for (float x = 0.5f * w + 4.5f; x + 3.0f <= dash_hi; x += 6.0f)
        emit_ground_rect4(c, x, 0.0f, x + 3.0f, half_line, y);
    if ((err = finish_shared(c, &c->mesh_markings)))
        return err;

    /* Lamps on the building side of the sidewalk of side 0, clear of the
     * street band (which ends 1 m short of the lot line). */
    tw_mesh_builder_reset(&c->ground, false);
    const float lz = s - 0.55f;
    const float span = w - 2.0f * s - 4.0f;
    const uint32_t lamps = (uint32_t)fmaxf(2.0f, floorf(span / 18.0f + 0.5f) + 1.0f);
    for (uint32_t i = 0; i < lamps; i++) {
        const float lx = s + 2.0f + span * (float)i / (float)(lamps - 1);
        const float base_lo[3] = {lx - 0.15f, kerb_height, lz - 0.15f};
        const float base_hi[3] = {lx + 0.15f, kerb_height + 0.6f, lz + 0.15f};
        const float pole_lo[3] = {lx - 0.07f, kerb_height + 0.6f, lz - 0.07f};
        const float pole_hi[3] = {lx + 0.07f, kerb_height + 6.0f, lz + 0.07f};
        const float head_lo[3] = {lx - 0.3f, kerb_height + 6.0f, lz - 0.22f};
        const float head_hi[3] = {lx + 0.3f, kerb_height + 6.25f, lz + 0.22f};
        tw_shape_box(&c->ground, base_lo, base_hi, TW_FACES_NO_BOTTOM);
        tw_shape_box(&c->ground, pole_lo, pole_hi, TW_FACES_SIDES);
        tw_shape_box(&c->ground, head_lo, head_hi, TW_FACES_SIDES | TW_FACE_PY | TW_FACE_NY);
    }
    if ((err = finish_shared(c, &c->mesh_lamps)))
        return err;
    return TW_OK;
}

static int build_park_meshes(struct tw_city_blocks *c)
{
    int err;
    tw_mesh_builder_reset(&c->ground, false);
    const float blob_a[3] = {0.0f, 5.4f, 0.0f}, radius_a[3] = {2.6f, 2.1f, 2.6f};
    const float blob_b[3] = {0.5f, 6.9f, -0.3f}, radius_b[3] = {1.8f, 1.5f, 1.8f};
    tw_shape_ellipsoid(&c->ground, blob_a, radius_a, 4);
    tw_shape_ellipsoid(&c->ground, blob_b, radius_b, 2);
    if ((err = finish_shared(c, &c->mesh_canopy)))
        return err;

    tw_mesh_builder_reset(&c->ground, false);
    tw_shape_prism(&c->ground, 0.0f, 0.0f, 0.22f, 0.0f, 4.6f, 6, false);
    if ((err = finish_shared(c, &c->mesh_trunk)))
        return err;

    /* A cross of paths, slightly above the lawn. */
    tw_mesh_builder_reset(&c->ground, false);
    const float s = c->half_street, w = c->w, m = 0.5f * c->w, y = kerb_height + 0.02f;
    const float rects[3][4] = {
        {s, m - 1.5f, w - s, m + 1.5f}, {m - 1.5f, s, m + 1.5f, m - 1.5f},
        {m - 1.5f, m + 1.5f, m + 1.5f, w - s},
    };
    const float up[3] = {0, 1, 0};
    for (int k = 0; k < 3; k++) {
        const float p0[3] = {rects[k][0], y, rects[k][1]}, p1[3] = {rects[k][2], y, rects[k][1]};
        const float p2[3] = {rects[k][2], y, rects[k][3]}, p3[3] = {rects[k][0], y, rects[k][3]};
        tw_shape_quad(&c->ground, p0, p1, p2, p3, up);
    }
    if ((err = finish_shared(c, &c->mesh_paths)))
        return err;

    /* The fountain: a ring wall (outer and inner faces, top) and a column. */
    tw_mesh_builder_reset(&c->ground, false);
    const uint32_t sides = 16;
    const float r_out = 4.0f, r_in = 3.6f, y0 = kerb_height, y1 = kerb_height + 0.6f;
    for (uint32_t k = 0; k < sides; k++) {
        const double a0 = 2.0 * 3.14159265358979323846 * k / sides;
        const double a1 = 2.0 * 3.14159265358979323846 * (k + 1) / sides;
        const float c0 = (float)cos(a0), s0 = (float)sin(a0), c1 = (float)cos(a1), s1 = (float)sin(a1);
        const float out[3] = {c0 + c1, 0.0f, s0 + s1}, in[3] = {-out[0], 0.0f, -out[2]};
        const float o0[3] = {m + r_out * c0, y0, m + r_out * s0}, o1[3] = {m + r_out * c1, y0, m + r_out * s1};
        const float o2[3] = {m + r_out * c1, y1, m + r_out * s1}, o3[3] = {m + r_out * c0, y1, m + r_out * s0};
        const float i0[3] = {m + r_in * c0, y0, m + r_in * s0}, i1[3] = {m + r_in * c1, y0, m + r_in * s1};
        const float i2[3] = {m + r_in * c1, y1, m + r_in * s1}, i3[3] = {m + r_in * c0, y1, m + r_in * s0};
        tw_shape_quad(&c->ground, o0, o1, o2, o3, out);
        tw_shape_quad(&c->ground, i0, i1, i2, i3, in);
        tw_shape_quad(&c->ground, o3, o2, i2, i3, up);
    }
    tw_shape_prism(&c->ground, m, m, 0.35f, y0, y0 + 2.2f, 8, true);
    if ((err = finish_shared(c, &c->mesh_fountain)))
        return err;

    tw_mesh_builder_reset(&c->ground, false);
    float disc[16][3];
    for (uint32_t k = 0; k < sides; k++) {
        const double a = 2.0 * 3.14159265358979323846 * k / sides;
        disc[k][0] = m + r_in * (float)cos(a);
        disc[k][1] = kerb_height + 0.4f;
        disc[k][2] = m + r_in * (float)sin(a);
    }
    tw_shape_polygon(&c->ground, (const float(*)[3])disc, sides, up);
    if ((err = finish_shared(c, &c->mesh_water)))
        return err;
    c->park_meshes = true;
    return TW_OK;
}

static int add_materials(struct tw_city_blocks *c)
{
    static const float colours[11][4] = {
        {0.16f, 0.16f, 0.17f, 1.0f},  /* asphalt */
        {0.62f, 0.60f, 0.56f, 1.0f},  /* sidewalk */
        {0.88f, 0.88f, 0.82f, 1.0f},  /* road marking */
        {0.44f, 0.42f, 0.39f, 1.0f},  /* courtyard paving */
        {0.26f, 0.46f, 0.19f, 1.0f},  /* grass */
        {0.09f, 0.13f, 0.19f, 1.0f},  /* window glass */
        {0.32f, 0.29f, 0.28f, 1.0f},  /* roof */
        {0.20f, 0.21f, 0.23f, 1.0f},  /* lamp metal */
        {0.17f, 0.37f, 0.13f, 1.0f},  /* foliage */
        {0.36f, 0.26f, 0.17f, 1.0f},  /* bark */
        {0.22f, 0.38f, 0.50f, 1.0f},  /* water */
    };
    static const float facades[FACADE_COLOURS][4] = {
        {0.56f, 0.27f, 0.20f, 1.0f},  /* brick */
        {0.77f, 0.68f, 0.52f, 1.0f},  /* sandstone */
        {0.63f, 0.63f, 0.61f, 1.0f},  /* concrete */
        {0.86f, 0.81f, 0.70f, 1.0f},  /* cream render */
        {0.42f, 0.47f, 0.53f, 1.0f},  /* blue-grey panels */
        {0.73f, 0.53f, 0.31f, 1.0f},  /* ochre */
    };
    uint32_t *slots[11] = {
        &c->mat_asphalt, &c->mat_sidewalk, &c->mat_marking, &c->mat_courtyard,
        &c->mat_grass, &c->mat_glass, &c->mat_roof, &c->mat_metal, &c->mat_foliage,
        &c->mat_bark, &c->mat_water,
    };
    for (int k = 0; k < 11; k++) {
        const int m = tw_tileset_add_material(c->ts, colours[k]);
        if (m < 0)
            return m;
        *slots[k] = (uint32_t)m;
    }
    for (int k = 0; k < FACADE_COLOURS; k++) {
        const int m = tw_tileset_add_material(c->ts, facades[k]);
        if (m < 0)
            return m;
        c->mat_facade[k] = (uint32_t)m;
    }
    return TW_OK;
}

/* ---- the generator's lifetime (tilesets-private.h) --------------------------------- */

/* Sets up the generator on an unfinished tileset: materials, then the
 * ground and park meshes that every prototype shares (the park meshes later,
 * with the first park, unless park_meshes_now). */
static int blocks_create(struct tw_tileset *ts, const struct tw_city_settings *settings,
                         bool park_meshes_now, struct tw_city_blocks **out)
{
    if (!ts || !settings || !out || ts->finished)
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_city_blocks *c = calloc(1, sizeof(*c));
    if (!c)
        return TW_ERR_NOMEM;
    c->ts = ts;
    c->set = *settings;
    c->w = c->set.footprint;
    c->half_street = 0.5f * c->set.street_width;
    c->kerb_line = tw_city_road_half_width(&c->set);
    c->lot_scale = fmaxf(1.0f, (c->w - c->set.street_width) / 66.0f);
    tw_buildings_init(&c->buildings, ts);
    int err = add_materials(c);
    if (!err)
        err = build_ground_meshes(c);
    if (!err && park_meshes_now)
        err = build_park_meshes(c);
    if (err) {
        tw_city_blocks_destroy(c);
        return err;
    }
    *out = c;
    return TW_OK;
}

int tw_city_blocks_create(struct tw_tileset *ts, const struct tw_city_settings *settings,
                          struct tw_city_blocks **out)
{
    return blocks_create(ts, settings, true, out);
}

int tw_city_blocks_create_tile(struct tw_tileset *ts, const struct tw_city_settings *settings,
                               struct tw_city_blocks **out)
{
    return blocks_create(ts, settings, false, out);
}


float tw_city_road_half_width(const struct tw_city_settings *settings)
{
    const float half_street = 0.5f * settings->street_width;
    return half_street - tw_clampf(0.22f * settings->street_width, 1.5f, 4.0f);
}
/* Every height a block draws is at most proto_height_cap() before it is
 * rounded to height_step (build_dense(): hp <= cap; the other kinds cap
 * lower), so at most cap + height_step / 2 after; tw_building_spec_init() keeps a
 * building's top, roof clutter and parapet included, 0.01 m under its
 * height; it stands on the kerb. Lamps (6.4 m) and park trees (10.3 m) stay
 * under the lowest max_height (20 m). */
float tw_city_blocks_max_top(const struct tw_city_settings *settings)
{
    return settings->max_height + 0.5f * height_step;
}

void tw_city_blocks_destroy(struct tw_city_blocks *c)
{
    if (!c)
        return;
    tw_buildings_finish(&c->buildings);
    tw_mesh_builder_release(&c->ground);
    free(c->lots);
    free(c);
}

int tw_city_blocks_add(struct tw_city_blocks *c, uint32_t proto, enum tw_city_block_kind kind,
                       uint64_t stream, bool tallest)
{
    if (!c || proto >= c->ts->prototype_count)
        return TW_ERR_INVALID;
    struct tw_rng r = {stream};
    switch (kind) {
    case TW_CITY_BLOCK_DENSE: return build_dense(c, proto, &r, tallest);
    case TW_CITY_BLOCK_LOWRISE: return build_lowrise(c, proto, &r);
    default: return build_park(c, proto, &r);
    }
}

int tw_city_blocks_add_streets(struct tw_city_blocks *c, uint32_t proto,
                               uint32_t ground_material)
{
    if (!c || proto >= c->ts->prototype_count || ground_material >= c->ts->material_count)
        return TW_ERR_INVALID;
    uint64_t triangles = 0;
    return add_streets(c, proto, ground_material, &triangles);
}

void tw_city_blocks_lot_area(const struct tw_city_blocks *c, float area[4], float *ground_y)
{
    area[0] = area[1] = c->half_street;
    area[2] = area[3] = c->w - c->half_street;
    *ground_y = kerb_height;
}
