/* The forest's models (trees.h): tree species x sizes, rocks, a log and
 * undergrowth patches, built from the seed as flat-shaded meshes. */
#include "tilesets/procedural.h"
#include "tilesets/shapes.h"
#include "tilesets/tilesets-private.h"
#include "tilesets/trees.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A fern: fronds arching out from (x, y, z), each a two-sided folded kite. */
static void emit_fern(struct tw_mesh_builder *b, struct tw_rng *r, float x, float y, float z,
                      float length)
{
    const uint32_t fronds = 5 + tw_rng_below(r, 3);
    const float turn = tw_rng_range(r, 0.0f, TW_TAU);
    for (uint32_t k = 0; k < fronds; k++) {
        const float a = turn + TW_TAU * ((float)k + tw_rng_range(r, -0.25f, 0.25f)) / (float)fronds;
        const float len = length * tw_rng_range(r, 0.75f, 1.1f);
        const float dx = cosf(a), dz = sinf(a), width = 0.16f * len;
        const float rise = tw_rng_range(r, 0.45f, 0.65f) * len;
        const float base[3] = {x + 0.05f * dx, y + 0.02f, z + 0.05f * dz};
        const float tip[3] = {x + len * dx, y + 0.2f * rise, z + len * dz};
        const float mid_l[3] = {x + 0.55f * len * dx - width * dz, y + rise,
                                z + 0.55f * len * dz + width * dx};
        const float mid_r[3] = {x + 0.55f * len * dx + width * dz, y + rise,
                                z + 0.55f * len * dz - width * dx};
        tw_shape_two_sided(b, base, mid_r, tip);
        tw_shape_two_sided(b, base, tip, mid_l);
    }
}

const struct tw_tree_recipe tw_tree_recipes[TW_TREE_MODELS] = {
    {TW_FOREST_SPECIES_SPRUCE, 4.2f, 1.35f, 0.12f, 0.10f, 3, 6},
    {TW_FOREST_SPECIES_SPRUCE, 10.5f, 2.05f, 0.18f, 0.20f, 4, 7},
    {TW_FOREST_SPECIES_SPRUCE, 18.5f, 2.85f, 3.2f, 0.32f, 5, 8},
    {TW_FOREST_SPECIES_FIR, 9.0f, 1.75f, 1.9f, 0.18f, 4, 7},
    {TW_FOREST_SPECIES_FIR, 16.0f, 2.45f, 2.8f, 0.30f, 5, 8},
    {TW_FOREST_SPECIES_PINE, 14.0f, 2.2f, 8.0f, 0.20f, 3, 1},
    {TW_FOREST_SPECIES_PINE, 21.0f, 2.8f, 12.5f, 0.28f, 4, 1},
    {TW_FOREST_SPECIES_BEECH, 11.0f, 3.1f, 3.4f, 0.24f, 3, 1},
    {TW_FOREST_SPECIES_BEECH, 18.0f, 4.6f, 5.2f, 0.40f, 4, 2},
    {TW_FOREST_SPECIES_BIRCH, 10.0f, 1.5f, 3.6f, 0.13f, 3, 1},
    {TW_FOREST_SPECIES_BIRCH, 15.0f, 2.0f, 5.6f, 0.17f, 4, 1},
};

void tw_tree_species_models(uint32_t species, uint32_t *first, uint32_t *count)
{
    *first = 0;
    *count = 0;
    for (uint32_t k = 0; k < TW_TREE_MODELS; k++) {
        if (tw_tree_recipes[k].species != species)
            continue;
        if (!*count)
            *first = k;
        (*count)++;
    }
}

/* Appends the profile of the builder's triangles to the model's. */
static int append_profile(struct tw_tree_model *m, const struct tw_mesh_builder *b)
{
    struct tw_tree_profile *p =
        realloc(m->profile, sizeof(*p) * (m->profile_count + b->triangle_count));
    if (!p)
        return TW_ERR_NOMEM;
    m->profile = p;
    for (uint32_t t = 0; t < b->triangle_count; t++) {
        struct tw_tree_profile e = {1e30f, 0.0f};
        for (int v = 0; v < 3; v++) {
            const float *q = b->positions + 3 * (size_t)b->indices[3 * (size_t)t + v];
            e.min_y = fminf(e.min_y, q[1]);
            e.reach = fmaxf(e.reach, sqrtf(q[0] * q[0] + q[2] * q[2]));
        }
        m->profile[m->profile_count++] = e;
        m->reach = fmaxf(m->reach, e.reach);
    }
    return TW_OK;
}

