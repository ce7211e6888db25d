/* The generators' shared random stream and mesh buffer (mesh-builder.h). */
#include "tilesets/mesh-builder.h"

#include <stdlib.h>
#include <string.h>

struct tw_rng tw_rng_seeded(uint64_t seed, int64_t i, int64_t j)
{
    struct tw_rng r = {tw_tiles_hash(seed, i, j)};
    return r;
}

uint64_t tw_rng_next(struct tw_rng *r)
{
    uint64_t z = (r->state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

float tw_rng_float(struct tw_rng *r)
{
    return (float)(tw_rng_next(r) >> 40) * 0x1.0p-24f;
}

float tw_rng_range(struct tw_rng *r, float lo, float hi)
{
    return lo + (hi - lo) * tw_rng_float(r);
}

uint32_t tw_rng_below(struct tw_rng *r, uint32_t n)
{
    return (uint32_t)(((tw_rng_next(r) >> 32) * (uint64_t)n) >> 32);
}

bool tw_rng_chance(struct tw_rng *r, float p)
{
    return tw_rng_float(r) < p;
}

void tw_mesh_builder_reset(struct tw_mesh_builder *b, bool count_only)
{
    b->vertex_count = 0;
    b->triangle_count = 0;
    b->count_only = count_only;
    b->err = TW_OK;
}

void tw_mesh_builder_release(struct tw_mesh_builder *b)
{
    free(b->positions);
    free(b->normals);
    free(b->indices);
    memset(b, 0, sizeof(*b));
}

bool tw_mesh_builder_reserve(struct tw_mesh_builder *b, uint32_t vertices, uint32_t triangles)
{
    if (b->vertex_count > UINT32_MAX / 2 - vertices ||
        b->triangle_count > UINT32_MAX / 8 - triangles) {
        b->err = TW_ERR_LIMIT;
        return false;
    }
    if (b->vertex_count + vertices > b->vertex_cap) {
        uint32_t cap = b->vertex_cap ? b->vertex_cap : 1024;
        while (cap < b->vertex_count + vertices)
            cap *= 2;
        float *p = realloc(b->positions, sizeof(float) * 3 * (size_t)cap);
        if (p)
            b->positions = p;
        float *n = p ? realloc(b->normals, sizeof(float) * 3 * (size_t)cap) : NULL;
        if (n)
            b->normals = n;
        if (!p || !n) {
            b->err = TW_ERR_NOMEM;
            return false;
        }
        b->vertex_cap = cap;
    }
    if (b->triangle_count + triangles > b->triangle_cap) {
        uint32_t cap = b->triangle_cap ? b->triangle_cap : 1024;
        while (cap < b->triangle_count + triangles)
            cap *= 2;
        uint32_t *i = realloc(b->indices, sizeof(uint32_t) * 3 * (size_t)cap);
        if (!i) {
            b->err = TW_ERR_NOMEM;
            return false;
        }
        b->indices = i;
        b->triangle_cap = cap;
    }
    return true;
}

int tw_mesh_builder_add_to(const struct tw_mesh_builder *b, struct tw_tileset *ts,
                           uint32_t *mesh)
{
    if (b->err)
        return b->err;
    const int index = tw_tileset_add_mesh(ts, b->positions, b->normals, b->vertex_count,
                                          b->indices, b->triangle_count);
    if (index < 0)
        return index;
    *mesh = (uint32_t)index;
    return TW_OK;
}
