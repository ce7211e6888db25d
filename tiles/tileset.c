/* The tileset model: builder, cluster split, boxes (tiles.h). */
#include "tileworld/tiles.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <float.h>
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A tileset with what its builder keeps to itself: the capacities of its
 * arrays and, once packed, the size of its one block. The public struct is
 * first, so that a struct tw_tileset pointer is a pointer to this. */
struct tileset {
    struct tw_tileset ts;
    uint32_t material_cap, mesh_cap, prototype_cap, part_cap;
    uint32_t *instance_cap;       /* per prototype, prototype_cap of them; NULL once packed */
    uint64_t packed_bytes;        /* the size of the block tw_tileset_pack() made; 0: not one */
    char failure[256];            /* why a provider could not make it (tw_tileset_fail) */
    struct tw_lods_cache *lods;   /* its levels, once a world asked (tw_lods_of_tileset) */
};

static struct tileset *impl(struct tw_tileset *ts)
{
    return (struct tileset *)ts;
}

static const struct tileset *impl_const(const struct tw_tileset *ts)
{
    return (const struct tileset *)ts;
}

struct tw_lods_cache **tw_tileset_lods_slot(const struct tw_tileset *ts)
{
    /* The tileset is not changed: what is derived from it is kept with it. */
    return &((struct tileset *)(uintptr_t)ts)->lods;
}

static int grow(void **array, uint32_t *cap, uint32_t need, size_t elem)
{
    return tw_array_reserve_u32(array, cap, need, elem, 8);
}

int tw_tileset_create(const char *name, float w, float d, struct tw_tileset **out)
{
    if (!out || !isfinite(w) || !isfinite(d) || !(w > 0.0f) || !(d > 0.0f))
        return TW_ERR_INVALID;
    struct tileset *t = calloc(1, sizeof(*t));
    if (!t)
        return TW_ERR_NOMEM;
    struct tw_tileset *ts = &t->ts;
    if (name)
        strncpy(ts->name, name, sizeof(ts->name) - 1);
    ts->footprint[0] = w;
    ts->footprint[1] = d;
    ts->common_box = tw_box_empty();
    *out = ts;
    return TW_OK;
}

int tw_tileset_fail(struct tw_tileset *ts, int err, const char *fmt, ...)
{
    if (err >= 0)
        err = TW_ERR_INVALID;
    if (!ts || !fmt)
        return err;
    char msg[sizeof(impl(ts)->failure)];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof(msg), fmt, ap);
    va_end(ap);
    /* A provider's text, in a line of the world's log: escaped. */
    tw_log_escape(msg, impl(ts)->failure, sizeof(impl(ts)->failure));
    return err;
}

const char *tw_tileset_failure(const struct tw_tileset *ts)
{
    return ts && impl_const(ts)->failure[0] ? impl_const(ts)->failure : NULL;
}

void tw_tileset_destroy(struct tw_tileset *ts)
{
    if (!ts)
        return;
    struct tileset *t = impl(ts);
    tw_lods_cache_free(t->lods);
    if (t->packed_bytes) {
        tw_pack_free(t, t->packed_bytes); /* one block (tw_tileset_pack) */
        return;
    }
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        free(ts->meshes[k].positions);
        free(ts->meshes[k].normals);
        free(ts->meshes[k].indices);
        free(ts->meshes[k].colors);
    }
    for (uint32_t k = 0; k < ts->prototype_count; k++) {
        free(ts->prototypes[k].instances);
        free(ts->prototypes[k].clusters);
    }
    free(ts->meshes);
    free(ts->parts);
    free(ts->materials);
    free(ts->prototypes);
    free(t->instance_cap);
    free(t);
}

