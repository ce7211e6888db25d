/* The procedural forest tileset (tilesets.h, DESIGN.md §10) and the stand
 * generator that the hybrid shares (tilesets-private.h).
 *
 * A forest hides things only through many weak occluders together: every
 * tree is small next to the tile (a few metres wide, thin trunk, gaps
 * between and inside canopies), but a stand of 150 to 300 of them closes up
 * along a line of sight of a few tiles. A few species x sizes are meshes
 * (conifers of stacked frusta, broadleaves of lumpy blobs, birches); every
 * tree is an instance of its canopy mesh, plus one of its trunk mesh where
 * the canopy does not hide it, turned about y and scaled. Undergrowth
 * (bushes, ferns) is baked into a few patch meshes that tile the stand in
 * quarter turns, so the instance count stays a few hundred. Meshes are flat
 * shaded: every triangle has its own vertices and the face normal.
 *
 * Placement keeps two promises that the tests check: every vertex stays
 * inside the stand's rectangle (so inside the footprint), and within the
 * walking band along the tile borders nothing stands between 0.05 m and
 * TW_FOREST_HEADROOM above the ground. Each mesh carries a profile (per
 * triangle: lowest point, horizontal reach from the axis) against which
 * every candidate placement is tested exactly. */
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"
#include "tiles/array.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const float tau = 6.28318530717958647692f;
static const uint32_t no_mesh = UINT32_MAX;

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : x > hi ? hi : x;
}

/* ---- mesh building -------------------------------------------------------------- */

/* A triangle with its own vertices and its face normal, wound
 * counter-clockwise seen from the side facing points to (the renderer culls
 * back faces). Degenerate triangles are dropped. */
static void emit_triangle(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                          const float p2[3], const float facing[3])
{
    if (b->err)
        return;
    const float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                  e1[0] * e2[1] - e1[1] * e2[0]};
    const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 1e-7f))
        return;
    const bool flip = n[0] * facing[0] + n[1] * facing[1] + n[2] * facing[2] < 0.0f;
    const float scale = (flip ? -1.0f : 1.0f) / len;
    for (int k = 0; k < 3; k++)
        n[k] *= scale;
    if (!tw_mesh_builder_reserve(b, 3, 1))
        return;
    const float *corners[3] = {p0, flip ? p2 : p1, flip ? p1 : p2};
    const uint32_t base = b->vertex_count;
    for (uint32_t v = 0; v < 3; v++) {
        memcpy(b->positions + 3 * (size_t)(base + v), corners[v], sizeof(float) * 3);
        memcpy(b->normals + 3 * (size_t)(base + v), n, sizeof(float) * 3);
        b->indices[3 * (size_t)b->triangle_count + v] = base + v;
    }
    b->vertex_count += 3;
    b->triangle_count++;
}

/* A triangle of a star-shaped solid around inside: it faces away from it. */
static void emit_outward(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                         const float p2[3], const float inside[3])
{
    float facing[3];
    for (int k = 0; k < 3; k++)
        facing[k] = (p0[k] + p1[k] + p2[k]) / 3.0f - inside[k];
    emit_triangle(b, p0, p1, p2, facing);
}

/* Both sides of a thin leaf. */
static void emit_two_sided(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                           const float p2[3])
{
    const float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    const float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                        e1[0] * e2[1] - e1[1] * e2[0]};
    const float m[3] = {-n[0], -n[1], -n[2]};
    emit_triangle(b, p0, p1, p2, n);
    emit_triangle(b, p0, p1, p2, m);
}

/* A vertical frustum about (cx, cz) from radius r0 at y0 to r1 at y1 (r1 = 0:
 * a cone), sides faces, the ring turned by phase radians; a bottom cap
 * facing down when asked. */
static void emit_frustum(struct tw_mesh_builder *b, float cx, float cz, float y0, float y1, float r0,
                         float r1, uint32_t sides, float phase, bool bottom_cap)
{
    for (uint32_t k = 0; k < sides; k++) {
        const float a0 = phase + tau * (float)k / (float)sides;
        const float a1 = phase + tau * (float)(k + 1) / (float)sides;
        const float c0 = cosf(a0), s0 = sinf(a0), c1 = cosf(a1), s1 = sinf(a1);
        const float p0[3] = {cx + r0 * c0, y0, cz + r0 * s0};
        const float p1[3] = {cx + r0 * c1, y0, cz + r0 * s1};
        const float p2[3] = {cx + r1 * c1, y1, cz + r1 * s1};
        const float p3[3] = {cx + r1 * c0, y1, cz + r1 * s0};
        /* Outward in the horizontal: right for any slope. */
        const float facing[3] = {c0 + c1, 0.0f, s0 + s1};
        emit_triangle(b, p0, p1, p2, facing);
        if (r1 > 0.0f)
            emit_triangle(b, p0, p2, p3, facing);
    }
    if (bottom_cap) {
        const float down[3] = {0.0f, -1.0f, 0.0f};
        const float first[3] = {cx + r0 * cosf(phase), y0, cz + r0 * sinf(phase)};
        for (uint32_t k = 1; k + 1 < sides; k++) {
            const float a0 = phase + tau * (float)k / (float)sides;
            const float a1 = phase + tau * (float)(k + 1) / (float)sides;
            const float p1[3] = {cx + r0 * cosf(a0), y0, cz + r0 * sinf(a0)};
            const float p2[3] = {cx + r0 * cosf(a1), y0, cz + r0 * sinf(a1)};
            emit_triangle(b, first, p1, p2, down);
        }
    }
}

