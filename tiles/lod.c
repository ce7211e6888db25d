/* Levels of detail of a tileset's prototypes (tiles-internal.h, DESIGN §17):
 * each prototype baked into one tile-local mesh and simplified by
 * meshoptimizer, level after level, each with its geometric error. */
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#include <float.h>
#include <math.h>
#include <meshoptimizer.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lod-source-hash.h"
#include "tiles/file-cache.h"

/* No level below this many triangles: what is left is a few boxes. */
#define LOD_MIN_TRIANGLES 8u
/* A box's triangles: the coarsest level there is. */
#define BOX_TRIANGLES 12u

/* One prototype baked: tile-local positions, normals and colours (the
 * material's colour times the vertex colour), every instance drawn. */
struct baked {
    float *pos;
    float *nrm;
    uint8_t *rgba;
    uint32_t *idx;
    uint32_t vertices;
    uint32_t triangles;
};

static void baked_free(struct baked *b)
{
    free(b->pos);
    free(b->nrm);
    free(b->rgba);
    free(b->idx);
    memset(b, 0, sizeof(*b));
}

static int bake(const struct tw_tileset *ts, uint32_t p, struct baked *b)
{
    memset(b, 0, sizeof(*b));
    const struct tw_prototype *proto = &ts->prototypes[p];
    uint32_t *list = malloc(sizeof(*list) * (proto->instance_count ? proto->instance_count : 1));
    if (!list)
        return TW_ERR_NOMEM;
    /* Every instance drawn: those merged into another are drawn by it. */
    uint32_t count = 0;
    uint64_t vertices = 0, triangles = 0;
    for (uint32_t k = 0; k < proto->instance_count; k++) {
        const struct tw_instance *in = &proto->instances[k];
        if (in->merged_into != TW_INSTANCE_NONE)
            continue;
        list[count++] = k;
        vertices += ts->meshes[in->mesh].vertex_count;
        triangles += ts->meshes[in->mesh].triangle_count;
    }
    int err = TW_OK;
    if (vertices > UINT32_MAX || triangles > UINT32_MAX / 3)
        err = TW_ERR_LIMIT;
    if (err || vertices == 0 || triangles == 0)
        goto out;
    b->pos = malloc(sizeof(float) * 3 * (size_t)vertices);
    b->nrm = malloc(sizeof(float) * 3 * (size_t)vertices);
    b->rgba = malloc(4 * (size_t)vertices);
    b->idx = malloc(sizeof(uint32_t) * 3 * (size_t)triangles);
    if (!b->pos || !b->nrm || !b->rgba || !b->idx) {
        baked_free(b);
        err = TW_ERR_NOMEM;
        goto out;
    }
    tw_tileset_bake(ts, p, list, count, b->pos, b->nrm, b->rgba, b->idx, &b->vertices,
                    &b->triangles);
    /* Unit normals: the level's corners take the one nearest a face's. */
    for (uint32_t v = 0; v < b->vertices; v++) {
        float *r = b->nrm + 3 * (size_t)v;
        const float len = sqrtf(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
        for (int c = 0; c < 3; c++)
            r[c] = len > 0.0f ? r[c] / len : (c == 1 ? 1.0f : 0.0f);
    }
out:
    free(list);
    return err;
}

/* Adds the level whose indices (into b's vertices) are idx[0 .. 3 n) to
 * levels as a prototype of one identity instance: the indices ordered for
 * the vertex cache and for overdraw, the vertices compacted to those used. */
static int add_level(struct tw_tileset *levels, uint32_t white, const char *name,
                     const struct baked *b, uint32_t *idx, size_t n)
{
    meshopt_optimizeVertexCache(idx, idx, 3 * n, b->vertices);
    meshopt_optimizeOverdraw(idx, idx, 3 * n, b->pos, b->vertices, sizeof(float) * 3, 1.05f);
    unsigned int *remap = malloc(sizeof(*remap) * b->vertices);
    if (!remap)
        return TW_ERR_NOMEM;
    const size_t used = meshopt_optimizeVertexFetchRemap(remap, idx, 3 * n, b->vertices);
    float *pos = malloc(sizeof(float) * 3 * (size_t)b->vertices);
    float *nrm = malloc(sizeof(float) * 3 * (size_t)b->vertices);
    uint8_t *rgba = malloc(4 * (size_t)b->vertices);
    int err = TW_OK;
    if (!pos || !nrm || !rgba) {
        err = TW_ERR_NOMEM;
        goto out;
    }
    meshopt_remapIndexBuffer(idx, idx, 3 * n, remap);
    meshopt_remapVertexBuffer(pos, b->pos, b->vertices, sizeof(float) * 3, remap);
    meshopt_remapVertexBuffer(nrm, b->nrm, b->vertices, sizeof(float) * 3, remap);
    meshopt_remapVertexBuffer(rgba, b->rgba, b->vertices, 4, remap);
    const int mesh = tw_tileset_add_mesh(levels, pos, nrm, (uint32_t)used, idx, (uint32_t)n);
    if (mesh < 0) {
        err = mesh;
        goto out;
    }
    levels->meshes[mesh].colors = rgba;     /* the tileset's now */
    rgba = NULL;
    const int proto = tw_tileset_add_prototype(levels, name, 1.0f);
    if (proto < 0) {
        err = proto;
        goto out;
    }
    const int inst = tw_tileset_add_instance(levels, (uint32_t)proto, (uint32_t)mesh, white, NULL);
    if (inst < 0)
        err = inst;
out:
    free(remap);
    free(pos);
    free(nrm);
    free(rgba);
    return err;
}

/* The baked mesh welded by position and colour: what the simplifier sees
 * (a box whose faces have vertices of their own is a closed surface to it,
 * not six loose quads), and for each welded vertex the baked vertices it
 * stands for (one place, one colour), to give each corner of a simplified
 * triangle back its own normal. */
struct welded {
    float *pos;
    uint32_t *idx;
    uint32_t vertices;
    uint32_t *first;    /* welded vertex w stands for baked vertices of[first[w] .. first[w + 1]) */
    uint32_t *of;
};

static void welded_free(struct welded *w)
{
    free(w->pos);
    free(w->idx);
    free(w->first);
    free(w->of);
    memset(w, 0, sizeof(*w));
}

static int weld(const struct baked *b, struct welded *w)
{
    memset(w, 0, sizeof(*w));
    unsigned int *remap = malloc(sizeof(*remap) * b->vertices);
    w->idx = malloc(sizeof(uint32_t) * 3 * (size_t)b->triangles);
    if (!remap || !w->idx) {
        free(remap);
        welded_free(w);
        return TW_ERR_NOMEM;
    }
    /* Welded by position and colour: a colour's edge (a window on a
     * facade) is a seam the simplifier keeps, where it would otherwise go
     * for the little its depth costs in distance. */
    const struct meshopt_Stream streams[2] = {{b->pos, sizeof(float) * 3, sizeof(float) * 3},
                                              {b->rgba, 4, 4}};
    w->vertices = (uint32_t)meshopt_generateVertexRemapMulti(
        remap, b->idx, 3 * (size_t)b->triangles, b->vertices, streams, 2);
    w->pos = malloc(sizeof(float) * 3 * (size_t)w->vertices);
    w->first = calloc((size_t)w->vertices + 1, sizeof(*w->first));
    w->of = malloc(sizeof(*w->of) * b->vertices);
    if (!w->pos || !w->first || !w->of) {
        free(remap);
        welded_free(w);
        return TW_ERR_NOMEM;
    }
    meshopt_remapIndexBuffer(w->idx, b->idx, 3 * (size_t)b->triangles, remap);
    meshopt_remapVertexBuffer(w->pos, b->pos, b->vertices, sizeof(float) * 3, remap);
    /* Vertices no triangle uses have no welded vertex (~0u). */
    for (uint32_t v = 0; v < b->vertices; v++)
        if (remap[v] != ~0u)
            w->first[remap[v] + 1]++;
    for (uint32_t k = 0; k < w->vertices; k++)
        w->first[k + 1] += w->first[k];
    uint32_t *fill = calloc(w->vertices ? w->vertices : 1, sizeof(*fill));
    if (!fill) {
        free(remap);
        welded_free(w);
        return TW_ERR_NOMEM;
    }
    for (uint32_t v = 0; v < b->vertices; v++)
        if (remap[v] != ~0u)
            w->of[w->first[remap[v]] + fill[remap[v]]++] = v;
    free(fill);
    free(remap);
    return TW_OK;
}

/* ---- the error a level has: measured ------------------------------------------- */

/* meshoptimizer's error is an estimate from its quadrics, of positions
 * only: it underestimates what the eye sees (a roof edge moved, a window
 * gone). A level's error is therefore measured (measure_error below), with
 * a uniform grid over the level's triangles. */

#define GRID_MAX 48

struct grid {
    float lo[3], cell;
    int dim[3];
    uint32_t *first;    /* per cell + 1: its triangles in tri[first[c] .. first[c + 1]) */
    uint32_t *tri;
    struct tw_box *box; /* per triangle: a search visits one from many vertices */
};

static int cell_of(const struct grid *g, int a, float x)
{
    const int c = (int)floorf((x - g->lo[a]) / g->cell);
    return c < 0 ? 0 : c >= g->dim[a] ? g->dim[a] - 1 : c;
}

/* Plain comparisons: fminf and fmaxf, which must order NaNs, are calls. */
static float min3(float a, float b, float c)
{
    const float m = a < b ? a : b;
    return m < c ? m : c;
}

static float max3(float a, float b, float c)
{
    const float m = a > b ? a : b;
    return m > c ? m : c;
}

static void grid_free(struct grid *g)
{
    free(g->first);
    free(g->tri);
    free(g->box);
}

/* Bins triangles idx[0 .. 3 n) of pos into a grid over box. */
static int grid_build(struct grid *g, const struct tw_box *box, const float *pos,
                      const uint32_t *idx, size_t n, float min_cell)
{
    memset(g, 0, sizeof(*g));
    float extent = 0.0f;
    for (int a = 0; a < 3; a++)
        extent = fmaxf(extent, box->max[a] - box->min[a]);
    /* About four cells a triangle at most: a class of a few triangles is
     * not binned into a grid of a hundred thousand cells. */
    const float by_count = extent / cbrtf(4.0f * (float)n + 8.0f);
    g->cell = fmaxf(fmaxf(fmaxf(extent / GRID_MAX, by_count), min_cell), 1e-3f);
    size_t cells = 1;
    for (int a = 0; a < 3; a++) {
        g->lo[a] = box->min[a];
        g->dim[a] = (int)ceilf((box->max[a] - box->min[a]) / g->cell) + 1;
        if (g->dim[a] > GRID_MAX + 1)
            g->dim[a] = GRID_MAX + 1;
        cells *= (size_t)g->dim[a];
    }
    g->first = calloc(cells + 1, sizeof(*g->first));
    g->box = malloc(sizeof(*g->box) * (n ? n : 1));
    if (!g->first || !g->box) {
        grid_free(g);
        return TW_ERR_NOMEM;
    }
    for (size_t t = 0; t < n; t++) {
        const float *a = pos + 3 * (size_t)idx[3 * t], *b = pos + 3 * (size_t)idx[3 * t + 1],
                    *c = pos + 3 * (size_t)idx[3 * t + 2];
        for (int k = 0; k < 3; k++) {
            g->box[t].min[k] = min3(a[k], b[k], c[k]);
            g->box[t].max[k] = max3(a[k], b[k], c[k]);
        }
    }
    size_t refs = 0;
    for (int pass = 0; pass < 2; pass++) {
        for (size_t t = 0; t < n; t++) {
            int c0[3], c1[3];
            for (int a = 0; a < 3; a++) {
                c0[a] = cell_of(g, a, g->box[t].min[a]);
                c1[a] = cell_of(g, a, g->box[t].max[a]);
            }
            for (int z = c0[2]; z <= c1[2]; z++)
                for (int y = c0[1]; y <= c1[1]; y++)
                    for (int x = c0[0]; x <= c1[0]; x++) {
                        const size_t c = ((size_t)z * g->dim[1] + y) * g->dim[0] + x;
                        if (pass == 0)
                            g->first[c + 1]++;
                        else
                            g->tri[g->first[c]++] = (uint32_t)t;
                    }
        }
        if (pass == 0) {
            for (size_t c = 0; c < cells; c++)
                g->first[c + 1] += g->first[c];
            refs = g->first[cells];
            g->tri = malloc(sizeof(*g->tri) * (refs ? refs : 1));
            if (!g->tri) {
                grid_free(g);
                return TW_ERR_NOMEM;
            }
        }
    }
    /* The second pass advanced each cell's start to the next one's: back. */
    for (size_t c = cells; c > 0; c--)
        g->first[c] = g->first[c - 1];
    g->first[0] = 0;
    return TW_OK;
}

static float dot3(const float *a, const float *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Squared distance from p to triangle (a, b, c) (Ericson, Real-Time
 * Collision Detection, 5.1.5). */
static float point_triangle2(const float *p, const float *a, const float *b, const float *c)
{
    const float ab[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const float ac[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const float ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    float q[3];
    const float d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    const float bp[3] = {p[0] - b[0], p[1] - b[1], p[2] - b[2]};
    const float d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    const float cp[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    const float d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    const float va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
    if (d1 <= 0.0f && d2 <= 0.0f) {
        memcpy(q, a, sizeof(q));
    } else if (d3 >= 0.0f && d4 <= d3) {
        memcpy(q, b, sizeof(q));
    } else if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) {
        const float v = d1 / (d1 - d3);
        for (int k = 0; k < 3; k++)
            q[k] = a[k] + v * ab[k];
    } else if (d6 >= 0.0f && d5 <= d6) {
        memcpy(q, c, sizeof(q));
    } else if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) {
        const float w = d2 / (d2 - d6);
        for (int k = 0; k < 3; k++)
            q[k] = a[k] + w * ac[k];
    } else if (va <= 0.0f && (d4 - d3) >= 0.0f && (d5 - d6) >= 0.0f) {
        const float w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int k = 0; k < 3; k++)
            q[k] = b[k] + w * (c[k] - b[k]);
    } else {
        const float denom = 1.0f / (va + vb + vc);
        const float v = vb * denom, w = vc * denom;
        for (int k = 0; k < 3; k++)
            q[k] = a[k] + ab[k] * v + ac[k] * w;
    }
    const float d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
    return dot3(d, d);
}

static uint32_t find_root(uint32_t *parent, uint32_t v)
{
    while (parent[v] != v) {
        parent[v] = parent[parent[v]];
        v = parent[v];
    }
    return v;
}

static void unite(uint32_t *parent, uint32_t a, uint32_t b)
{
    a = find_root(parent, a);
    b = find_root(parent, b);
    if (a != b)
        parent[a < b ? b : a] = a < b ? a : b;
}

/* For each full-detail vertex, the squared size (box diagonal) of its
 * patch: the triangles of its colour connected to it. Removing a patch
 * whole changes colour over that size at most; a vertex no triangle uses
 * gets 0. */
static float *patch_sizes(const struct baked *b, const struct welded *w)
{
    uint32_t *parent = malloc(sizeof(*parent) * b->vertices);
    float *box = malloc(sizeof(float) * 6 * b->vertices);
    float *size2 = calloc(b->vertices ? b->vertices : 1, sizeof(*size2));
    if (!parent || !box || !size2) {
        free(parent);
        free(box);
        free(size2);
        return NULL;
    }
    for (uint32_t v = 0; v < b->vertices; v++)
        parent[v] = v;
    for (uint32_t t = 0; t < b->triangles; t++) {
        unite(parent, b->idx[3 * t], b->idx[3 * t + 1]);
        unite(parent, b->idx[3 * t + 1], b->idx[3 * t + 2]);
    }
    /* Vertices at one place and of one colour (a welded vertex) join
     * their patches. */
    for (uint32_t wv = 0; wv < w->vertices; wv++)
        for (uint32_t i = w->first[wv] + 1; i < w->first[wv + 1]; i++)
            unite(parent, w->of[w->first[wv]], w->of[i]);
    for (uint32_t v = 0; v < b->vertices; v++)
        for (int a = 0; a < 3; a++) {
            box[6 * (size_t)v + a] = INFINITY;
            box[6 * (size_t)v + 3 + a] = -INFINITY;
        }
    for (uint32_t v = 0; v < b->vertices; v++) {
        float *r = box + 6 * (size_t)find_root(parent, v);
        for (int a = 0; a < 3; a++) {
            r[a] = fminf(r[a], b->pos[3 * (size_t)v + a]);
            r[3 + a] = fmaxf(r[3 + a], b->pos[3 * (size_t)v + a]);
        }
    }
    for (size_t k = 0; k < 3 * (size_t)b->triangles; k++) {
        const uint32_t v = b->idx[k];
        const float *r = box + 6 * (size_t)find_root(parent, v);
        float d2 = 0.0f;
        for (int a = 0; a < 3; a++)
            d2 += (r[3 + a] - r[a]) * (r[3 + a] - r[a]);
        size2[v] = d2;
    }
    free(parent);
    free(box);
    return size2;
}

/* A difference of colour (of 255, any channel) that is not one: materials'
 * colours rounded to bytes. */
#define COLOUR_MATCH 8

/* Whether a corner of triangle tri (indices into m) has colour c. */
static bool colour_match(const struct baked *m, const uint32_t *tri, const uint8_t *c)
{
    for (int k = 0; k < 3; k++) {
        const uint8_t *q = m->rgba + 4 * (size_t)tri[k];
        if (abs((int)q[0] - c[0]) <= COLOUR_MATCH && abs((int)q[1] - c[1]) <= COLOUR_MATCH &&
            abs((int)q[2] - c[2]) <= COLOUR_MATCH)
            return true;
    }
    return false;
}

/* The squared distance from p to the nearest triangle of g (indices idx
 * into m) of colour c, or best2 if none is nearer; it may stop at any
 * value at most enough2 (the caller has no use for less): rings of grid
 * cells searched outwards until no farther ring can hold a nearer
 * triangle. */
static float nearest_of_colour2(const struct grid *g, const struct baked *m, const uint32_t *idx,
                                const float *p, const uint8_t *colour, float best2, float enough2)
{
    int c[3];
    for (int a = 0; a < 3; a++)
        c[a] = cell_of(g, a, p[a]);
    const int rmax = g->dim[0] + g->dim[1] + g->dim[2];
    for (int r = 0; r <= rmax; r++) {
        /* A triangle in a cell of ring r or beyond lies at least r - 1
         * cells away (p may lie anywhere in its cell, or beyond the
         * grid's edge, clamped to it). */
        const float reach = (float)(r > 0 ? r - 1 : 0) * g->cell;
        if ((r > 0 && best2 <= reach * reach) || best2 <= enough2)
            return best2;
        /* The shell of ring r only: cost grows as r^2, not r^3. */
        for (int z = c[2] - r; z <= c[2] + r; z++) {
            if (z < 0 || z >= g->dim[2])
                continue;
            for (int y = c[1] - r; y <= c[1] + r; y++) {
                if (y < 0 || y >= g->dim[1])
                    continue;
                const bool face = abs(z - c[2]) == r || abs(y - c[1]) == r;
                const int step = face || r == 0 ? 1 : 2 * r;
                for (int x = c[0] - r; x <= c[0] + r; x += step) {
                    if (x < 0 || x >= g->dim[0])
                        continue;
                    const size_t cell = ((size_t)z * g->dim[1] + y) * g->dim[0] + x;
                    for (uint32_t k = g->first[cell]; k < g->first[cell + 1]; k++) {
                        const uint32_t t = g->tri[k];
                        if (!colour_match(m, idx + 3 * (size_t)t, colour))
                            continue;
                        /* The triangle's box first: most are farther. */
                        if (tw_box_distance2(&g->box[t], p) >= best2)
                            continue;
                        const float d2 = point_triangle2(p, m->pos + 3 * (size_t)idx[3 * t],
                                                         m->pos + 3 * (size_t)idx[3 * t + 1],
                                                         m->pos + 3 * (size_t)idx[3 * t + 2]);
                        if (d2 < best2)
                            best2 = d2;
                    }
                    if (best2 <= enough2)
                        return best2;   /* cannot matter to the caller */
                }
            }
        }
    }
    return best2;
}

static bool stopped(const atomic_bool *stop)
{
    return stop && atomic_load_explicit(stop, memory_order_relaxed);
}

/* Which baked vertices share a triangle: to[first[v] .. first[v + 1]) are
 * v's neighbours (a patch's, by patch_sizes: one triangle, one patch). */
struct adjacency {
    uint32_t *first, *to;
};

static void adjacency_free(struct adjacency *a)
{
    free(a->first);
    free(a->to);
    memset(a, 0, sizeof(*a));
}

static int adjacency_build(const struct baked *b, struct adjacency *a)
{
    a->first = calloc((size_t)b->vertices + 2, sizeof(*a->first));
    a->to = malloc(sizeof(*a->to) * (6 * (size_t)b->triangles + 1));
    if (!a->first || !a->to) {
        adjacency_free(a);
        return TW_ERR_NOMEM;
    }
    for (size_t k = 0; k < 3 * (size_t)b->triangles; k++)
        a->first[b->idx[k] + 2] += 2;
    for (uint32_t v = 0; v < b->vertices; v++)
        a->first[v + 2] += a->first[v + 1];
    /* first[v + 1] is v's fill point, and ends as first[v + 2]'s old start. */
    for (uint32_t t = 0; t < b->triangles; t++)
        for (int c = 0; c < 3; c++) {
            const uint32_t v = b->idx[3 * t + c];
            a->to[a->first[v + 1]++] = b->idx[3 * t + (c + 1) % 3];
            a->to[a->first[v + 1]++] = b->idx[3 * t + (c + 2) % 3];
        }
    return TW_OK;
}

/* The other way round: the largest distance from a level's triangles
 * (idx[0 .. 3 n), into m) to the full-detail triangles of their colour
 * (full, a grid of the full-detail triangles full_idx, into m), at least at_least; a result above
 * give_up may stop short of the largest. A level's corners are
 * full-detail vertices (edge collapse and clustering alike keep some of
 * them), so its edges' midpoints and its triangles' centres are what is
 * asked: a triangle that spans a gap between two windows, or fills a
 * courtyard, paints its colour where the full detail has none. */
static void reverse_error(const struct baked *m, const struct grid *full,
                          const uint32_t *full_idx, const uint32_t *idx, size_t n, float at_least,
                          float give_up, float *out)
{
    float worst2 = at_least * at_least;
    /* No search needs to look farther than past give_up. */
    const float cap2 = isfinite(give_up) ? 4.0f * give_up * give_up + 1e-6f : INFINITY;
    for (size_t t = 0; t < n && worst2 <= give_up * give_up; t++) {
        const float *a = m->pos + 3 * (size_t)idx[3 * t], *b = m->pos + 3 * (size_t)idx[3 * t + 1],
                    *c = m->pos + 3 * (size_t)idx[3 * t + 2];
        const uint8_t *colour = m->rgba + 4 * (size_t)idx[3 * t];
        float q[4][3];
        for (int k = 0; k < 3; k++) {
            q[0][k] = 0.5f * (a[k] + b[k]);
            q[1][k] = 0.5f * (b[k] + c[k]);
            q[2][k] = 0.5f * (c[k] + a[k]);
            q[3][k] = (a[k] + b[k] + c[k]) / 3.0f;
        }
        for (int k = 0; k < 4; k++) {
            const float d2 = nearest_of_colour2(full, m, full_idx, q[k], colour, cap2, worst2);
            if (d2 > worst2)
                worst2 = d2;
        }
    }
    *out = sqrtf(worst2);
}

/* The largest distance from a full-detail vertex of m to a triangle of the
 * level (idx[0 .. 3 n), into m) of the vertex's colour, at most the size of
 * its patch (size2), or at_least if that is larger, over the vertices
 * order[0 .. count) (largest patch first: the first patch too small to
 * raise the worst ends the measure, and any order gives the same result);
 * a result above give_up may stop short of the largest: rings of grid cells
 * searched outwards until no farther ring can hold a nearer triangle. A
 * window removed from a facade is as far as the nearest window left, or its
 * own size, not as the wall behind it: what the eye misses is its colour,
 * over its size. */
static int measure_error(const struct baked *m, const float *size2, const struct adjacency *adj,
                         const uint32_t *order, size_t count, const struct tw_box *box,
                         const uint32_t *idx, size_t n, float at_least, float give_up,
                         const atomic_bool *stop, float *out)
{
    struct grid g;
    /* Cells of half the error already known: a search rarely goes past
     * the second ring. */
    int err = grid_build(&g, box, m->pos, idx, n, 0.5f * at_least);
    uint8_t *known = calloc(m->vertices ? m->vertices : 1, 1);
    float *dist = malloc(sizeof(*dist) * (m->vertices ? m->vertices : 1));
    if (err || !known || !dist) {
        grid_free(&g);
        free(known);
        free(dist);
        return err ? err : TW_ERR_NOMEM;
    }
    /* A vertex the level kept lies on it. */
    for (size_t k = 0; k < 3 * n; k++) {
        known[idx[k]] = 1;
        dist[idx[k]] = 0.0f;
    }
    /* Nothing below at_least is asked: a vertex nearer than that to some
     * triangle is done. */
    float worst2 = at_least * at_least;
    for (size_t i = 0; i < count; i++) {
        if (i % 1024 == 1023 && stopped(stop)) {
            err = TW_ERR_STATE;
            break;
        }
        const uint32_t v = order[i];
        /* The patches left are too small to raise the worst: done. */
        if (size2[v] <= worst2)
            break;
        if (known[v])
            continue;
        const float *p = m->pos + 3 * (size_t)v;
        const uint8_t *colour = m->rgba + 4 * (size_t)v;
        /* Its patch gone, a vertex is off by its patch's size at most. */
        float bound2 = size2[v];
        /* A neighbour of its colour (so of its patch) already measured is
         * as far, plus the edge between them, at most: where that cannot
         * raise the worst, no search. */
        for (uint32_t k = adj->first[v]; k < adj->first[v + 1]; k++) {
            const uint32_t u = adj->to[k];
            if (!known[u] || memcmp(m->rgba + 4 * (size_t)u, colour, 4) != 0)
                continue;
            const float *q = m->pos + 3 * (size_t)u;
            const float e[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
            const float d = dist[u] + sqrtf(dot3(e, e));
            if (d * d < bound2)
                bound2 = d * d;
        }
        float best2 = bound2;
        if (bound2 > worst2)
            best2 = nearest_of_colour2(&g, m, idx, p, colour, bound2, worst2);
        known[v] = 1;
        dist[v] = sqrtf(best2);
        /* A vertex no nearer than the worst so far cannot raise it: the
         * search stopped early for it, and best2 only bounds from above. */
        if (best2 > worst2)
            worst2 = best2;
        /* Past what the caller would take: the rest cannot change that. */
        if (worst2 > give_up * give_up)
            break;
    }
    grid_free(&g);
    free(known);
    free(dist);
    *out = sqrtf(worst2);
    return err;
}

/* Triangles widx[0 .. 3 n) of welded vertices back into baked vertices:
 * each corner the one of its welded vertex's (all of one colour) whose
 * normal is nearest the triangle's own (a box corner takes the vertex of
 * the face it lies on). */
static void unweld(const struct baked *b, const struct welded *w, const uint32_t *widx, size_t n,
                   uint32_t *out)
{
    for (size_t t = 0; t < n; t++) {
        const float *p0 = w->pos + 3 * (size_t)widx[3 * t], *p1 = w->pos + 3 * (size_t)widx[3 * t + 1],
                    *p2 = w->pos + 3 * (size_t)widx[3 * t + 2];
        const float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
        const float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
        const float fn[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                             e1[0] * e2[1] - e1[1] * e2[0]};
        for (int c = 0; c < 3; c++) {
            const uint32_t wv = widx[3 * t + c];
            uint32_t best = w->of[w->first[wv]];
            float best_dot = -INFINITY;
            for (uint32_t k = w->first[wv]; k < w->first[wv + 1]; k++) {
                const float d = dot3(b->nrm + 3 * (size_t)w->of[k], fn);
                if (d > best_dot) {
                    best_dot = d;
                    best = w->of[k];
                }
            }
            out[3 * t + c] = best;
        }
    }
}

/* A level is made colour by colour: the full-detail triangles are sorted
 * into classes by the colour of their first corner, and each class is
 * simplified on its own (its own vertices, its own extent), so that a
 * colour's patch moves over its own surface and never takes another
 * colour's place. Each class's error is measured against its own
 * full-detail vertices; a level's error is the largest of its classes'. */
struct classes {
    uint32_t count;
    uint32_t *first;    /* class c's full-detail triangles: tri[first[c] .. first[c + 1]) */
    uint32_t *tri;
    uint32_t *vfirst;   /* class c's full-detail vertices: vorder[vfirst[c] .. vfirst[c + 1]), */
    uint32_t *vorder;   /* largest patch first */
    struct adjacency adj;   /* of all the full-detail vertices */
    float *error;       /* per class: the error of its triangles now */
};

static void classes_free(struct classes *c)
{
    free(c->first);
    free(c->tri);
    free(c->vfirst);
    free(c->vorder);
    adjacency_free(&c->adj);
    free(c->error);
    memset(c, 0, sizeof(*c));
}

static int classes_make(const struct baked *b, struct classes *c)
{
    memset(c, 0, sizeof(*c));
    uint32_t *of = malloc(sizeof(*of) * ((size_t)b->triangles + 1));
    uint8_t(*colour)[4] = malloc(4 * ((size_t)b->triangles + 1));
    c->tri = malloc(sizeof(*c->tri) * ((size_t)b->triangles + 1));
    if (!of || !colour || !c->tri) {
        free(of);
        free(colour);
        classes_free(c);
        return TW_ERR_NOMEM;
    }
    /* A handful of materials: a linear search over the colours seen. */
    for (uint32_t t = 0; t < b->triangles; t++) {
        const uint8_t *q = b->rgba + 4 * (size_t)b->idx[3 * t];
        uint32_t k = 0;
        while (k < c->count && memcmp(colour[k], q, 4) != 0)
            k++;
        if (k == c->count)
            memcpy(colour[c->count++], q, 4);
        of[t] = k;
    }
    free(colour);
    c->first = calloc((size_t)c->count + 1, sizeof(*c->first));
    c->error = calloc((size_t)c->count + 1, sizeof(*c->error));
    if (!c->first || !c->error) {
        free(of);
        classes_free(c);
        return TW_ERR_NOMEM;
    }
    for (uint32_t t = 0; t < b->triangles; t++)
        c->first[of[t] + 1]++;
    for (uint32_t k = 0; k < c->count; k++)
        c->first[k + 1] += c->first[k];
    uint32_t *fill = calloc((size_t)c->count + 1, sizeof(*fill));
    if (!fill) {
        free(of);
        classes_free(c);
        return TW_ERR_NOMEM;
    }
    for (uint32_t t = 0; t < b->triangles; t++)
        c->tri[c->first[of[t]] + fill[of[t]]++] = t;
    free(fill);
    free(of);
    return TW_OK;
}

struct by_size {
    float size2;
    uint32_t v;
};

static int by_size_cmp(const void *pa, const void *pb)
{
    const struct by_size *a = pa, *b = pb;
    if (a->size2 != b->size2)
        return a->size2 > b->size2 ? -1 : 1;
    return a->v < b->v ? -1 : a->v > b->v;
}

/* Vertices list[0 .. n) sorted by their patch's size (size2), largest
 * first; scratch tmp of n. */
static void sort_by_size(uint32_t *list, size_t n, const float *size2, struct by_size *tmp)
{
    for (size_t i = 0; i < n; i++)
        tmp[i] = (struct by_size){size2[list[i]], list[i]};
    qsort(tmp, n, sizeof(*tmp), by_size_cmp);
    for (size_t i = 0; i < n; i++)
        list[i] = tmp[i].v;
}

/* Each class's full-detail vertices (those of its triangles), largest
 * patch first: what its levels' error is measured at. */
static int classes_order(struct classes *c, const struct baked *b, const float *size2)
{
    uint8_t *seen = calloc((size_t)b->vertices + 1, 1);
    struct by_size *tmp = malloc(sizeof(*tmp) * (3 * (size_t)b->triangles + 1));
    c->vfirst = calloc((size_t)c->count + 1, sizeof(*c->vfirst));
    c->vorder = malloc(sizeof(*c->vorder) * (3 * (size_t)b->triangles + 1));
    if (!seen || !tmp || !c->vfirst || !c->vorder || adjacency_build(b, &c->adj)) {
        free(seen);
        free(tmp);
        return TW_ERR_NOMEM;
    }
    uint32_t n = 0;
    for (uint32_t k = 0; k < c->count; k++) {
        c->vfirst[k] = n;
        for (uint32_t t = c->first[k]; t < c->first[k + 1]; t++)
            for (int j = 0; j < 3; j++) {
                const uint32_t v = b->idx[3 * (size_t)c->tri[t] + j];
                if (!seen[v]) {
                    seen[v] = 1;
                    c->vorder[n++] = v;
                }
            }
        /* A vertex may serve two classes: unmarked for the next. */
        for (uint32_t i = c->vfirst[k]; i < n; i++)
            seen[c->vorder[i]] = 0;
        sort_by_size(c->vorder + c->vfirst[k], n - c->vfirst[k], size2, tmp);
    }
    c->vfirst[c->count] = n;
    free(seen);
    free(tmp);
    return TW_OK;
}

/* A triangle of welded vertices, turned to start at its least (its
 * winding kept): the same triangle gives the same key. */
struct tri_key {
    uint32_t v[3];
};

static struct tri_key tri_key(const uint32_t *t)
{
    const int s = t[0] <= t[1] && t[0] <= t[2] ? 0 : t[1] <= t[2] ? 1 : 2;
    return (struct tri_key){{t[s], t[(s + 1) % 3], t[(s + 2) % 3]}};
}

static int tri_key_cmp(const void *pa, const void *pb)
{
    const struct tri_key *a = pa, *b = pb;
    for (int k = 0; k < 3; k++)
        if (a->v[k] != b->v[k])
            return a->v[k] < b->v[k] ? -1 : 1;
    return 0;
}

/* Scratch for simplifying one class: its triangles over its own vertices. */
struct part {
    uint32_t *local;    /* per welded vertex: its index in the part, or ~0u */
    uint32_t *global;   /* per part vertex: its welded vertex */
    float *pos;
    uint32_t *idx, *a, *b;
    uint32_t *baked;    /* a candidate's triangles in baked vertices */
    struct tri_key *kept;   /* the class's triangles before this level, sorted */
    uint32_t *fresh;    /* a candidate's triangles not among them, baked */
};

static void part_free(struct part *p)
{
    free(p->local);
    free(p->global);
    free(p->pos);
    free(p->idx);
    free(p->a);
    free(p->b);
    free(p->baked);
    free(p->kept);
    free(p->fresh);
}

static int part_alloc(struct part *p, const struct baked *b, const struct welded *w)
{
    memset(p, 0, sizeof(*p));
    const size_t t3 = 3 * (size_t)b->triangles + 1;
    p->local = malloc(sizeof(*p->local) * ((size_t)w->vertices + 1));
    p->global = malloc(sizeof(*p->global) * ((size_t)w->vertices + 1));
    p->pos = malloc(sizeof(float) * 3 * ((size_t)w->vertices + 1));
    p->idx = malloc(sizeof(uint32_t) * t3);
    p->a = malloc(sizeof(uint32_t) * t3);
    p->b = malloc(sizeof(uint32_t) * t3);
    p->baked = malloc(sizeof(uint32_t) * t3);
    p->kept = malloc(sizeof(*p->kept) * ((size_t)b->triangles + 1));
    p->fresh = malloc(sizeof(uint32_t) * t3);
    if (!p->local || !p->global || !p->pos || !p->idx || !p->a || !p->b || !p->baked ||
        !p->kept || !p->fresh) {
        part_free(p);
        return TW_ERR_NOMEM;
    }
    for (uint32_t v = 0; v < w->vertices; v++)
        p->local[v] = ~0u;
    return TW_OK;
}

/* Class k's triangles in[0 .. 3 n) (welded) simplified within target
 * metres, into out (welded): vertex clustering on a grid of the target
 * (it removes parts thinner than a cell: posts, kerbs, a window's reveal)
 * and then edge collapses (they merge what is flat), or edge collapses
 * alone where the clustering costs more than the target, or the triangles
 * as they were. Returns the triangle count; the class's error is raised to
 * what was measured. */
static int simplify_class(const struct baked *b, const struct welded *w, const float *size2,
                          const struct grid *full, const struct tw_box *box, struct classes *cl, uint32_t k,
                          struct part *p, const uint32_t *in, size_t n, float target,
                          const atomic_bool *stop, uint32_t *out, size_t *out_n)
{
    *out_n = n;
    memcpy(out, in, sizeof(uint32_t) * 3 * n);
    if (n == 0)
        return TW_OK;
    uint32_t nv = 0;
    for (size_t i = 0; i < 3 * n; i++) {
        const uint32_t v = in[i];
        if (p->local[v] == ~0u) {
            p->local[v] = nv;
            p->global[nv] = v;
            memcpy(p->pos + 3 * (size_t)nv, w->pos + 3 * (size_t)v, sizeof(float) * 3);
            nv++;
        }
        p->idx[i] = p->local[v];
    }
    for (uint32_t i = 0; i < nv; i++)
        p->local[p->global[i]] = ~0u;
    const float scale = meshopt_simplifyScale(p->pos, nv, sizeof(float) * 3);
    if (!(scale > 0.0f))
        return TW_OK;
    const float rel = target / scale;
    /* The triangles the class has now, each already measured the other way
     * round within cl->error[k] (full detail's at 0): a candidate keeping
     * one unchanged need not ask about it again. Sorted once a candidate
     * gets that far. */
    bool sorted = false;
    /* meshoptimizer's errors are estimates of its own, and the measure
     * counts what they do not (a patch of colour removed costs its size):
     * clustering on a grid of the target's size measured 1.05 to 1.3 times
     * the target on city. So it is asked for half the target first, then
     * a quarter, then an eighth. */
    static const struct {
        bool cluster;
        float share;
    } attempts[] = {{true, 0.5f}, {false, 0.5f}, {true, 0.25f}, {false, 0.25f}, {false, 0.125f}};
    int err = TW_OK;
    for (size_t attempt = 0; attempt < sizeof(attempts) / sizeof(attempts[0]); attempt++) {
        if (stopped(stop)) {
            err = TW_ERR_STATE;
            break;
        }
        const float r = rel * attempts[attempt].share;
        size_t m;
        if (attempts[attempt].cluster) {
            const size_t s = meshopt_simplifySloppy(p->a, p->idx, 3 * n, p->pos, nv,
                                                    sizeof(float) * 3, 0, r, NULL);
            m = meshopt_simplify(p->b, p->a, s, p->pos, nv, sizeof(float) * 3, 0, r, 0, NULL) / 3;
        } else {
            m = meshopt_simplify(p->b, p->idx, 3 * n, p->pos, nv, sizeof(float) * 3, 0, r, 0,
                                 NULL) / 3;
        }
        if (m >= *out_n)
            continue;
        for (size_t i = 0; i < 3 * m; i++)
            p->a[i] = p->global[p->b[i]];
        unweld(b, w, p->a, m, p->baked);
        float measured = 0.0f;
        err = measure_error(b, size2, &cl->adj, cl->vorder + cl->vfirst[k],
                            cl->vfirst[k + 1] - cl->vfirst[k], box, p->baked, m, cl->error[k],
                            target, stop, &measured);
        if (err)
            break;
        if (measured <= target) {
            /* measured >= cl->error[k]: the kept triangles cannot raise it. */
            if (!sorted) {
                for (size_t t = 0; t < n; t++)
                    p->kept[t] = tri_key(in + 3 * t);
                qsort(p->kept, n, sizeof(*p->kept), tri_key_cmp);
                sorted = true;
            }
            size_t fresh = 0;
            for (size_t t = 0; t < m; t++) {
                const struct tri_key key = tri_key(p->a + 3 * t);
                if (!bsearch(&key, p->kept, n, sizeof(*p->kept), tri_key_cmp))
                    memcpy(p->fresh + 3 * fresh++, p->baked + 3 * t, sizeof(uint32_t) * 3);
            }
            reverse_error(b, full, b->idx, p->fresh, fresh, measured, target, &measured);
        }
        if (measured <= target) {
            memcpy(out, p->a, sizeof(uint32_t) * 3 * m);
            *out_n = m;
            cl->error[k] = fmaxf(cl->error[k], measured);
            break;
        }
    }
    return err;
}

/* b's vertices and those of box's faces of some area (4 a face, as
 * triangles idx[0 .. 3 *n), of b's first colour until given another)
 * together, so that the measure and add_level see one mesh. */
static int box_baked(const struct baked *b, const struct tw_box *box, struct baked *x,
                     uint32_t idx[36], size_t *n)
{
    *n = 0;
    memset(x, 0, sizeof(*x));
    const uint32_t nv = b->vertices + 24;
    x->pos = malloc(sizeof(float) * 3 * (size_t)nv);
    x->nrm = malloc(sizeof(float) * 3 * (size_t)nv);
    x->rgba = malloc(4 * (size_t)nv);
    if (!x->pos || !x->nrm || !x->rgba) {
        baked_free(x);
        return TW_ERR_NOMEM;
    }
    memcpy(x->pos, b->pos, sizeof(float) * 3 * (size_t)b->vertices);
    memcpy(x->nrm, b->nrm, sizeof(float) * 3 * (size_t)b->vertices);
    memcpy(x->rgba, b->rgba, 4 * (size_t)b->vertices);
    x->vertices = b->vertices;
    const float *lo = box->min, *hi = box->max;
    for (int a = 0; a < 3; a++) {
        const int u = (a + 1) % 3, w = (a + 2) % 3;
        if (!(hi[u] > lo[u]) || !(hi[w] > lo[w]))
            continue;   /* a face of no area */
        for (int side = 0; side < 2; side++) {
            const uint32_t v0 = x->vertices;
            /* Corners counter-clockwise seen from outside. */
            const float su[4] = {0, 1, 1, 0}, sw[4] = {0, 0, 1, 1};
            for (int k = 0; k < 4; k++) {
                float *q = x->pos + 3 * (size_t)x->vertices;
                float *nq = x->nrm + 3 * (size_t)x->vertices;
                q[a] = side ? hi[a] : lo[a];
                q[u] = su[side ? k : 3 - k] ? hi[u] : lo[u];
                q[w] = sw[side ? k : 3 - k] ? hi[w] : lo[w];
                nq[a] = side ? 1.0f : -1.0f;
                nq[u] = nq[w] = 0.0f;
                memcpy(x->rgba + 4 * (size_t)x->vertices, b->rgba, 4);
                x->vertices++;
            }
            const uint32_t quad[6] = {v0, v0 + 1, v0 + 2, v0, v0 + 2, v0 + 3};
            memcpy(idx + 3 * *n, quad, sizeof(quad));
            *n += 2;
        }
    }
    return TW_OK;
}

/* The box's corners in the colour of b's vertex v. */
static void box_colour(const struct baked *b, struct baked *x, uint32_t v)
{
    for (uint32_t k = b->vertices; k < x->vertices; k++)
        memcpy(x->rgba + 4 * (size_t)k, b->rgba + 4 * (size_t)v, 4);
}

/* The colours a box level is tried in: those covering the most area. */
#define BOX_COLOURS 8

/* The coarsest level where simplifying stopped above a box: box, the
 * prototype's (its faces of no area left out), in the colour of the one
 * of cl's BOX_COLOURS classes of most area whose error is least (a box of
 * the facades' colour leaves the ground's vertices off by the ground's
 * size), added to levels as a level of its own, *added set; its error
 * measured as any level's, at least at_least, into *error, and the vertex
 * of b whose colour it took into *colour. */
static int add_box_level(struct tw_tileset *levels, uint32_t white, const char *name,
                         const struct baked *b, const struct classes *cl, const float *size2,
                         const struct grid *full, const struct tw_box *box, float at_least,
                         float *error, bool *added, uint32_t *colour)
{
    *added = false;
    /* The classes of most area, largest first. */
    double top_area[BOX_COLOURS];
    uint32_t top_vertex[BOX_COLOURS];
    uint32_t tops = 0;
    for (uint32_t k = 0; k < cl->count; k++) {
        double area = 0.0;
        for (uint32_t t = cl->first[k]; t < cl->first[k + 1]; t++) {
            const uint32_t *tri = b->idx + 3 * (size_t)cl->tri[t];
            const float *p0 = b->pos + 3 * (size_t)tri[0], *p1 = b->pos + 3 * (size_t)tri[1],
                        *p2 = b->pos + 3 * (size_t)tri[2];
            const float u[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
            const float v[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
            const float c[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                                u[0] * v[1] - u[1] * v[0]};
            area += 0.5 * sqrt((double)dot3(c, c));
        }
        uint32_t at;
        if (tops < BOX_COLOURS)
            at = tops++;
        else if (area > top_area[BOX_COLOURS - 1])
            at = BOX_COLOURS - 1;   /* the smallest of the list goes */
        else
            continue;
        while (at > 0 && top_area[at - 1] < area) {
            top_area[at] = top_area[at - 1];
            top_vertex[at] = top_vertex[at - 1];
            at--;
        }
        top_area[at] = area;
        top_vertex[at] = b->idx[3 * (size_t)cl->tri[cl->first[k]]];
    }
    struct baked x = {0};
    float *size2x = malloc(sizeof(float) * ((size_t)b->vertices + 24));
    /* Every full-detail vertex is asked (the box's own lie on it). */
    uint32_t *order = malloc(sizeof(*order) * ((size_t)b->vertices + 1));
    struct by_size *tmp = malloc(sizeof(*tmp) * ((size_t)b->vertices + 1));
    uint32_t idx[36];
    size_t n = 0;
    int err = size2x && order && tmp ? box_baked(b, box, &x, idx, &n) : TW_ERR_NOMEM;
    if (err)
        goto out;
    memcpy(size2x, size2, sizeof(float) * (size_t)b->vertices);
    for (uint32_t v = b->vertices; v < x.vertices; v++)
        size2x[v] = 0.0f;
    for (uint32_t v = 0; v < b->vertices; v++)
        order[v] = v;
    sort_by_size(order, b->vertices, size2, tmp);
    if (n == 0 || tops == 0)
        goto out;   /* no box of any area: no level */
    /* The colour of least error. */
    uint32_t best = 0;
    *error = INFINITY;
    for (uint32_t k = 0; k < tops && !err; k++) {
        box_colour(b, &x, top_vertex[k]);
        float e = 0.0f;
        err = measure_error(&x, size2x, &cl->adj, order, b->vertices, box, idx, n, at_least,
                            *error, NULL, &e);
        if (!err && e < *error)
            reverse_error(&x, full, b->idx, idx, n, e, *error, &e);
        if (!err && e < *error) {
            *error = e;
            best = k;
        }
    }
    box_colour(b, &x, top_vertex[best]);
    if (!err)
        err = add_level(levels, white, name, &x, idx, n);
    *added = !err;
    *colour = top_vertex[best];
out:
    baked_free(&x);
    free(size2x);
    free(order);
    free(tmp);
    return err;
}

/* The name of level k (1, 2, ...) of prototype proto_name. */
static void level_name(char name[48], const char *proto_name, uint32_t k)
{
    snprintf(name, 48, "%.36s/lod%u", proto_name, k % 100000u);
}

/* ---- the store: a prototype's levels on disk ------------------------------------ */

/* A prototype's levels as build_prototype made them, enough to make them
 * again without the search: each level's error and what add_level was
 * given (its triangles, in baked vertices; for a box, the vertex whose
 * colour it took). Written after the head below, which holds its checksum;
 * all numbers in this machine's byte order (the key has it). */
enum { STORED_TRIANGLES = 0, STORED_BOX = 1 };

struct stored_head {
    char magic[24];
    uint64_t key[2];
    uint32_t vertices, triangles, count, body_words;
    uint64_t sum;   /* FNV-1a of the body: what a reader trusts is what was written */
};

static const char stored_magic[24] = "tileworld-levels 1\n";

struct record {
    uint32_t *w;    /* per level: kind, error (a float's bits), n or colour, then 3 n indices */
    size_t n, cap;
    bool failed;    /* out of memory: nothing is stored */
};

static void record_put(struct record *r, const uint32_t *w, size_t n)
{
    if (r->failed)
        return;
    if (r->n + n > r->cap) {
        size_t cap = r->cap ? 2 * r->cap : 4096;
        while (cap < r->n + n)
            cap *= 2;
        uint32_t *grown = realloc(r->w, sizeof(*grown) * cap);
        if (!grown) {
            r->failed = true;
            return;
        }
        r->w = grown;
        r->cap = cap;
    }
    memcpy(r->w + r->n, w, sizeof(*w) * n);
    r->n += n;
}

static void record_level(struct record *r, uint32_t kind, float error, uint32_t n,
                         const uint32_t *idx)
{
    uint32_t head[3] = {kind, 0, n};
    memcpy(&head[1], &error, sizeof(error));
    record_put(r, head, 3);
    if (kind == STORED_TRIANGLES)
        record_put(r, idx, 3 * (size_t)n);
}

/* What the levels of baked prototype b with box box depend on, hashed two
 * ways (FNV-1a, and a multiply-rotate over words): the levels' code (this
 * file's text), meshoptimizer's version, and the content. */
static void stored_key(const struct baked *b, const struct tw_box *box, uint64_t key[2])
{
    static const char source[] = TW_LOD_SOURCE_HASH;
    const uint32_t version = MESHOPTIMIZER_VERSION;
    const struct {
        const void *p;
        size_t n;
    } parts[] = {
        {source, sizeof(source)},
        {&version, sizeof(version)},
        {&b->vertices, sizeof(b->vertices)},
        {&b->triangles, sizeof(b->triangles)},
        {box, sizeof(*box)},
        {b->pos, sizeof(float) * 3 * (size_t)b->vertices},
        {b->nrm, sizeof(float) * 3 * (size_t)b->vertices},
        {b->rgba, 4 * (size_t)b->vertices},
        {b->idx, sizeof(uint32_t) * 3 * (size_t)b->triangles},
    };
    uint64_t h = TW_HASH_START, g = 0x9e3779b97f4a7c15ull;
    for (size_t k = 0; k < sizeof(parts) / sizeof(parts[0]); k++) {
        h = tw_hash_more(h, parts[k].p, parts[k].n);
        const uint8_t *q = parts[k].p;
        for (size_t i = 0; i < parts[k].n; i += 8) {
            uint64_t w = 0;
            memcpy(&w, q + i, parts[k].n - i < 8 ? parts[k].n - i : 8);
            g ^= w;
            g = ((g << 31) | (g >> 33)) * 0x9e3779b97f4a7c15ull;
        }
        g ^= parts[k].n;
    }
    key[0] = h;
    key[1] = g;
}

static void stored_write(struct tw_file_cache *store, const uint64_t key[2], const struct baked *b,
                         uint32_t count, const struct record *r)
{
    if (r->failed || r->n > UINT32_MAX)
        return;
    struct stored_head head;
    memset(&head, 0, sizeof(head));
    memcpy(head.magic, stored_magic, sizeof(head.magic));
    head.key[0] = key[0];
    head.key[1] = key[1];
    head.vertices = b->vertices;
    head.triangles = b->triangles;
    head.count = count;
    head.body_words = (uint32_t)r->n;
    head.sum = tw_hash_more(TW_HASH_START, r->w, sizeof(uint32_t) * r->n);
    (void)tw_file_cache_put(store, key[0], &head, sizeof(head), r->w, sizeof(uint32_t) * r->n);
}

/* The record stored for key and b, checked whole: its head, its checksum,
 * every level's kind, error, size and indices; false if there is none or
 * it does not hold. */
static bool stored_read(struct tw_file_cache *store, const uint64_t key[2], const struct baked *b,
                        struct record *r, uint32_t *count)
{
    FILE *f = tw_file_cache_get(store, key[0]);
    if (!f)
        return false;
    struct stored_head head;
    bool ok = fread(&head, sizeof(head), 1, f) == 1 &&
              memcmp(head.magic, stored_magic, sizeof(head.magic)) == 0 &&
              head.key[0] == key[0] && head.key[1] == key[1] && head.vertices == b->vertices &&
              head.triangles == b->triangles && head.count <= TW_LOD_MAX_LEVELS &&
              head.body_words <= 3 * (size_t)(TW_LOD_MAX_LEVELS) * (1 + (size_t)b->triangles);
    if (ok) {
        r->w = malloc(sizeof(uint32_t) * ((size_t)head.body_words + 1));
        ok = r->w && fread(r->w, sizeof(uint32_t), head.body_words, f) == head.body_words &&
             fgetc(f) == EOF;
    }
    fclose(f);
    if (ok) {
        r->n = head.body_words;
        ok = head.sum == tw_hash_more(TW_HASH_START, r->w, sizeof(uint32_t) * r->n);
    }
    /* Each level in turn, errors never smaller. */
    size_t at = 0;
    float last = 0.0f;
    for (uint32_t k = 0; ok && k < head.count; k++) {
        ok = at + 3 <= r->n;
        if (!ok)
            break;
        const uint32_t kind = r->w[at], n = r->w[at + 2];
        float error;
        memcpy(&error, &r->w[at + 1], sizeof(error));
        ok = isfinite(error) && error >= last &&
             ((kind == STORED_BOX && n < b->vertices) ||
              (kind == STORED_TRIANGLES && n > 0 && n <= b->triangles &&
               at + 3 + 3 * (size_t)n <= r->n));
        last = error;
        at += 3;
        if (ok && kind == STORED_TRIANGLES) {
            for (size_t i = 0; i < 3 * (size_t)n && ok; i++)
                ok = r->w[at + i] < b->vertices;
            at += 3 * (size_t)n;
        }
    }
    ok = ok && at == r->n;
    if (ok) {
        *count = head.count;
        tw_file_cache_touch(store, key[0]);
    } else {
        free(r->w);
        memset(r, 0, sizeof(*r));
    }
    return ok;
}

/* The levels of record r (stored_read's, count of them) added to levels as
 * build_prototype adds them; their errors into errors, their number into
 * *added. */
static int stored_replay(const struct record *r, uint32_t count, const struct baked *b,
                         const struct tw_box *box, const char *proto_name, struct tw_tileset *levels,
                         uint32_t white, float *errors, uint32_t *added)
{
    *added = 0;
    uint32_t *idx = malloc(sizeof(uint32_t) * (3 * (size_t)b->triangles + 1));
    if (!idx)
        return TW_ERR_NOMEM;
    int err = TW_OK;
    size_t at = 0;
    for (uint32_t k = 0; k < count && !err; k++) {
        const uint32_t kind = r->w[at], n = r->w[at + 2];
        float error;
        memcpy(&error, &r->w[at + 1], sizeof(error));
        at += 3;
        char name[48];
        level_name(name, proto_name, k + 1);
        if (kind == STORED_TRIANGLES) {
            memcpy(idx, r->w + at, sizeof(uint32_t) * 3 * (size_t)n);
            at += 3 * (size_t)n;
            err = add_level(levels, white, name, b, idx, n);
        } else {
            struct baked x;
            uint32_t bidx[36];
            size_t bn = 0;
            err = box_baked(b, box, &x, bidx, &bn);
            if (!err) {
                box_colour(b, &x, n);
                err = add_level(levels, white, name, &x, bidx, bn);
            }
            baked_free(&x);
        }
        if (err == TW_ERR_INVALID || err == TW_ERR_LIMIT) {
            err = TW_OK;    /* refused, as when built: the prototype stops at the last */
            break;
        }
        if (!err)
            errors[(*added)++] = error;
    }
    free(idx);
    return err;
}

/* The stores opened, one a folder, kept until the process ends. */
struct store_entry {
    struct store_entry *next;
    struct tw_file_cache *cache;
    char dir[];
};
static pthread_mutex_t stores_lock = PTHREAD_MUTEX_INITIALIZER;
static struct store_entry *stores;

int tw_lods_store(const char *dir, uint64_t max_bytes, struct tw_file_cache **out, char *err,
                  size_t err_size)
{
    *out = NULL;
    if (!dir || !dir[0]) {
        snprintf(err, err_size, "no cache folder");
        return TW_ERR_INVALID;
    }
    pthread_mutex_lock(&stores_lock);
    struct store_entry *e = stores;
    while (e && strcmp(e->dir, dir) != 0)
        e = e->next;
    int rc = TW_OK;
    if (!e) {
        const size_t len = strlen(dir) + 1;
        e = calloc(1, sizeof(*e) + len);
        if (!e) {
            rc = TW_ERR_NOMEM;
            snprintf(err, err_size, "%s", tw_error_to_str(rc));
        } else {
            rc = tw_file_cache_open(dir, "levels", max_bytes ? max_bytes : TW_LODS_STORE_BYTES,
                                    &e->cache, err, err_size);
        }
        if (rc) {
            free(e);
            e = NULL;
        } else {
            memcpy(e->dir, dir, len);
            e->next = stores;
            stores = e;
        }
    }
    pthread_mutex_unlock(&stores_lock);
    if (e)
        *out = e->cache;
    return rc;
}

/* The targets of the levels: from 2^(1 - TARGET_STEPS / 2) of the
 * prototype's extent up to twice the extent, each sqrt(2) times the one
 * before. Steps of 2 left a class where it was whenever its patches'
 * sizes lay just above a target (windows of 0.75 and 1.5 m against
 * targets of 0.70 and 1.39 m), until the next target took much more. */
#define TARGET_STEPS 20

/* The levels of prototype p of ts, added to levels: their number into
 * *count and their errors (metres) into errors. */
static int build_prototype(const struct tw_tileset *ts, uint32_t p, struct tw_file_cache *store,
                           const atomic_bool *stop, struct tw_tileset *levels, uint32_t white,
                           float *errors, uint32_t *count, bool *from_store)
{
    *count = 0;
    *from_store = false;
    struct baked b;
    int err = bake(ts, p, &b);
    if (err || b.triangles < 2 * LOD_MIN_TRIANGLES) {
        baked_free(&b);
        return err;
    }
    /* What is built is recorded for the store, what it holds is made
     * again from it. */
    uint64_t key[2] = {0, 0};
    struct record rec = {0};
    if (store) {
        stored_key(&b, &ts->prototypes[p].box, key);
        uint32_t n = 0;
        if (stored_read(store, key, &b, &rec, &n)) {
            err = stored_replay(&rec, n, &b, &ts->prototypes[p].box, ts->prototypes[p].name,
                                levels, white, errors, count);
            *from_store = err == TW_OK;
            free(rec.w);
            baked_free(&b);
            return err;
        }
    }
    struct welded w;
    struct classes cl = {0};
    struct part part = {0};
    err = weld(&b, &w);
    if (!err)
        err = classes_make(&b, &cl);
    if (!err)
        err = part_alloc(&part, &b, &w);
    /* The level now, class after class (start[k] .. start[k + 1]), and the
     * next one being made. */
    const size_t t3 = 3 * (size_t)b.triangles + 1;
    uint32_t *cur = malloc(sizeof(uint32_t) * t3);
    uint32_t *next = malloc(sizeof(uint32_t) * t3);
    uint32_t *idx = malloc(sizeof(uint32_t) * t3);
    size_t *start = calloc((size_t)cl.count + 1, sizeof(*start));
    size_t *next_start = calloc((size_t)cl.count + 1, sizeof(*next_start));
    float *size2 = err ? NULL : patch_sizes(&b, &w);
    if (!err && size2)
        err = classes_order(&cl, &b, size2);
    /* The full-detail triangles, for the measure the other way round. */
    struct grid full = {0};
    if (!err)
        err = grid_build(&full, &ts->prototypes[p].box, b.pos, b.idx, b.triangles, 0.0f);
    if (err || !cur || !next || !idx || !start || !next_start || !size2) {
        err = err ? err : TW_ERR_NOMEM;
        goto out;
    }
    for (uint32_t k = 0; k < cl.count; k++) {
        for (uint32_t t = cl.first[k]; t < cl.first[k + 1]; t++)
            memcpy(cur + 3 * (size_t)t, w.idx + 3 * (size_t)cl.tri[t], sizeof(uint32_t) * 3);
        start[k + 1] = cl.first[k + 1];
    }
    const float extent = meshopt_simplifyScale(w.pos, w.vertices, sizeof(float) * 3);
    size_t previous = b.triangles;
    for (int step = TARGET_STEPS; step >= 0 && *count < TW_LOD_MAX_LEVELS && !err; step--) {
        const float target = 2.0f * (extent * powf(2.0f, -0.5f * (float)step));
        size_t total = 0;
        for (uint32_t k = 0; k < cl.count && !err; k++) {
            size_t m = 0;
            next_start[k] = total;
            err = simplify_class(&b, &w, size2, &full, &ts->prototypes[p].box, &cl, k, &part,
                                 cur + 3 * start[k], start[k + 1] - start[k], target, stop,
                                 next + 3 * total, &m);
            total += m;
        }
        next_start[cl.count] = total;
        if (err)
            break;
        uint32_t *swap = cur;
        cur = next;
        next = swap;
        size_t *swap_start = start;
        start = next_start;
        next_start = swap_start;
        if (total == 0)
            break;  /* nothing left: the level before is the coarsest */
        /* A level that saves little costs memory and a BVH for nothing;
         * the next target starts from it all the same. */
        if ((double)total > TW_LOD_KEEP_RATIO * (double)previous)
            continue;
        float error = 0.0f;
        for (uint32_t k = 0; k < cl.count; k++)
            error = fmaxf(error, cl.error[k]);
        if (*count > 0 && error < errors[*count - 1])
            error = errors[*count - 1];   /* a coarser level is never called more exact */
        unweld(&b, &w, cur, total, idx);
        char name[48];
        level_name(name, ts->prototypes[p].name, *count + 1);
        const size_t mark = rec.n;
        record_level(&rec, STORED_TRIANGLES, error, (uint32_t)total, idx);
        err = add_level(levels, white, name, &b, idx, total);
        if (err)
            rec.n = mark;
        if (err == TW_ERR_INVALID || err == TW_ERR_LIMIT) {
            err = TW_OK;    /* a level the tileset refuses: the prototype stops at the last */
            break;
        }
        if (err)
            break;
        errors[(*count)++] = error;
        previous = total;
        if (total < LOD_MIN_TRIANGLES)
            break;  /* what is left is a few boxes */
    }
    /* Where the last level is still far from a box (every class gone at
     * the next target, or none simplified further), a box ends the
     * levels: far enough away, a cell of a block is drawn as one. */
    if (!err && *count < TW_LOD_MAX_LEVELS && previous >= 2 * BOX_TRIANGLES) {
        char name[48];
        level_name(name, ts->prototypes[p].name, *count + 1);
        const float last = *count > 0 ? errors[*count - 1] : 0.0f;
        float error = 0.0f;
        bool added = false;
        uint32_t colour = 0;
        err = add_box_level(levels, white, name, &b, &cl, size2, &full, &ts->prototypes[p].box,
                            last, &error, &added, &colour);
        if (err == TW_ERR_INVALID || err == TW_ERR_LIMIT) {
            err = TW_OK;    /* refused: the prototype stops at the last */
        } else if (added) {
            errors[(*count)++] = fmaxf(error, last);
            record_level(&rec, STORED_BOX, errors[*count - 1], colour, NULL);
        }
    }
    if (!err && store)
        stored_write(store, key, &b, *count, &rec);
out:
    free(rec.w);
    grid_free(&full);
    free(size2);
    free(cur);
    free(next);
    free(idx);
    free(start);
    free(next_start);
    part_free(&part);
    classes_free(&cl);
    welded_free(&w);
    baked_free(&b);
    return err;
}

int tw_lods_build(const struct tw_tileset *ts, uint32_t max_cluster_triangles,
                  struct tw_file_cache *store, const atomic_bool *stop, struct tw_lods *out)
{
    memset(out, 0, sizeof(*out));
    if (!ts || !ts->finished)
        return TW_ERR_INVALID;
    const uint32_t np = ts->prototype_count;
    out->source_count = np;
    out->first = calloc(np, sizeof(*out->first));
    out->count = calloc(np, sizeof(*out->count));
    out->error = malloc(sizeof(*out->error) * (size_t)np * TW_LOD_MAX_LEVELS + 1);
    int err = out->first && out->count && out->error ? TW_OK : TW_ERR_NOMEM;
    struct tw_tileset *levels = NULL;
    if (!err)
        err = tw_tileset_create(ts->name, ts->footprint[0], ts->footprint[1], &levels);
    const int white = err ? err : tw_tileset_add_material(levels, (const float[4]){1, 1, 1, 1});
    if (white < 0)
        err = white;
    uint32_t total = 0;
    for (uint32_t p = 0; p < np && !err; p++) {
        out->first[p] = total;
        bool from_store = false;
        err = build_prototype(ts, p, store, stop, levels, (uint32_t)white, out->error + total,
                              &out->count[p], &from_store);
        total += out->count[p];
        out->stored += from_store;
    }
    if (!err && total > 0) {
        levels->merge_triangles = 1;   /* one instance each: nothing to merge */
        err = tw_tileset_finish(levels, max_cluster_triangles);
        /* A level left with no triangle of any area, or out of reach: no
         * levels rather than no world. */
        if (err == TW_ERR_INVALID || err == TW_ERR_LIMIT) {
            err = TW_OK;
            total = 0;
        }
        if (!err && total > 0)
            err = tw_tileset_pack(&levels);
    }
    if (err || total == 0) {
        tw_tileset_destroy(levels);
        levels = NULL;
        for (uint32_t p = 0; p < np && out->count; p++)
            out->count[p] = 0;
    }
    out->levels = levels;
    if (err)
        tw_lods_free(out);
    return err;
}

/* A tileset's levels, shared by the worlds over it. */
struct tw_lods_cache {
    pthread_mutex_t lock;       /* held while they are built */
    bool built;
    struct tw_lods lods;
};

/* Guards the tilesets' slots while a cache is made. */
static pthread_mutex_t slots_lock = PTHREAD_MUTEX_INITIALIZER;

int tw_lods_of_tileset(const struct tw_tileset *ts, struct tw_file_cache *store,
                       const struct tw_lods **out)
{
    *out = NULL;
    if (!ts || !ts->finished)
        return TW_ERR_INVALID;
    struct tw_lods_cache **slot = tw_tileset_lods_slot(ts);
    pthread_mutex_lock(&slots_lock);
    if (!*slot && (*slot = calloc(1, sizeof(**slot))) != NULL)
        pthread_mutex_init(&(*slot)->lock, NULL);
    struct tw_lods_cache *c = *slot;
    pthread_mutex_unlock(&slots_lock);
    if (!c)
        return TW_ERR_NOMEM;
    pthread_mutex_lock(&c->lock);
    int err = TW_OK;
    if (!c->built) {
        err = tw_lods_build(ts, ts->max_cluster_triangles, store, NULL, &c->lods);
        c->built = err == TW_OK;
    }
    pthread_mutex_unlock(&c->lock);
    if (!err)
        *out = &c->lods;
    return err;
}

void tw_lods_cache_free(struct tw_lods_cache *c)
{
    if (!c)
        return;
    tw_lods_free(&c->lods);
    pthread_mutex_destroy(&c->lock);
    free(c);
}

void tw_lods_free(struct tw_lods *l)
{
    if (!l)
        return;
    tw_tileset_destroy(l->levels);
    free(l->first);
    free(l->count);
    free(l->error);
    memset(l, 0, sizeof(*l));
}

uint64_t tw_lods_bytes(const struct tw_lods *l)
{
    if (!l || !l->first)
        return 0;
    return tw_tileset_bytes(l->levels) +
           (uint64_t)l->source_count * (sizeof(*l->first) + sizeof(*l->count)) +
           (uint64_t)(l->levels ? l->levels->prototype_count : 0) * sizeof(*l->error);
}

uint32_t tw_lods_pick(const struct tw_lods *l, uint32_t p, float max_error)
{
    if (!l || !l->levels || p >= l->source_count || !(max_error > 0.0f))
        return 0;
    const float *e = l->error + l->first[p];
    uint32_t level = 0;
    while (level < l->count[p] && e[level] <= max_error)
        level++;
    return level;
}