int tw_tileset_add_material(struct tw_tileset *ts, const float rgba[4])
{
    if (!ts || !rgba || ts->finished)
        return TW_ERR_INVALID;
    for (int k = 0; k < 4; k++)
        if (!isfinite(rgba[k]))
            return TW_ERR_INVALID;
    int err = grow((void **)&ts->materials, &impl(ts)->material_cap, ts->material_count + 1,
                   sizeof(*ts->materials));
    if (err)
        return err;
    struct tw_material *m = &ts->materials[ts->material_count];
    for (int k = 0; k < 4; k++)
        m->base_color[k] = fminf(fmaxf(rgba[k], 0.0f), 1.0f);
    return (int)ts->material_count++;
}

static void compute_normals(float *normals, const float *pos, uint32_t nv,
                            const uint32_t *idx, uint32_t nt)
{
    memset(normals, 0, sizeof(float) * 3 * nv);
    for (uint32_t t = 0; t < nt; t++) {
        const float *a = pos + 3 * idx[3 * t];
        const float *b = pos + 3 * idx[3 * t + 1];
        const float *c = pos + 3 * idx[3 * t + 2];
        const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const float e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                            e1[0] * e2[1] - e1[1] * e2[0]};
        for (int v = 0; v < 3; v++)
            for (int k = 0; k < 3; k++)
                normals[3 * idx[3 * t + v] + k] += n[k];
    }
    for (uint32_t v = 0; v < nv; v++) {
        float *n = normals + 3 * v;
        float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (len > 0.0f) {
            n[0] /= len; n[1] /= len; n[2] /= len;
        } else {
            n[0] = 0.0f; n[1] = 1.0f; n[2] = 0.0f;
        }
    }
}

int tw_tileset_add_mesh(struct tw_tileset *ts, const float *positions,
                        const float *normals, uint32_t vertex_count,
                        const uint32_t *indices, uint32_t triangle_count)
{
    if (!ts || ts->finished || !positions || !indices || vertex_count == 0 ||
        triangle_count == 0 || triangle_count > UINT32_MAX / 3)
        return TW_ERR_INVALID;
    for (uint64_t k = 0; k < 3ull * vertex_count; k++)
        if (!isfinite(positions[k]) || (normals && !isfinite(normals[k])))
            return TW_ERR_INVALID;
    for (uint64_t k = 0; k < 3ull * vertex_count; k++)
        if (fabsf(positions[k]) > TW_TILES_MAX_MESH_COORD)
            return TW_ERR_LIMIT;
    for (uint64_t k = 0; k < 3ull * triangle_count; k++)
        if (indices[k] >= vertex_count)
            return TW_ERR_INVALID;
    int err = grow((void **)&ts->meshes, &impl(ts)->mesh_cap, ts->mesh_count + 1, sizeof(*ts->meshes));
    if (err)
        return err;
    struct tw_mesh m = {0};
    const size_t vbytes = sizeof(float) * 3 * (size_t)vertex_count;
    const size_t ibytes = sizeof(uint32_t) * 3 * (size_t)triangle_count;
    m.positions = malloc(vbytes);
    m.normals = malloc(vbytes);
    m.indices = malloc(ibytes);
    if (!m.positions || !m.normals || !m.indices) {
        free(m.positions);
        free(m.normals);
        free(m.indices);
        return TW_ERR_NOMEM;
    }
    memcpy(m.positions, positions, vbytes);
    memcpy(m.indices, indices, ibytes);
    if (normals)
        memcpy(m.normals, normals, vbytes);
    else
        compute_normals(m.normals, positions, vertex_count, indices, triangle_count);
    m.vertex_count = vertex_count;
    m.triangle_count = triangle_count;
    m.box = tw_box_empty();
    for (uint32_t v = 0; v < vertex_count; v++)
        tw_box_add_point(&m.box, positions + 3 * v);
    ts->meshes[ts->mesh_count] = m;
    return (int)ts->mesh_count++;
}

