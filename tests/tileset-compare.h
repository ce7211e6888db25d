/*
 * Pieces of a bit-for-bit comparison of two tilesets, for the tests that
 * check that a generator or provider makes the same content from the same
 * seed: each test adds what else it compares.
 */
#ifndef TW_TESTS_TILESET_COMPARE_H
#define TW_TESTS_TILESET_COMPARE_H

#include <stdbool.h>
#include <string.h>

#include "tileworld/tiles.h"

/* The same counts, positions, normals and indices. */
static bool mesh_data_identical(const struct tw_mesh *x, const struct tw_mesh *y)
{
    const size_t vbytes = sizeof(float) * 3 * x->vertex_count;
    return x->vertex_count == y->vertex_count && x->triangle_count == y->triangle_count &&
           memcmp(x->positions, y->positions, vbytes) == 0 &&
           memcmp(x->normals, y->normals, vbytes) == 0 &&
           memcmp(x->indices, y->indices, sizeof(uint32_t) * 3 * x->triangle_count) == 0;
}

/* The same name, counts and box (not the instances and clusters). */
static bool prototype_head_identical(const struct tw_prototype *x, const struct tw_prototype *y)
{
    return strcmp(x->name, y->name) == 0 && x->instance_count == y->instance_count &&
           x->cluster_count == y->cluster_count && x->triangle_count == y->triangle_count &&
           memcmp(&x->box, &y->box, sizeof(x->box)) == 0;
}

#endif
