/*
 * What the tests of generators and providers read from a tileset: pieces of
 * a bit-for-bit comparison of two tilesets (each test adds what else it
 * compares), and the bounds of a triangle as its instance places it.
 */
#ifndef TW_TESTS_TILESET_CHECKS_H
#define TW_TESTS_TILESET_CHECKS_H

#include <math.h>
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

/* p through an instance's row-major 3x4 transform. */
static void transform_point(const float m[12], const float p[3], float out[3])
{
    for (int r = 0; r < 3; r++)
        out[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3];
}

/* The tile-local bounds of triangle t of m as instance in places it. */
static void placed_triangle_bounds(const struct tw_instance *in, const struct tw_mesh *m,
                                   uint32_t t, float lo[3], float hi[3])
{
    for (int a = 0; a < 3; a++) {
        lo[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (int v = 0; v < 3; v++) {
        float q[3];
        transform_point(in->transform, m->positions + 3 * (size_t)m->indices[3 * t + v], q);
        for (int a = 0; a < 3; a++) {
            lo[a] = fminf(lo[a], q[a]);
            hi[a] = fmaxf(hi[a], q[a]);
        }
    }
}

#endif