float tw_tree_reach_below(const struct tw_tree_model *m, float height, float sxz, float sy)
{
    float reach = 0.0f;
    for (uint32_t k = 0; k < m->profile_count; k++)
        if (m->profile[k].min_y * sy < height)
            reach = fmaxf(reach, m->profile[k].reach);
    return reach * sxz;
}

/* Conifer crowns: frusta stacked like skirts, each overlapping the one
 * below, radii shrinking to the top, a cone to finish. */
static void emit_conifer_crown(struct tw_mesh_builder *b, struct tw_rng *r,
                               const struct tw_tree_recipe *mr)
{
    const uint32_t layers = mr->layers;
    const float span = mr->height - mr->crown_base;
    /* Layer k spans [bottom_k, bottom_k + tall]; layers overlap by 45 %. */
    const float tall = span / (1.0f + 0.55f * (float)(layers - 1));
    for (uint32_t k = 0; k < layers; k++) {
        const float t = (float)k / (float)layers;
        const float y0 = mr->crown_base + 0.55f * tall * (float)k;
        const float y1 = k + 1 == layers ? mr->height : y0 + tall;
        const float r0 = mr->radius * (1.0f - 0.78f * t) * tw_rng_range(r, 0.9f, 1.08f);
        const float r1 = k + 1 == layers ? 0.0f : 0.22f * r0;
        tw_shape_frustum(b, tw_rng_range(r, -0.05f, 0.05f) * r0,
                         tw_rng_range(r, -0.05f, 0.05f) * r0, y0, y1, r0, r1, mr->sides,
                         tw_rng_range(r, 0.0f, TW_TAU), true);
    }
}

/* A tapered trunk from the ground to top, closed at the top. */
static void emit_trunk(struct tw_mesh_builder *b, float radius, float top, uint32_t sides,
                       float phase)
{
    tw_shape_frustum(b, 0.0f, 0.0f, 0.0f, top, radius, 0.45f * radius, sides, phase, false);
    const float up[3] = {0.0f, 1.0f, 0.0f};
    const float r1 = 0.45f * radius;
    const float first[3] = {r1 * cosf(phase), top, r1 * sinf(phase)};
    for (uint32_t k = 1; k + 1 < sides; k++) {
        const float a0 = phase + TW_TAU * (float)k / (float)sides;
        const float a1 = phase + TW_TAU * (float)(k + 1) / (float)sides;
        const float p1[3] = {r1 * cosf(a0), top, r1 * sinf(a0)};
        const float p2[3] = {r1 * cosf(a1), top, r1 * sinf(a1)};
        tw_shape_triangle(b, first, p1, p2, up);
    }
}

/* Broadleaf, pine and birch crowns: a main lumpy blob and smaller ones
 * round it, with gaps between them. */
static void emit_leafy_crown(struct tw_mesh_builder *b, struct tw_rng *r,
                             const struct tw_tree_recipe *mr)
{
    const float crown_h = mr->height - mr->crown_base;
    const float cy = mr->crown_base + 0.5f * crown_h;
    struct tw_lumps l;
    const bool birch = mr->species == TW_FOREST_SPECIES_BIRCH;
    const float squash = mr->species == TW_FOREST_SPECIES_PINE ? 0.55f : birch ? 1.3f : 0.78f;
    /* The main blob. */
    const float main_r = birch ? 0.8f * mr->radius : 0.72f * mr->radius;
    const float main_ry = fminf(0.5f * crown_h, main_r * squash);
    tw_lumps_init(&l, r, 1.0f);
    const float centre[3] = {0.0f, cy + 0.05f * crown_h, 0.0f};
    const float radius[3] = {main_r, main_ry, main_r * tw_rng_range(r, 0.9f, 1.05f)};
    tw_shape_blob(b, centre, radius, mr->sides, &l, -1e30f);
    /* Satellites round the main one, at random heights in the crown. */
    const uint32_t n = mr->layers;
    const float turn = tw_rng_range(r, 0.0f, TW_TAU);
    for (uint32_t k = 0; k < n; k++) {
        const float a = turn + TW_TAU * ((float)k + tw_rng_range(r, -0.2f, 0.2f)) / (float)n;
        const float sr = mr->radius * tw_rng_range(r, 0.36f, 0.48f);
        const float sry = fminf(sr * squash, 0.35f * crown_h);
        const float out = mr->radius - sr;
        const float sy = mr->crown_base + sry + tw_rng_range(r, 0.0f, 1.0f) *
                         fmaxf(0.0f, crown_h - 2.0f * sry) * (birch ? 1.0f : 0.6f);
        tw_lumps_init(&l, r, 1.0f);
        const float c[3] = {out * cosf(a), sy, out * sinf(a)};
        const float rad[3] = {sr, sry, sr};
        tw_shape_blob(b, c, rad, 1, &l, -1e30f);
    }
}