int tw_tileset_add_prototype(struct tw_tileset *ts, const char *name, float weight)
{
    if (!ts || ts->finished || !isfinite(weight) || !(weight > 0.0f))
        return TW_ERR_INVALID;
    struct tileset *t = impl(ts);
    const uint32_t had = t->prototype_cap;
    int err = grow((void **)&ts->prototypes, &t->prototype_cap, ts->prototype_count + 1,
                   sizeof(*ts->prototypes));
    if (!err && t->prototype_cap != had) {
        uint32_t *caps = realloc(t->instance_cap, sizeof(*caps) * t->prototype_cap);
        if (caps) {
            t->instance_cap = caps;
            memset(caps + had, 0, sizeof(*caps) * (t->prototype_cap - had));
        } else {
            err = TW_ERR_NOMEM;     /* the prototypes' array grew: harmless */
        }
    }
    if (err)
        return err;
    t->instance_cap[ts->prototype_count] = 0;
    struct tw_prototype *p = &ts->prototypes[ts->prototype_count];
    memset(p, 0, sizeof(*p));
    if (name)
        strncpy(p->name, name, sizeof(p->name) - 1);
    p->weight = weight;
    p->box = tw_box_empty();
    return (int)ts->prototype_count++;
}

int tw_tileset_add_instance(struct tw_tileset *ts, uint32_t proto, uint32_t mesh,
                            uint32_t material, const float transform[12])
{
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (!ts || ts->finished || proto >= ts->prototype_count || mesh >= ts->mesh_count ||
        material >= ts->material_count)
        return TW_ERR_INVALID;
    if (!transform)
        transform = identity;
    for (int k = 0; k < 12; k++)
        if (!isfinite(transform[k]))
            return TW_ERR_INVALID;
    for (int k = 0; k < 12; k++)
        if (fabsf(transform[k]) > TW_TILES_MAX_COORD)
            return TW_ERR_LIMIT;
    /* The placed mesh stays within reach (the transformed box holds every
     * transformed vertex). */
    const struct tw_box placed = tw_box_transform(&ts->meshes[mesh].box, transform);
    for (int k = 0; k < 3; k++)
        if (!(placed.min[k] >= -TW_TILES_MAX_COORD) || !(placed.max[k] <= TW_TILES_MAX_COORD))
            return TW_ERR_LIMIT;
    struct tw_prototype *p = &ts->prototypes[proto];
    int err = grow((void **)&p->instances, &impl(ts)->instance_cap[proto], p->instance_count + 1,
                   sizeof(*p->instances));
    if (err)
        return err;
    struct tw_instance *in = &p->instances[p->instance_count];
    /* Zeroed first: padding too, so that equal tilesets compare equal bytewise. */
    memset(in, 0, sizeof(*in));
    in->mesh = mesh;
    in->material = material;
    memcpy(in->transform, transform, sizeof(in->transform));
    in->box = tw_box_empty();
    in->merged_into = TW_INSTANCE_NONE;
    in->merged = false;
    return (int)p->instance_count++;
}

/* ---- finishing: clusters and boxes ------------------------------------------------ */

struct keyed_triangle {
    float key;
    uint32_t triangle;
};

static int compare_keyed(const void *a, const void *b)
{
    const struct keyed_triangle *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return (x->triangle > y->triangle) - (x->triangle < y->triangle);
}

static void triangle_centroid(const struct tw_mesh *m, uint32_t t, float c[3])
{
    const uint32_t *i = m->indices + 3 * t;
    for (int k = 0; k < 3; k++)
        c[k] = (m->positions[3 * i[0] + k] + m->positions[3 * i[1] + k] +
                m->positions[3 * i[2] + k]) / 3.0f;
}

static struct tw_box triangles_box(const struct tw_mesh *m, uint32_t first, uint32_t count,
                                   const float *transform)
{
    struct tw_box b = tw_box_empty();
    for (uint32_t t = first; t < first + count; t++) {
        for (int v = 0; v < 3; v++) {
            const float *p = m->positions + 3 * m->indices[3 * t + v];
            if (transform) {
                const float *x = transform;
                const float q[3] = {
                    x[0] * p[0] + x[1] * p[1] + x[2] * p[2] + x[3],
                    x[4] * p[0] + x[5] * p[1] + x[6] * p[2] + x[7],
                    x[8] * p[0] + x[9] * p[1] + x[10] * p[2] + x[11],
                };
                tw_box_add_point(&b, q);
            } else {
                tw_box_add_point(&b, p);
            }
        }
    }
    return b;
}