/* A smooth radial bumpiness for blobs: a function of the direction only,
 * so the vertices shared by neighbouring faces agree and no cracks open. */
struct lumps {
    float axis[4][3];
    float freq[4], phase[4], amp[4];
};

static void lumps_init(struct lumps *l, struct tw_rng *r, float amount)
{
    for (int k = 0; k < 4; k++) {
        const float y = tw_rng_range(r, -1.0f, 1.0f), a = tw_rng_range(r, 0.0f, tau);
        const float h = sqrtf(fmaxf(0.0f, 1.0f - y * y));
        l->axis[k][0] = h * cosf(a);
        l->axis[k][1] = y;
        l->axis[k][2] = h * sinf(a);
        l->freq[k] = tw_rng_range(r, 1.5f, 4.0f);
        l->phase[k] = tw_rng_range(r, 0.0f, tau);
        l->amp[k] = amount * tw_rng_range(r, 0.04f, 0.09f);
    }
}

static float lumps_at(const struct lumps *l, const float d[3])
{
    float s = 1.0f;
    for (int k = 0; k < 4; k++)
        s += l->amp[k] * sinf(l->freq[k] * (d[0] * l->axis[k][0] + d[1] * l->axis[k][1] +
                                            d[2] * l->axis[k][2]) + l->phase[k]);
    return s;
}

/* A blob: a lumpy ellipsoid of radius about centre cut flat at floor_y
 * (tw_icosphere_each). */
struct blob {
    struct tw_mesh_builder *b;
    const float *centre, *radius;
    const struct lumps *lumps;      /* NULL: smooth */
    float floor_y;
};

static void blob_triangle(void *user, const float v[3][3], const float len[3])
{
    const struct blob *bl = user;
    float p[3][3];
    for (int k = 0; k < 3; k++) {
        float dir[3];
        for (int d = 0; d < 3; d++)
            dir[d] = v[k][d] / len[k];
        const float s = bl->lumps ? lumps_at(bl->lumps, dir) : 1.0f;
        for (int d = 0; d < 3; d++)
            p[k][d] = bl->centre[d] + bl->radius[d] * s * dir[d];
        p[k][1] = fmaxf(p[k][1], bl->floor_y);
    }
    emit_outward(bl->b, p[0], p[1], p[2], bl->centre);
}

/* An icosahedron with every face split into n x n triangles, pushed onto a
 * lumpy ellipsoid and cut flat at floor_y: 20 n^2 triangles. */
static void emit_blob(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                      uint32_t n, const struct lumps *lumps, float floor_y)
{
    struct blob bl = {b, centre, radius, lumps, floor_y};
    tw_icosphere_each(n, blob_triangle, &bl);
}

/* A fern: fronds arching out from (x, y, z), each a two-sided folded kite. */
static void emit_fern(struct tw_mesh_builder *b, struct tw_rng *r, float x, float y, float z,
                      float length)
{
    const uint32_t fronds = 5 + tw_rng_below(r, 3);
    const float turn = tw_rng_range(r, 0.0f, tau);
    for (uint32_t k = 0; k < fronds; k++) {
        const float a = turn + tau * ((float)k + tw_rng_range(r, -0.25f, 0.25f)) / (float)fronds;
        const float len = length * tw_rng_range(r, 0.75f, 1.1f);
        const float dx = cosf(a), dz = sinf(a), width = 0.16f * len;
        const float rise = tw_rng_range(r, 0.45f, 0.65f) * len;
        const float base[3] = {x + 0.05f * dx, y + 0.02f, z + 0.05f * dz};
        const float tip[3] = {x + len * dx, y + 0.2f * rise, z + len * dz};
        const float mid_l[3] = {x + 0.55f * len * dx - width * dz, y + rise,
                                z + 0.55f * len * dz + width * dx};
        const float mid_r[3] = {x + 0.55f * len * dx + width * dz, y + rise,
                                z + 0.55f * len * dz - width * dx};
        emit_two_sided(b, base, mid_r, tip);
        emit_two_sided(b, base, tip, mid_l);
    }
}

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

/* The forest tileset's own: the hybrid has no trails. */
static const float trail_colour[4] = {0.62f, 0.53f, 0.38f, 1.0f};

/* ---- tree species x sizes ----------------------------------------------------------- */

enum species { SPRUCE, FIR, PINE, BEECH, BIRCH, SPECIES_COUNT };

_Static_assert((int)SPECIES_COUNT == (int)TW_FOREST_SPECIES_COUNT &&
                   (int)SPRUCE == (int)TW_FOREST_SPECIES_SPRUCE &&
                   (int)FIR == (int)TW_FOREST_SPECIES_FIR &&
                   (int)PINE == (int)TW_FOREST_SPECIES_PINE &&
                   (int)BEECH == (int)TW_FOREST_SPECIES_BEECH &&
                   (int)BIRCH == (int)TW_FOREST_SPECIES_BIRCH,
               "species in the order of tilesets-private.h");