/* Two short limbs from the trunk into the crown. */
static void emit_limbs(struct tw_mesh_builder *b, struct tw_rng *r, const struct tw_tree_recipe *mr)
{
    const float turn = tw_rng_range(r, 0.0f, TW_TAU);
    for (int k = 0; k < 2; k++) {
        const float a = turn + (float)k * 0.5f * TW_TAU + tw_rng_range(r, -0.4f, 0.4f);
        const float y0 = mr->crown_base * 0.85f;
        const float y1 = mr->crown_base + 0.35f * (mr->height - mr->crown_base);
        const float reach = 0.45f * mr->radius, rr = 0.45f * mr->trunk_radius;
        const float dx = cosf(a), dz = sinf(a);
        /* A four-sided limb from near the axis at y0 out to reach at y1. */
        const float ends[2][3] = {{0.3f * mr->trunk_radius * dx, y0, 0.3f * mr->trunk_radius * dz},
                                  {reach * dx, y1, reach * dz}};
        const float px = -dz, pz = dx;
        float ring[2][4][3];
        for (int e = 0; e < 2; e++) {
            const float w = e ? 0.5f * rr : rr;
            for (int s = 0; s < 4; s++) {
                const float u = s == 0 || s == 3 ? -w : w, v = s < 2 ? -w : w;
                ring[e][s][0] = ends[e][0] + u * px;
                ring[e][s][1] = ends[e][1] + v;
                ring[e][s][2] = ends[e][2] + u * pz;
            }
        }
        const float mid[3] = {0.5f * (ends[0][0] + ends[1][0]), 0.5f * (ends[0][1] + ends[1][1]),
                              0.5f * (ends[0][2] + ends[1][2])};
        for (int s = 0; s < 4; s++) {
            const int t = (s + 1) % 4;
            tw_shape_outward(b, ring[0][s], ring[0][t], ring[1][t], mid);
            tw_shape_outward(b, ring[0][s], ring[1][t], ring[1][s], mid);
        }
    }
}

static int build_tree_models(struct tw_forest_models *models, struct tw_mesh_builder *b,
                             struct tw_tileset *ts, uint64_t seed)
{
    int err = TW_OK;
    for (uint32_t k = 0; k < TW_TREE_MODELS && !err; k++) {
        const struct tw_tree_recipe *mr = &tw_tree_recipes[k];
        struct tw_tree_model *m = &models->trees[k];
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)k, 0x74726565);
        m->trunk = TW_TREE_NO_TRUNK;

        tw_mesh_builder_reset(b, false);
        if (mr->species == TW_FOREST_SPECIES_SPRUCE || mr->species == TW_FOREST_SPECIES_FIR)
            emit_conifer_crown(b, &r, mr);
        else
            emit_leafy_crown(b, &r, mr);
        /* Young spruces keep their skirts to the ground, which hides the
         * trunk: one instance per tree, a stub keeps the skirt from
         * floating. Old ones have shed their lower branches. */
        const bool skirted = mr->species == TW_FOREST_SPECIES_SPRUCE && mr->crown_base < 1.0f;
        if (skirted)
            emit_trunk(b, mr->trunk_radius, mr->crown_base + 0.4f, 5,
                       tw_rng_range(&r, 0.0f, TW_TAU));
        if ((err = tw_mesh_builder_add_to(b, ts, &m->canopy)) || (err = append_profile(m, b)))
            break;
        if (skirted)
            continue;

        tw_mesh_builder_reset(b, false);
        /* Up into the crown, where it ends unseen. */
        const float crown_h = mr->height - mr->crown_base;
        const bool conifer =
            mr->species == TW_FOREST_SPECIES_FIR || mr->species == TW_FOREST_SPECIES_SPRUCE;
        const float top = conifer ? 0.55f * mr->height
                          : mr->species == TW_FOREST_SPECIES_BIRCH
                              ? 0.85f * mr->height
                              : mr->crown_base + 0.45f * crown_h;
        emit_trunk(b, mr->trunk_radius, top, mr->species == TW_FOREST_SPECIES_BIRCH ? 5 : 6,
                   tw_rng_range(&r, 0.0f, TW_TAU));
        if (mr->species == TW_FOREST_SPECIES_BEECH)
            emit_limbs(b, &r, mr);
        if (!(err = tw_mesh_builder_add_to(b, ts, &m->trunk)))
            err = append_profile(m, b);
    }
    return err;
}