/* Reorders a mesh's triangles so that ranges of at most max_tris triangles
 * are spatially coherent: recursive median splits of the centroids along
 * their longest axis. Appends one part per range to ts->parts. */
static int split_mesh(struct tw_tileset *ts, uint32_t mesh_index, uint32_t max_tris,
                      uint32_t *part_cap)
{
    struct tw_mesh *m = &ts->meshes[mesh_index];
    const uint32_t nt = m->triangle_count;
    m->first_part = ts->part_count;
    m->part_count = 0;
    if (nt == 0)    /* every triangle without area: nothing to draw */
        return TW_OK;

    struct keyed_triangle *order = malloc(sizeof(*order) * nt);
    uint32_t *new_indices = malloc(sizeof(uint32_t) * 3 * (size_t)nt);
    /* A stack of [first, count) ranges; depth is at most log2(nt) + 1 per level
     * of pending siblings, so 2 * 64 entries are plenty. */
    uint32_t stack[128][2];
    int err = TW_OK;
    if (!order || !new_indices) {
        err = TW_ERR_NOMEM;
        goto out;
    }
    for (uint32_t t = 0; t < nt; t++)
        order[t].triangle = t;

    int top = 0;
    stack[top][0] = 0;
    stack[top][1] = nt;
    top++;
    /* Ranges are emitted in stack order; parts are sorted by first afterwards. */
    while (top > 0) {
        top--;
        const uint32_t first = stack[top][0], count = stack[top][1];
        if (max_tris == 0 || count <= max_tris) {
            err = grow((void **)&ts->parts, part_cap, ts->part_count + 1, sizeof(*ts->parts));
            if (err)
                goto out;
            struct tw_mesh_part *part = &ts->parts[ts->part_count++];
            part->mesh = mesh_index;
            part->first_triangle = first;
            part->triangle_count = count;
            m->part_count++;
            continue;
        }
        struct tw_box cb = tw_box_empty();
        for (uint32_t k = first; k < first + count; k++) {
            float c[3];
            triangle_centroid(m, order[k].triangle, c);
            tw_box_add_point(&cb, c);
        }
        int axis = 0;
        for (int k = 1; k < 3; k++)
            if (cb.max[k] - cb.min[k] > cb.max[axis] - cb.min[axis])
                axis = k;
        for (uint32_t k = first; k < first + count; k++) {
            float c[3];
            triangle_centroid(m, order[k].triangle, c);
            order[k].key = c[axis];
        }
        qsort(order + first, count, sizeof(*order), compare_keyed);
        const uint32_t half = count / 2;
        if (top + 2 > 128) {
            err = TW_ERR_LIMIT;
            goto out;
        }
        /* Push the right half first so the left one is emitted first. */
        stack[top][0] = first + half;
        stack[top][1] = count - half;
        top++;
        stack[top][0] = first;
        stack[top][1] = half;
        top++;
    }
    for (uint32_t t = 0; t < nt; t++)
        memcpy(new_indices + 3 * t, m->indices + 3 * order[t].triangle, sizeof(uint32_t) * 3);
    free(m->indices);
    m->indices = new_indices;
    new_indices = NULL;
    for (uint32_t k = m->first_part; k < m->first_part + m->part_count; k++)
        ts->parts[k].box = triangles_box(m, ts->parts[k].first_triangle,
                                         ts->parts[k].triangle_count, NULL);
out:
    free(order);
    free(new_indices);
    return err;
}

/* ---- finishing: triangles without area ------------------------------------------- */

/* Whether triangle (a, b, c) has no area that float positions can hold: its
 * height over its longest edge is within float rounding (FLT_EPSILON) of
 * that edge's length, collinear and coincident corners included. It covers
 * no surface, yet a rasteriser that rounds its projected corners can give it
 * fragments at a depth extrapolated from a plane through three almost
 * collinear points: anywhere, the near plane included (kenney-city had one
 * there, in front of everything, that the oracle then counted as visible). */