/* The ranges that placements scale meshes by; tw_forest_stands_max_top()
 * bounds heights with their upper ends. */
static const float tree_scale[2] = {0.85f, 1.15f};      /* horizontal, and vertical with: */
static const float tree_stretch[2] = {0.92f, 1.08f};    /* vertical over horizontal */
static const float outcrop_size[2] = {3.0f, 4.6f};
static const float boulder_size[2] = {0.5f, 1.1f}, boulder_spread[2] = {0.6f, 2.0f};
static const float rock_stretch[2] = {0.85f, 1.15f};    /* vertical over horizontal */
static const float log_scale[2] = {0.6f, 1.1f};

/* One size of one species, in metres: the meshes are built at this size and
 * each instance scales it by about 0.85 to 1.15. */
struct model_recipe {
    uint32_t species;
    float height;
    float radius;       /* of the crown */
    float crown_base;   /* lowest point of the crown */
    float trunk_radius;
    uint32_t layers;    /* conifers: frusta; others: blobs */
    uint32_t sides;     /* conifers: sides of each frustum; others: blob subdivision */
};

static const struct model_recipe model_recipes[] = {
    {SPRUCE, 4.2f, 1.35f, 0.12f, 0.10f, 3, 6},
    {SPRUCE, 10.5f, 2.05f, 0.18f, 0.20f, 4, 7},
    {SPRUCE, 18.5f, 2.85f, 3.2f, 0.32f, 5, 8},
    {FIR, 9.0f, 1.75f, 1.9f, 0.18f, 4, 7},
    {FIR, 16.0f, 2.45f, 2.8f, 0.30f, 5, 8},
    {PINE, 14.0f, 2.2f, 8.0f, 0.20f, 3, 1},
    {PINE, 21.0f, 2.8f, 12.5f, 0.28f, 4, 1},
    {BEECH, 11.0f, 3.1f, 3.4f, 0.24f, 3, 1},
    {BEECH, 18.0f, 4.6f, 5.2f, 0.40f, 4, 2},
    {BIRCH, 10.0f, 1.5f, 3.6f, 0.13f, 3, 1},
    {BIRCH, 15.0f, 2.0f, 5.6f, 0.17f, 4, 1},
};

enum { MODEL_COUNT = sizeof(model_recipes) / sizeof(model_recipes[0]) };

/* Per triangle: its lowest point and its horizontal reach from the axis. */
struct profile_entry {
    float min_y;
    float reach;
};

struct tree_model {
    uint32_t canopy, trunk;         /* trunk: no_mesh when the canopy hides it */
    float reach;                    /* horizontal reach of any vertex from the axis */
    struct profile_entry *profile;  /* of canopy and trunk together */
    uint32_t profile_count;
};

/* ---- the generator's state ------------------------------------------------------------ */

enum { PATCH_LEVELS = 3, ROCK_SHAPES = 4 };

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
    struct tree_model models[MODEL_COUNT];
    uint32_t rock[ROCK_SHAPES];
    float rock_reach[ROCK_SHAPES];
    uint32_t log;
    float log_length, log_radius;
    uint32_t bush_patch[PATCH_LEVELS], fern_patch[PATCH_LEVELS];
    float patch_size;

    struct tw_mesh_builder builder;
    struct placed *placed;
    uint32_t placed_count, placed_cap;

    /* Made by the first tw_forest_stands_add_floor(). */
    bool has_floor;
    float floor_band;
    uint32_t floor_mesh, trail_mesh, trail_material;

    /* A generator made by tw_forest_stands_create_from(): the mesh indices
     * above (but the floor's) are source's, and local maps each to its copy
     * in ts, no_mesh until first placed. NULL: they are ts's own. */
    const struct tw_tileset *source;
    uint32_t *local;
};

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
    if (f->local[mesh] == no_mesh) {
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

static int add_mesh(struct tw_forest_stands *f, uint32_t *mesh)
{
    if (!f->builder.err && f->builder.triangle_count == 0)
        return TW_ERR_INVALID;
    return tw_mesh_builder_add_to(&f->builder, f->ts, mesh);
}

/* Appends the profile of the builder's triangles to the model's. */
static int append_profile(struct tree_model *m, const struct tw_mesh_builder *b)
{
    struct profile_entry *p =
        realloc(m->profile, sizeof(*p) * (m->profile_count + b->triangle_count));
    if (!p)
        return TW_ERR_NOMEM;
    m->profile = p;
    for (uint32_t t = 0; t < b->triangle_count; t++) {
        struct profile_entry e = {1e30f, 0.0f};
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

/* The reach of the triangles of m that come below height (mesh-local y
 * scaled by sy), scaled by sxz; 0 if none does. */
static float model_reach_below(const struct tree_model *m, float height, float sxz, float sy)
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
                               const struct model_recipe *mr)
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
        emit_frustum(b, tw_rng_range(r, -0.05f, 0.05f) * r0, tw_rng_range(r, -0.05f, 0.05f) * r0, y0,
                     y1, r0, r1, mr->sides, tw_rng_range(r, 0.0f, tau), true);
    }
}