/* Rock shapes: lumpy, flattened blobs cut flat at the ground; unit size. */
static int build_rocks(struct tw_forest_models *models, struct tw_mesh_builder *b,
                       struct tw_tileset *ts, uint64_t seed)
{
    int err = TW_OK;
    for (uint32_t k = 0; k < TW_ROCK_SHAPES && !err; k++) {
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)k, 0x726f636b);
        struct tw_lumps l;
        tw_lumps_init(&l, &r, 1.6f);
        tw_mesh_builder_reset(b, false);
        const float ry = tw_rng_range(&r, 0.55f, 0.8f);
        const float centre[3] = {0.0f, 0.25f * ry, 0.0f};
        const float radius[3] = {1.0f, ry, tw_rng_range(&r, 0.7f, 1.0f)};
        tw_shape_blob(b, centre, radius, k == TW_ROCK_SHAPES - 1 ? 2 : 1, &l, 0.0f);
        err = tw_mesh_builder_add_to(b, ts, &models->rock[k]);
        models->rock_reach[k] = 0.0f;
        for (uint32_t v = 0; v < b->vertex_count; v++) {
            const float *q = b->positions + 3 * (size_t)v;
            models->rock_reach[k] = fmaxf(models->rock_reach[k], sqrtf(q[0] * q[0] + q[2] * q[2]));
        }
    }
    /* A fallen log along x, centred on the origin, lying on the ground. */
    if (!err) {
        tw_mesh_builder_reset(b, false);
        models->log_length = 7.0f;
        models->log_radius = 0.3f;
        const uint32_t sides = 6;
        const float h = 0.5f * models->log_length, rad = models->log_radius;
        for (uint32_t s = 0; s < sides; s++) {
            const float a0 = TW_TAU * (float)s / (float)sides;
            const float a1 = TW_TAU * (float)(s + 1) / (float)sides;
            const float p0[3] = {-h, rad + rad * sinf(a0), rad * cosf(a0)};
            const float p1[3] = {h, rad + rad * sinf(a0), rad * cosf(a0)};
            const float p2[3] = {h, rad + rad * sinf(a1), rad * cosf(a1)};
            const float p3[3] = {-h, rad + rad * sinf(a1), rad * cosf(a1)};
            const float axis[3] = {0.0f, rad, 0.0f};
            tw_shape_outward(b, p0, p1, p2, axis);
            tw_shape_outward(b, p0, p2, p3, axis);
            const float end0[3] = {-h, rad, 0.0f}, end1[3] = {h, rad, 0.0f};
            const float out0[3] = {-1.0f, 0.0f, 0.0f}, out1[3] = {1.0f, 0.0f, 0.0f};
            tw_shape_triangle(b, end0, p0, p3, out0);
            tw_shape_triangle(b, end1, p1, p2, out1);
        }
        err = tw_mesh_builder_add_to(b, ts, &models->log);
    }
    return err;
}

/* Undergrowth patches: bushes or ferns scattered over a square of side
 * patch_size centred on the origin, kept TW_PATCH_MARGIN from its edges.
 * Levels: sparse, medium, dense. */