static bool has_no_area(const float *a, const float *b, const float *c)
{
    double e[3][3];
    for (int k = 0; k < 3; k++) {
        e[0][k] = (double)b[k] - a[k];
        e[1][k] = (double)c[k] - a[k];
        e[2][k] = (double)c[k] - b[k];
    }
    const double n[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1],
                         e[0][2] * e[1][0] - e[0][0] * e[1][2],
                         e[0][0] * e[1][1] - e[0][1] * e[1][0]};
    double longest = 0.0;   /* squared */
    for (int k = 0; k < 3; k++) {
        const double l = e[k][0] * e[k][0] + e[k][1] * e[k][1] + e[k][2] * e[k][2];
        if (l > longest)
            longest = l;
    }
    /* |n| is the height times the longest edge: height <= eps * longest. */
    const double eps = FLT_EPSILON;
    return n[0] * n[0] + n[1] * n[1] + n[2] * n[2] <= eps * eps * longest * longest;
}

/* Drops m's triangles without area (has_no_area), the others kept in order.
 * Modelling tools leave them at T-junctions: a kenney piece holds up to 34. */
static void drop_triangles_without_area(struct tw_mesh *m)
{
    uint32_t kept = 0;
    for (uint32_t t = 0; t < m->triangle_count; t++) {
        const uint32_t *i = m->indices + 3 * (size_t)t;
        if (has_no_area(m->positions + 3 * (size_t)i[0], m->positions + 3 * (size_t)i[1],
                        m->positions + 3 * (size_t)i[2]))
            continue;
        memmove(m->indices + 3 * (size_t)kept, i, sizeof(uint32_t) * 3);
        kept++;
    }
    m->triangle_count = kept;
}

/* ---- finishing: merging small instances ------------------------------------------ */

/* The index of an opaque white material, added if there is none. */
static int white_material(struct tw_tileset *ts)
{
    for (uint32_t k = 0; k < ts->material_count; k++) {
        const float *c = ts->materials[k].base_color;
        if (c[0] == 1.0f && c[1] == 1.0f && c[2] == 1.0f && c[3] == 1.0f)
            return (int)k;
    }
    return tw_tileset_add_material(ts, (const float[4]){1.0f, 1.0f, 1.0f, 1.0f});
}

static uint8_t unorm8(float x)
{
    return (uint8_t)lrintf(fminf(fmaxf(x, 0.0f), 1.0f) * 255.0f);
}

void tw_tileset_bake(const struct tw_tileset *ts, uint32_t p, const uint32_t *list, uint32_t count,
                     float *pos, float *nrm, uint8_t *rgba, uint32_t *idx, uint32_t *vertices,
                     uint32_t *triangles)
{
    uint32_t vbase = 0, tbase = 0;
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_instance *in = &ts->prototypes[p].instances[list[k]];
        const struct tw_mesh *m = &ts->meshes[in->mesh];
        const float *x = in->transform;
        const float *color = ts->materials[in->material].base_color;
        for (uint32_t v = 0; v < m->vertex_count; v++) {
            const float *a = m->positions + 3 * (size_t)v, *n = m->normals + 3 * (size_t)v;
            float *q = pos + 3 * (size_t)(vbase + v), *r = nrm + 3 * (size_t)(vbase + v);
            for (int row = 0; row < 3; row++) {
                const float *t = x + 4 * row;
                q[row] = t[0] * a[0] + t[1] * a[1] + t[2] * a[2] + t[3];
                r[row] = t[0] * n[0] + t[1] * n[1] + t[2] * n[2];
            }
            for (int c = 0; c < 4; c++) {
                const float vc = m->colors ? m->colors[4 * (size_t)v + c] / 255.0f : 1.0f;
                rgba[4 * (size_t)(vbase + v) + c] = unorm8(vc * color[c]);
            }
        }
        for (uint32_t i = 0; i < 3 * m->triangle_count; i++)
            idx[3 * (size_t)tbase + i] = m->indices[i] + vbase;
        vbase += m->vertex_count;
        tbase += m->triangle_count;
    }
    *vertices = vbase;
    *triangles = tbase;
}