/* A tapered trunk from the ground to top, closed at the top. */
static void emit_trunk(struct tw_mesh_builder *b, float radius, float top, uint32_t sides,
                       float phase)
{
    emit_frustum(b, 0.0f, 0.0f, 0.0f, top, radius, 0.45f * radius, sides, phase, false);
    const float up[3] = {0.0f, 1.0f, 0.0f};
    const float r1 = 0.45f * radius;
    const float first[3] = {r1 * cosf(phase), top, r1 * sinf(phase)};
    for (uint32_t k = 1; k + 1 < sides; k++) {
        const float a0 = phase + tau * (float)k / (float)sides;
        const float a1 = phase + tau * (float)(k + 1) / (float)sides;
        const float p1[3] = {r1 * cosf(a0), top, r1 * sinf(a0)};
        const float p2[3] = {r1 * cosf(a1), top, r1 * sinf(a1)};
        emit_triangle(b, first, p1, p2, up);
    }
}

/* Broadleaf, pine and birch crowns: a main lumpy blob and smaller ones
 * round it, with gaps between them. */
static void emit_leafy_crown(struct tw_mesh_builder *b, struct tw_rng *r, const struct model_recipe *mr)
{
    const float crown_h = mr->height - mr->crown_base;
    const float cy = mr->crown_base + 0.5f * crown_h;
    struct lumps l;
    const float squash = mr->species == PINE ? 0.55f : mr->species == BIRCH ? 1.3f : 0.78f;
    /* The main blob. */
    const float main_r = mr->species == BIRCH ? 0.8f * mr->radius : 0.72f * mr->radius;
    const float main_ry = fminf(0.5f * crown_h, main_r * squash);
    lumps_init(&l, r, 1.0f);
    const float centre[3] = {0.0f, cy + 0.05f * crown_h, 0.0f};
    const float radius[3] = {main_r, main_ry, main_r * tw_rng_range(r, 0.9f, 1.05f)};
    emit_blob(b, centre, radius, mr->sides, &l, -1e30f);
    /* Satellites round the main one, at random heights in the crown. */
    const uint32_t n = mr->layers;
    const float turn = tw_rng_range(r, 0.0f, tau);
    for (uint32_t k = 0; k < n; k++) {
        const float a = turn + tau * ((float)k + tw_rng_range(r, -0.2f, 0.2f)) / (float)n;
        const float sr = mr->radius * tw_rng_range(r, 0.36f, 0.48f);
        const float sry = fminf(sr * squash, 0.35f * crown_h);
        const float out = mr->radius - sr;
        const float sy = mr->crown_base + sry + tw_rng_range(r, 0.0f, 1.0f) *
                         fmaxf(0.0f, crown_h - 2.0f * sry) * (mr->species == BIRCH ? 1.0f : 0.6f);
        lumps_init(&l, r, 1.0f);
        const float c[3] = {out * cosf(a), sy, out * sinf(a)};
        const float rad[3] = {sr, sry, sr};
        emit_blob(b, c, rad, 1, &l, -1e30f);
    }
}

/* Two short limbs from the trunk into the crown. */
static void emit_limbs(struct tw_mesh_builder *b, struct tw_rng *r, const struct model_recipe *mr)
{
    const float turn = tw_rng_range(r, 0.0f, tau);
    for (int k = 0; k < 2; k++) {
        const float a = turn + (float)k * 0.5f * tau + tw_rng_range(r, -0.4f, 0.4f);
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
            emit_outward(b, ring[0][s], ring[0][t], ring[1][t], mid);
            emit_outward(b, ring[0][s], ring[1][t], ring[1][s], mid);
        }
    }
}

static int build_tree_models(struct tw_forest_stands *f, uint64_t seed)
{
    struct tw_mesh_builder *b = &f->builder;
    int err = TW_OK;
    for (uint32_t k = 0; k < MODEL_COUNT && !err; k++) {
        const struct model_recipe *mr = &model_recipes[k];
        struct tree_model *m = &f->models[k];
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)k, 0x74726565);
        m->trunk = no_mesh;

        tw_mesh_builder_reset(b, false);
        if (mr->species == SPRUCE || mr->species == FIR)
            emit_conifer_crown(b, &r, mr);
        else
            emit_leafy_crown(b, &r, mr);
        /* Young spruces keep their skirts to the ground, which hides the
         * trunk: one instance per tree, a stub keeps the skirt from
         * floating. Old ones have shed their lower branches. */
        const bool skirted = mr->species == SPRUCE && mr->crown_base < 1.0f;
        if (skirted)
            emit_trunk(b, mr->trunk_radius, mr->crown_base + 0.4f, 5, tw_rng_range(&r, 0.0f, tau));
        if ((err = add_mesh(f, &m->canopy)) || (err = append_profile(m, b)))
            break;
        if (skirted)
            continue;

        tw_mesh_builder_reset(b, false);
        /* Up into the crown, where it ends unseen. */
        const float crown_h = mr->height - mr->crown_base;
        const float top = mr->species == FIR || mr->species == SPRUCE ? 0.55f * mr->height
                          : mr->species == BIRCH ? 0.85f * mr->height
                                                 : mr->crown_base + 0.45f * crown_h;
        emit_trunk(b, mr->trunk_radius, top, mr->species == BIRCH ? 5 : 6,
                   tw_rng_range(&r, 0.0f, tau));
        if (mr->species == BEECH)
            emit_limbs(b, &r, mr);
        if (!(err = add_mesh(f, &m->trunk)))
            err = append_profile(m, b);
    }
    return err;
}

