/*
 * Private to tilesets/: the deterministic random stream and the growable
 * flat-shaded mesh buffer that the procedural generators (city, forest,
 * hybrid) share. Not installed, not public API.
 */
#ifndef TW_TILESETS_MESH_BUILDER_H
#define TW_TILESETS_MESH_BUILDER_H

#include <stdbool.h>
#include <stdint.h>

#include "tileworld/tiles.h"

/* A small PRNG (splitmix64) seeded from tw_tiles_hash(): generators take all
 * their randomness from it, so a seed gives the same world everywhere. */
struct tw_rng {
    uint64_t state;
};

struct tw_rng tw_rng_seeded(uint64_t seed, int64_t i, int64_t j);
uint64_t tw_rng_next(struct tw_rng *r);
/* Uniform in [0, 1); 24 bits so that the value is exact in float. */
float tw_rng_float(struct tw_rng *r);
/* Uniform in [lo, hi). */
float tw_rng_range(struct tw_rng *r, float lo, float hi);
/* Uniform in [0, n). */
uint32_t tw_rng_below(struct tw_rng *r, uint32_t n);
/* True with probability p. */
bool tw_rng_chance(struct tw_rng *r, float p);

/* Accumulates flat-shaded triangles. In count_only mode nothing is stored,
 * so a triangle budget can be fitted by running the same generator; errors
 * are sticky and checked once, when the mesh is added to a tileset. */
struct tw_mesh_builder {
    float *positions;
    float *normals;
    uint32_t *indices;
    uint32_t vertex_count, vertex_cap;
    uint32_t triangle_count, triangle_cap;
    bool count_only;
    int err;
};

/* Empties the builder, keeping its memory. */
void tw_mesh_builder_reset(struct tw_mesh_builder *b, bool count_only);
/* Frees its memory; the builder is empty and usable again. */
void tw_mesh_builder_release(struct tw_mesh_builder *b);
/* Makes room for that many more vertices and triangles; false (and a sticky
 * error) when it cannot. */
bool tw_mesh_builder_reserve(struct tw_mesh_builder *b, uint32_t vertices, uint32_t triangles);
/* Adds the builder's triangles to ts as a mesh and sets *mesh to its index;
 * the builder's sticky error, or tw_tileset_add_mesh()'s, when there is one. */
int tw_mesh_builder_add_to(const struct tw_mesh_builder *b, struct tw_tileset *ts,
                           uint32_t *mesh);

#endif