/* The bytes that baking instance in copies. */
static uint64_t baked_bytes(const struct tw_tileset *ts, const struct tw_instance *in)
{
    const struct tw_mesh *m = &ts->meshes[in->mesh];
    return 28ull * m->vertex_count + 12ull * m->triangle_count;
}

/* Bakes instances list[0..count) of prototype p into one tile-local mesh,
 * its vertices coloured by their instance's material, placed by a new
 * identity instance of a white material, and marks them merged into it.
 * Transformed positions that overflow leave the instances as they are. */
static int merge_group(struct tw_tileset *ts, uint32_t p, const uint32_t *list, uint32_t count)
{
    uint64_t vertices = 0, triangles = 0;
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_mesh *m = &ts->meshes[ts->prototypes[p].instances[list[k]].mesh];
        vertices += m->vertex_count;
        triangles += m->triangle_count;
    }
    if (vertices > UINT32_MAX || triangles > UINT32_MAX / 3)
        return TW_OK;
    float *pos = malloc(sizeof(float) * 3 * (size_t)vertices);
    float *nrm = malloc(sizeof(float) * 3 * (size_t)vertices);
    uint8_t *rgba = malloc(4 * (size_t)vertices);
    uint32_t *idx = malloc(sizeof(uint32_t) * 3 * (size_t)triangles);
    int err = TW_OK;
    if (!pos || !nrm || !rgba || !idx) {
        err = TW_ERR_NOMEM;
        goto out;
    }
    uint32_t vbase, tbase;
    tw_tileset_bake(ts, p, list, count, pos, nrm, rgba, idx, &vbase, &tbase);
    const int mesh = tw_tileset_add_mesh(ts, pos, nrm, vbase, idx, tbase);
    if (mesh == TW_ERR_INVALID || mesh == TW_ERR_LIMIT)
        goto out;   /* not finite, or out of reach, once transformed: left alone */
    if (mesh < 0) {
        err = mesh;
        goto out;
    }
    const int white = white_material(ts);
    if (white < 0) {
        err = white;
        goto out;
    }
    ts->meshes[mesh].colors = rgba;
    rgba = NULL;
    const int merged = tw_tileset_add_instance(ts, p, (uint32_t)mesh, (uint32_t)white, NULL);
    if (merged < 0) {
        err = merged;
        goto out;
    }
    ts->prototypes[p].instances[merged].merged = true;
    for (uint32_t k = 0; k < count; k++)
        ts->prototypes[p].instances[list[k]].merged_into = (uint32_t)merged;
out:
    free(pos);
    free(nrm);
    free(rgba);
    free(idx);
    return err;
}

/* Merges prototype p's small instances, in their order, as far as the
 * tileset's budget for baked copies goes. */
static int merge_small_instances(struct tw_tileset *ts, uint32_t p, uint32_t below,
                                 uint64_t *budget)
{
    const uint32_t n = ts->prototypes[p].instance_count;
    uint32_t *list = malloc(sizeof(*list) * (n ? n : 1));
    if (!list)
        return TW_ERR_NOMEM;
    uint32_t count = 0;
    uint64_t bytes = 0;
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_instance *in = &ts->prototypes[p].instances[k];
        const uint32_t triangles = ts->meshes[in->mesh].triangle_count;
        if (triangles == 0 || triangles >= below)
            continue;
        const uint64_t more = baked_bytes(ts, in);
        if (bytes + more > *budget)
            break;
        bytes += more;
        list[count++] = k;
    }
    int err = TW_OK;
    if (count >= 2) {
        err = merge_group(ts, p, list, count);
        *budget -= bytes;
    }
    free(list);
    return err;
}