/* Rock shapes: lumpy, flattened blobs cut flat at the ground; unit size. */
static int build_rocks(struct tw_forest_stands *f, uint64_t seed)
{
    struct tw_mesh_builder *b = &f->builder;
    int err = TW_OK;
    for (uint32_t k = 0; k < ROCK_SHAPES && !err; k++) {
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)k, 0x726f636b);
        struct lumps l;
        lumps_init(&l, &r, 1.6f);
        tw_mesh_builder_reset(b, false);
        const float ry = tw_rng_range(&r, 0.55f, 0.8f);
        const float centre[3] = {0.0f, 0.25f * ry, 0.0f};
        const float radius[3] = {1.0f, ry, tw_rng_range(&r, 0.7f, 1.0f)};
        emit_blob(b, centre, radius, k == ROCK_SHAPES - 1 ? 2 : 1, &l, 0.0f);
        err = add_mesh(f, &f->rock[k]);
        f->rock_reach[k] = 0.0f;
        for (uint32_t v = 0; v < b->vertex_count; v++) {
            const float *q = b->positions + 3 * (size_t)v;
            f->rock_reach[k] = fmaxf(f->rock_reach[k], sqrtf(q[0] * q[0] + q[2] * q[2]));
        }
    }
    /* A fallen log along x, centred on the origin, lying on the ground. */
    if (!err) {
        tw_mesh_builder_reset(b, false);
        f->log_length = 7.0f;
        f->log_radius = 0.3f;
        const uint32_t sides = 6;
        const float h = 0.5f * f->log_length, rad = f->log_radius;
        for (uint32_t s = 0; s < sides; s++) {
            const float a0 = tau * (float)s / (float)sides;
            const float a1 = tau * (float)(s + 1) / (float)sides;
            const float p0[3] = {-h, rad + rad * sinf(a0), rad * cosf(a0)};
            const float p1[3] = {h, rad + rad * sinf(a0), rad * cosf(a0)};
            const float p2[3] = {h, rad + rad * sinf(a1), rad * cosf(a1)};
            const float p3[3] = {-h, rad + rad * sinf(a1), rad * cosf(a1)};
            const float axis[3] = {0.0f, rad, 0.0f};
            emit_outward(b, p0, p1, p2, axis);
            emit_outward(b, p0, p2, p3, axis);
            const float end0[3] = {-h, rad, 0.0f}, end1[3] = {h, rad, 0.0f};
            const float out0[3] = {-1.0f, 0.0f, 0.0f}, out1[3] = {1.0f, 0.0f, 0.0f};
            emit_triangle(b, end0, p0, p3, out0);
            emit_triangle(b, end1, p1, p2, out1);
        }
        err = add_mesh(f, &f->log);
    }
    return err;
}

/* Undergrowth patches: bushes or ferns scattered over a square of side
 * patch_size centred on the origin, kept margin from its edges so that
 * quarter turns and the walking band leave them whole. Levels: sparse,
 * medium, dense. */
static const float patch_margin = 1.0f;