static int build_patches(struct tw_forest_models *models, struct tw_mesh_builder *b,
                         struct tw_tileset *ts, uint64_t seed)
{
    static const uint32_t bushes[TW_PATCH_LEVELS] = {4, 7, 11};
    static const uint32_t fern_clumps[TW_PATCH_LEVELS] = {4, 6, 9};
    const float half = 0.5f * models->patch_size;
    int err = TW_OK;
    for (uint32_t level = 0; level < TW_PATCH_LEVELS && !err; level++) {
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)level, 0x62757368);
        tw_mesh_builder_reset(b, false);
        for (uint32_t k = 0; k < bushes[level]; k++) {
            const float size = tw_rng_range(&r, 0.45f, 1.1f);
            const uint32_t blobs = 1 + tw_rng_below(&r, 2);
            /* amount 1: lumps within 1 +- 0.36. */
            /* Lumps reach 1.36 x a blob's radius, side blobs sit 0.6 x out. */
            const float room = half - TW_PATCH_MARGIN - 1.8f * size;
            const float x = tw_rng_range(&r, -room, room), z = tw_rng_range(&r, -room, room);
            for (uint32_t j = 0; j < blobs; j++) {
                struct tw_lumps l;
                tw_lumps_init(&l, &r, 1.0f);
                const float s = j ? size * tw_rng_range(&r, 0.5f, 0.75f) : size;
                const float a = tw_rng_range(&r, 0.0f, TW_TAU), d = j ? 0.6f * size : 0.0f;
                const float centre[3] = {x + d * cosf(a), 0.45f * s, z + d * sinf(a)};
                const float radius[3] = {s, 0.8f * s, s * tw_rng_range(&r, 0.8f, 1.0f)};
                tw_shape_blob(b, centre, radius, 1, &l, 0.0f);
            }
        }
        err = tw_mesh_builder_add_to(b, ts, &models->bush_patch[level]);
        if (err)
            break;

        r = tw_rng_seeded(seed, (int64_t)level, 0x6665726e);
        tw_mesh_builder_reset(b, false);
        for (uint32_t k = 0; k < fern_clumps[level]; k++) {
            const float length = tw_rng_range(&r, 0.5f, 0.95f);
            /* A frond reaches 1.1 x length from its fern. */
            const float room = half - TW_PATCH_MARGIN - 1.15f * length;
            const float x = tw_rng_range(&r, -room, room), z = tw_rng_range(&r, -room, room);
            const uint32_t clump = 1 + tw_rng_below(&r, 3);
            for (uint32_t j = 0; j < clump; j++) {
                const float ox = j ? tw_rng_range(&r, -0.9f, 0.9f) : 0.0f;
                const float oz = j ? tw_rng_range(&r, -0.9f, 0.9f) : 0.0f;
                emit_fern(b, &r, tw_clampf(x + ox, -room, room), 0.0f,
                          tw_clampf(z + oz, -room, room), length);
            }
        }
        err = tw_mesh_builder_add_to(b, ts, &models->fern_patch[level]);
    }
    return err;
}
int tw_forest_models_build(struct tw_forest_models *m, struct tw_mesh_builder *b,
                           struct tw_tileset *ts, uint64_t seed)
{
    m->patch_size = 20.0f;
    int err = build_tree_models(m, b, ts, seed);
    if (!err)
        err = build_rocks(m, b, ts, seed);
    if (!err)
        err = build_patches(m, b, ts, seed);
    return err;
}

int tw_forest_models_copy(struct tw_forest_models *m, const struct tw_forest_models *from)
{
    *m = *from;
    for (uint32_t k = 0; k < TW_TREE_MODELS; k++)
        m->trees[k].profile = NULL;
    for (uint32_t k = 0; k < TW_TREE_MODELS; k++) {
        const struct tw_tree_model *src = &from->trees[k];
        struct tw_tree_model *t = &m->trees[k];
        if (!(t->profile = malloc(sizeof(*t->profile) * src->profile_count)))
            return TW_ERR_NOMEM;
        memcpy(t->profile, src->profile, sizeof(*t->profile) * src->profile_count);
    }
    return TW_OK;
}

void tw_forest_models_finish(struct tw_forest_models *m)
{
    for (uint32_t k = 0; k < TW_TREE_MODELS; k++) {
        free(m->trees[k].profile);
        m->trees[k].profile = NULL;
    }
}