int tw_tileset_finish(struct tw_tileset *ts, uint32_t max_cluster_triangles)
{
    if (!ts || ts->finished || ts->prototype_count == 0)
        return TW_ERR_INVALID;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        if (ts->prototypes[p].instance_count == 0)
            return TW_ERR_INVALID;

    int err = TW_OK;
    /* Before merging: baked into tile-local space and rounded, a collinear
     * triangle may no longer look collinear. */
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        drop_triangles_without_area(&ts->meshes[k]);
    /* Without a cluster size the caller wants whole meshes: nothing merged. */
    const uint32_t below = ts->merge_triangles ? ts->merge_triangles : TW_TILESET_MERGE_TRIANGLES;
    uint64_t budget = TW_TILESET_MERGE_BYTES;
    for (uint32_t p = 0; p < ts->prototype_count && max_cluster_triangles > 0 && below > 1; p++) {
        err = merge_small_instances(ts, p, below, &budget);
        if (err)
            return err;
    }
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        err = split_mesh(ts, k, max_cluster_triangles, &impl(ts)->part_cap);
        if (err)
            return err;
    }

    ts->common_box = tw_box_empty();
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        struct tw_prototype *proto = &ts->prototypes[p];
        uint64_t clusters = 0;
        for (uint32_t k = 0; k < proto->instance_count; k++)
            if (proto->instances[k].merged_into == TW_INSTANCE_NONE)
                clusters += ts->meshes[proto->instances[k].mesh].part_count;
        if (clusters > UINT32_MAX)
            return TW_ERR_LIMIT;
        proto->clusters = malloc(sizeof(*proto->clusters) * clusters);
        if (!proto->clusters)
            return TW_ERR_NOMEM;
        proto->cluster_count = 0;
        proto->triangle_count = 0;
        proto->box = tw_box_empty();
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            struct tw_instance *in = &proto->instances[k];
            const struct tw_mesh *m = &ts->meshes[in->mesh];
            if (in->merged_into != TW_INSTANCE_NONE) {
                /* Drawn by its merged instance; its box still says where it is. */
                in->box = triangles_box(m, 0, m->triangle_count, in->transform);
                continue;
            }
            in->box = tw_box_empty();
            for (uint32_t q = m->first_part; q < m->first_part + m->part_count; q++) {
                const struct tw_mesh_part *part = &ts->parts[q];
                struct tw_cluster *c = &proto->clusters[proto->cluster_count++];
                c->instance = k;
                c->part = q;
                c->triangle_count = part->triangle_count;
                /* Transformed vertices, not a transformed box: rotated
                 * instances keep tight cluster boxes. */
                c->box = triangles_box(m, part->first_triangle, part->triangle_count,
                                       in->transform);
                tw_box_add_box(&in->box, &c->box);
            }
            proto->triangle_count += m->triangle_count;
            tw_box_add_box(&proto->box, &in->box);
        }
        if (proto->cluster_count == 0)   /* no triangle with area: as empty as no instance */
            return TW_ERR_INVALID;
        tw_box_add_box(&ts->common_box, &proto->box);
    }
    /* Content that overhangs its cell by many footprints costs every frame
     * (tiles.h, TW_TILES_MAX_SPAN). */
    if ((double)ts->common_box.max[0] - ts->common_box.min[0] >
            (double)TW_TILES_MAX_SPAN * ts->footprint[0] ||
        (double)ts->common_box.max[2] - ts->common_box.min[2] >
            (double)TW_TILES_MAX_SPAN * ts->footprint[1])
        return TW_ERR_LIMIT;
    ts->max_cluster_triangles = max_cluster_triangles;
    ts->finished = true;
    return TW_OK;
}