static int build_patches(struct tw_forest_stands *f, uint64_t seed)
{
    static const uint32_t bushes[PATCH_LEVELS] = {4, 7, 11};
    static const uint32_t fern_clumps[PATCH_LEVELS] = {4, 6, 9};
    struct tw_mesh_builder *b = &f->builder;
    const float half = 0.5f * f->patch_size;
    int err = TW_OK;
    for (uint32_t level = 0; level < PATCH_LEVELS && !err; level++) {
        struct tw_rng r = tw_rng_seeded(seed, (int64_t)level, 0x62757368);
        tw_mesh_builder_reset(b, false);
        for (uint32_t k = 0; k < bushes[level]; k++) {
            const float size = tw_rng_range(&r, 0.45f, 1.1f);
            const uint32_t blobs = 1 + tw_rng_below(&r, 2);
            /* amount 1: lumps within 1 +- 0.36. */
            /* Lumps reach 1.36 x a blob's radius, side blobs sit 0.6 x out. */
            const float room = half - patch_margin - 1.8f * size;
            const float x = tw_rng_range(&r, -room, room), z = tw_rng_range(&r, -room, room);
            for (uint32_t j = 0; j < blobs; j++) {
                struct lumps l;
                lumps_init(&l, &r, 1.0f);
                const float s = j ? size * tw_rng_range(&r, 0.5f, 0.75f) : size;
                const float a = tw_rng_range(&r, 0.0f, tau), d = j ? 0.6f * size : 0.0f;
                const float centre[3] = {x + d * cosf(a), 0.45f * s, z + d * sinf(a)};
                const float radius[3] = {s, 0.8f * s, s * tw_rng_range(&r, 0.8f, 1.0f)};
                emit_blob(b, centre, radius, 1, &l, 0.0f);
            }
        }
        err = add_mesh(f, &f->bush_patch[level]);
        if (err)
            break;

        r = tw_rng_seeded(seed, (int64_t)level, 0x6665726e);
        tw_mesh_builder_reset(b, false);
        for (uint32_t k = 0; k < fern_clumps[level]; k++) {
            const float length = tw_rng_range(&r, 0.5f, 0.95f);
            /* A frond reaches 1.1 x length from its fern. */
            const float room = half - patch_margin - 1.15f * length;
            const float x = tw_rng_range(&r, -room, room), z = tw_rng_range(&r, -room, room);
            const uint32_t clump = 1 + tw_rng_below(&r, 3);
            for (uint32_t j = 0; j < clump; j++) {
                const float ox = j ? tw_rng_range(&r, -0.9f, 0.9f) : 0.0f;
                const float oz = j ? tw_rng_range(&r, -0.9f, 0.9f) : 0.0f;
                emit_fern(b, &r, clampf(x + ox, -room, room), 0.0f, clampf(z + oz, -room, room),
                          length);
            }
        }
        err = add_mesh(f, &f->fern_patch[level]);
    }
    return err;
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
    float mix[SPECIES_COUNT];       /* species weights */
    float big;                      /* share of the largest size */
    float spacing;                  /* trunks at least spacing x (crown_a + crown_b) apart */
    uint32_t boulders, outcrops, logs;
    float clearing;                 /* glade radius over the area's smaller side; 0: none */
    uint32_t undergrowth;           /* patch level, 0 to PATCH_LEVELS - 1 */
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
/* The models of species: count of them from first, sizes in order. */
static void species_models(uint32_t species, uint32_t *first, uint32_t *count)
{
    *first = 0;
    *count = 0;
    for (uint32_t k = 0; k < MODEL_COUNT; k++) {
        if (model_recipes[k].species != species)
            continue;
        if (!*count)
            *first = k;
        (*count)++;
    }
}

static uint32_t pick_model(struct tw_rng *r, uint32_t species, float big)
{
    uint32_t first, count;
    species_models(species, &first, &count);
    if (count <= 1 || tw_rng_chance(r, big))
        return first + count - 1;
    return first + tw_rng_below(r, count - 1);
}

static uint32_t canopy_material(const struct tw_forest_stands *f, struct tw_rng *r, uint32_t species)
{
    switch (species) {
    case SPRUCE: return f->mat[tw_rng_chance(r, 0.5f) ? MAT_SPRUCE : MAT_SPRUCE_DARK];
    case FIR: return f->mat[MAT_FIR];
    case PINE: return f->mat[MAT_PINE];
    case BEECH: return f->mat[tw_rng_chance(r, 0.6f) ? MAT_BEECH : MAT_BEECH_LIGHT];
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
            const uint32_t shape = outcrop ? ROCK_SHAPES - 1 : tw_rng_below(r, ROCK_SHAPES);
            const float size = outcrop ? tw_rng_range(r, outcrop_size[0], outcrop_size[1])
                                       : tw_rng_range(r, boulder_size[0], boulder_size[1]) *
                                             tw_rng_range(r, boulder_spread[0], boulder_spread[1]);
            const float sy = size * tw_rng_range(r, rock_stretch[0], rock_stretch[1]);
            const float reach = f->rock_reach[shape] * size;
            const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
            const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
            const float angle = tw_rng_range(r, 0.0f, tau);
            if (!fits(f, area, x, z, reach, reach))
                continue;
            /* Outcrops stay out of the glade; boulders may lie in it. */
            if (outcrop && in_clearing(clearing, x, z, reach))
                continue;
            if (!spot_free(f, x, z, 0.0f, reach, 0.0f))
                continue;
            err = add_turned(f, proto, f->rock[shape], f->mat[MAT_ROCK], x, area->ground_y, z,
                             angle, size, sy);
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
            const float half = 0.5f * f->log_length * s, rad = f->log_radius * s;
            const float reach = sqrtf(half * half + rad * rad);
            const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
            const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
            const float angle = tw_rng_range(r, 0.0f, tau);
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
            err = add_turned(f, proto, f->log, f->mat[MAT_BARK], x, area->ground_y, z, angle, s, s);
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
        const uint32_t species = pick_weighted(r, sr->mix, SPECIES_COUNT);
        const uint32_t model = pick_model(r, species, sr->big);
        const struct tree_model *m = &f->models[model];
        const float sxz = tw_rng_range(r, tree_scale[0], tree_scale[1]);
        const float sy = sxz * tw_rng_range(r, tree_stretch[0], tree_stretch[1]);
        const float angle = tw_rng_range(r, 0.0f, tau);
        const float x = tw_rng_range(r, area->rect[0], area->rect[2]);
        const float z = tw_rng_range(r, area->rect[1], area->rect[3]);
        const float reach = m->reach * sxz;
        /* A sapling or two may stand at the glade's edge, nothing inside. */
        if (in_clearing(clearing, x, z, -0.3f * clearing[2]) ||
            (in_clearing(clearing, x, z, 0.0f) && model != 0))
            continue;
        const float low = model_reach_below(m, TW_FOREST_HEADROOM, sxz, sy);
        if (!fits(f, area, x, z, reach, low))
            continue;
        /* Crowns may interleave (spruce skirts do); trunks keep clear of
         * rocks and logs. */
        const float crown = model_recipes[model].radius * sxz;
        const float base = 1.5f * model_recipes[model].trunk_radius * sxz;
        if (!spot_free(f, x, z, crown, base, sr->spacing))
            continue;
        err = add_turned(f, proto, m->canopy, canopy_material(f, r, species), x, area->ground_y,
                         z, angle, sxz, sy);
        if (!err && m->trunk != no_mesh)
            err = add_turned(f, proto, m->trunk,
                             f->mat[species == BIRCH ? MAT_BIRCH_BARK : MAT_BARK], x,
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
    const float p = f->patch_size;
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
                level = PATCH_LEVELS - 1;
            level = level < 0 ? 0 : level >= PATCH_LEVELS ? PATCH_LEVELS - 1 : level;
            const uint32_t k = tw_rng_below(r, 4);
            if (area->band > 0.0f &&
                border_distance(f, cx, cz) - 0.5f * p + patch_margin < area->band)
                continue;
            const float m[12] = {turn_cos[k], 0.0f, turn_sin[k], cx,
                                 0.0f, 1.0f, 0.0f, area->ground_y,
                                 -turn_sin[k], 0.0f, turn_cos[k], cz};
            uint32_t mesh = fern ? f->fern_patch[level] : f->bush_patch[level];
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
    f->patch_size = 20.0f;
    int err = add_materials(f);
    if (!err)
        err = build_tree_models(f, seed);
    if (!err)
        err = build_rocks(f, seed);
    if (!err)
        err = build_patches(f, seed);
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
    for (uint32_t k = 0; k < MODEL_COUNT; k++)
        free(f->models[k].profile);
    tw_mesh_builder_release(&f->builder);
    free(f->placed);
    free(f->local);
    free(f);
}

/* ---- the forest tileset ------------------------------------------------------------ */

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
        emit_triangle(b, p0, p1, p2, up);
        emit_triangle(b, p0, p2, p3, up);
    }
    int err = add_mesh(f, floor_mesh);
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
        emit_triangle(b, p0, p1, p2, up);
        emit_triangle(b, p0, p2, p3, up);
    }
    return add_mesh(f, trail_mesh);
}

void tw_tilesets_forest_default_settings(struct tw_forest_settings *s)
{
    if (!s)
        return;
    s->prototypes = 10;
    s->footprint = 80.0f;
    s->density = 1.0f;
    s->path_clearance = 1.0f;
    s->max_cluster_triangles = 2048;
}

int tw_forest_settings_resolve(const struct tw_forest_settings *in,
                               struct tw_forest_settings *out, const struct tw_log *log,
                               const char *who)
{
    tw_tilesets_forest_default_settings(out);
    if (in) {
        if (in->prototypes)
            out->prototypes = in->prototypes;
        if (in->footprint != 0.0f)
            out->footprint = in->footprint;
        if (in->density != 0.0f)
            out->density = in->density;
        if (in->path_clearance != 0.0f)
            out->path_clearance = in->path_clearance;
        if (in->max_cluster_triangles)
            out->max_cluster_triangles = in->max_cluster_triangles;
    }
    if (!tw_procedural_prototypes_valid(out->prototypes, log, who) ||
        !tw_procedural_in_range(out->footprint, 40.0f, 1000.0f, "footprint", " m", log, who) ||
        !tw_procedural_in_range(out->density, 0.25f, 2.0f, "density", "", log, who) ||
        !tw_procedural_in_range(out->path_clearance, 0.1f, 5.0f, "path_clearance", " m", log,
                                who))
        return TW_ERR_INVALID;
    return TW_OK;
}

/* The stands of the forest's prototypes, in order; the list repeats when
 * there are more prototypes. Every kind appears within the first 8. */
static const enum tw_forest_stand_kind forest_order[] = {
    TW_FOREST_STAND_SPRUCE, TW_FOREST_STAND_MIXED,    TW_FOREST_STAND_BEECH,
    TW_FOREST_STAND_THIN,   TW_FOREST_STAND_CLEARING, TW_FOREST_STAND_ROCKY,
    TW_FOREST_STAND_BIRCH,  TW_FOREST_STAND_SPRUCE,   TW_FOREST_STAND_MIXED,
    TW_FOREST_STAND_BEECH,
};