/* Lays ts out at c (sizing only when c->base is NULL); returns the new struct. */
static void *pack_into(const void *from, struct tw_pack_cursor *c)
{
    const struct tw_tileset *ts = from;
    struct tileset *out = tw_pack_take(c, impl_const(ts), sizeof(*out));
    struct tw_material *materials =
        tw_pack_take(c, ts->materials, sizeof(*ts->materials) * ts->material_count);
    struct tw_mesh *meshes = tw_pack_take(c, ts->meshes, sizeof(*ts->meshes) * ts->mesh_count);
    struct tw_mesh_part *parts = tw_pack_take(c, ts->parts, sizeof(*ts->parts) * ts->part_count);
    struct tw_prototype *protos =
        tw_pack_take(c, ts->prototypes, sizeof(*ts->prototypes) * ts->prototype_count);
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        const struct tw_mesh *m = &ts->meshes[k];
        float *pos = tw_pack_take(c, m->positions, sizeof(float) * 3 * (size_t)m->vertex_count);
        float *nor = tw_pack_take(c, m->normals, sizeof(float) * 3 * (size_t)m->vertex_count);
        uint32_t *idx =
            tw_pack_take(c, m->indices, sizeof(uint32_t) * 3 * (size_t)m->triangle_count);
        uint8_t *rgba = m->colors ? tw_pack_take(c, m->colors, 4 * (size_t)m->vertex_count) : NULL;
        if (meshes) {
            meshes[k].positions = pos;
            meshes[k].normals = nor;
            meshes[k].indices = idx;
            meshes[k].colors = rgba;
        }
    }
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *pr = &ts->prototypes[p];
        struct tw_instance *inst =
            tw_pack_take(c, pr->instances, sizeof(*pr->instances) * pr->instance_count);
        struct tw_cluster *cl =
            tw_pack_take(c, pr->clusters, sizeof(*pr->clusters) * pr->cluster_count);
        if (protos) {
            protos[p].instances = inst;
            protos[p].clusters = cl;
        }
    }
    if (!out)
        return NULL;
    out->ts.materials = materials;
    out->material_cap = ts->material_count;
    out->ts.meshes = meshes;
    out->mesh_cap = ts->mesh_count;
    out->ts.parts = parts;
    out->part_cap = ts->part_count;
    out->ts.prototypes = protos;
    out->prototype_cap = ts->prototype_count;
    out->instance_cap = NULL;
    out->packed_bytes = c->used;
    out->lods = NULL;           /* the levels stay with the original's */
    return &out->ts;
}

int tw_tileset_pack(struct tw_tileset **ts)
{
    if (!ts || !*ts || !(*ts)->finished)
        return TW_ERR_INVALID;
    struct tw_tileset *out = tw_pack_block(*ts, pack_into);
    if (!out)
        return TW_ERR_NOMEM;
    tw_tileset_destroy(*ts);
    *ts = out;
    return TW_OK;
}

uint64_t tw_tileset_geometry_bytes(const struct tw_tileset *ts)
{
    uint64_t bytes = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        bytes += (uint64_t)ts->meshes[k].vertex_count * TW_TILESET_GPU_VERTEX_BYTES +
                 (uint64_t)ts->meshes[k].triangle_count * 12u;
    return bytes;
}

uint64_t tw_tileset_bytes(const struct tw_tileset *ts)
{
    if (!ts)
        return 0;
    const struct tileset *t = impl_const(ts);
    if (t->packed_bytes)
        return t->packed_bytes;
    uint64_t bytes = sizeof(*t) + (uint64_t)sizeof(*ts->materials) * t->material_cap +
                     (uint64_t)sizeof(*ts->meshes) * t->mesh_cap +
                     (uint64_t)sizeof(*ts->parts) * t->part_cap +
                     (uint64_t)(sizeof(*ts->prototypes) + sizeof(*t->instance_cap)) *
                         t->prototype_cap;
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        bytes += (uint64_t)ts->meshes[k].vertex_count * (6u * sizeof(float) +
                                                         (ts->meshes[k].colors ? 4u : 0u)) +
                 (uint64_t)ts->meshes[k].triangle_count * 3u * sizeof(uint32_t);
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        bytes += (uint64_t)sizeof(struct tw_instance) * t->instance_cap[p] +
                 (uint64_t)sizeof(struct tw_cluster) * ts->prototypes[p].cluster_count;
    return bytes;
}