int tw_tilesets_forest(uint64_t seed, const struct tw_forest_settings *settings,
                       const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "forest"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_forest_settings set;
    int err = tw_forest_settings_resolve(settings, &set, log, "forest");
    if (err)
        return err;

    struct tw_tileset *ts = NULL;
    struct tw_forest_stands *stands = NULL;
    uint32_t floor_mesh = 0, trail_mesh = 0;
    int trail_material = 0;
    if ((err = tw_tileset_create("forest", set.footprint, set.footprint, &ts)))
        goto out;
    if ((err = tw_forest_stands_create(ts, seed, &set, &stands)))
        goto out;
    if ((trail_material = tw_tileset_add_material(ts, trail_colour)) < 0) {
        err = trail_material;
        goto out;
    }
    if ((err = build_ground(stands, set.path_clearance, &floor_mesh, &trail_mesh)))
        goto out;

    const uint32_t order_count = sizeof(forest_order) / sizeof(forest_order[0]);
    for (uint32_t k = 0; k < set.prototypes; k++) {
        const enum tw_forest_stand_kind kind = forest_order[k % order_count];
        char name[48];
        snprintf(name, sizeof(name), "forest-%s-%02u", tw_forest_stand_name(kind), k);
        const float weight = kind == TW_FOREST_STAND_CLEARING ? 0.5f
                             : kind == TW_FOREST_STAND_ROCKY  ? 0.7f
                                                              : 1.0f;
        const int proto = tw_tileset_add_prototype(ts, name, weight);
        if (proto < 0) {
            err = proto;
            goto out;
        }
        const int floor_index = tw_tileset_add_instance(ts, (uint32_t)proto, floor_mesh,
                                                        stands->mat[MAT_FLOOR], NULL);
        const int trail_index = floor_index < 0 ? floor_index
                                : tw_tileset_add_instance(ts, (uint32_t)proto, trail_mesh,
                                                          (uint32_t)trail_material, NULL);
        if (trail_index < 0) {
            err = trail_index;
            goto out;
        }
        const struct tw_forest_area area = {
            {0.0f, 0.0f, set.footprint, set.footprint}, 0.0f, set.path_clearance};
        if ((err = tw_forest_stands_add(stands, (uint32_t)proto, kind,
                                        tw_tiles_hash(seed, (int64_t)k, 0x666f72657374), &area)))
            goto out;
    }
out:
    err = tw_procedural_hand_over(ts, err, set.max_cluster_triangles, log, "forest", out);
    tw_forest_stands_destroy(stands);
    return err;
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
    memcpy(f->models, model->models, sizeof(f->models));
    memcpy(f->rock, model->rock, sizeof(f->rock));
    memcpy(f->rock_reach, model->rock_reach, sizeof(f->rock_reach));
    f->log = model->log;
    f->log_length = model->log_length;
    f->log_radius = model->log_radius;
    memcpy(f->bush_patch, model->bush_patch, sizeof(f->bush_patch));
    memcpy(f->fern_patch, model->fern_patch, sizeof(f->fern_patch));
    f->patch_size = model->patch_size;
    int err = TW_OK;
    /* The profiles are the model's until the copies own theirs. */
    for (uint32_t k = 0; k < MODEL_COUNT; k++)
        f->models[k].profile = NULL;
    if (!(f->local = malloc(sizeof(*f->local) * (from->mesh_count ? from->mesh_count : 1))))
        err = TW_ERR_NOMEM;
    for (uint32_t k = 0; !err && k < from->mesh_count; k++)
        f->local[k] = no_mesh;
    for (uint32_t k = 0; k < MODEL_COUNT && !err; k++) {
        const struct tree_model *src = &model->models[k];
        struct tree_model *m = &f->models[k];
        if (!(m->profile = malloc(sizeof(*m->profile) * src->profile_count)))
            err = TW_ERR_NOMEM;
        else
            memcpy(m->profile, src->profile, sizeof(*m->profile) * src->profile_count);
    }
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
    for (int s = 0; s < SPECIES_COUNT; s++) {
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
    for (uint32_t s = 0; s < SPECIES_COUNT; s++) {
        uint32_t first, count;
        species_models(s, &first, &count);
        /* pick_model(): the largest with probability big, the others
         * evenly. */
        double per_tree = 0.0;
        for (uint32_t k = first; k < first + count; k++) {
            const struct tree_model *m = &f->models[k];
            const double p = count <= 1 ? 1.0 : k + 1 == first + count ? big
                                                                       : (1.0 - big) / (count - 1);
            double triangles = mesh_home(f)->meshes[m->canopy].triangle_count;
            if (m->trunk != no_mesh)
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
    for (uint32_t k = 0; k < MODEL_COUNT; k++) {
        top = fmaxf(top, tree * meshes[f->models[k].canopy].box.max[1]);
        if (f->models[k].trunk != no_mesh)
            top = fmaxf(top, tree * meshes[f->models[k].trunk].box.max[1]);
    }
    const float boulder = boulder_size[1] * boulder_spread[1] * rock_stretch[1];
    for (uint32_t k = 0; k < ROCK_SHAPES; k++)
        top = fmaxf(top, boulder * meshes[f->rock[k]].box.max[1]);
    top = fmaxf(top, outcrop_size[1] * rock_stretch[1] * meshes[f->rock[ROCK_SHAPES - 1]].box.max[1]);
    top = fmaxf(top, log_scale[1] * meshes[f->log].box.max[1]);
    for (uint32_t k = 0; k < PATCH_LEVELS; k++) {
        top = fmaxf(top, meshes[f->bush_patch[k]].box.max[1]);
        top = fmaxf(top, meshes[f->fern_patch[k]].box.max[1]);
    }
    return top * (1.0f + 1e-5f);
}
