/*
 * Meshes the tests build tilesets from, alike.
 */
#ifndef TW_TESTS_MESHES_H
#define TW_TESTS_MESHES_H

#include <stdint.h>
#include <string.h>

#include "tileworld/tiles.h"

/* A box mesh with a face's own vertices (flat normals, as buildings are):
 * 24 vertices, 12 triangles, unit cube [0, 1]^3. Returns the mesh's index
 * in ts or a negative error. */
static inline int add_cube(struct tw_tileset *ts)
{
    static const float corners[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    static const int faces[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                    {3, 7, 6, 2}, {0, 4, 7, 3}, {1, 2, 6, 5}};
    float pos[24 * 3];
    uint32_t idx[36];
    for (int f = 0; f < 6; f++) {
        for (int v = 0; v < 4; v++)
            memcpy(pos + 3 * (4 * f + v), corners[faces[f][v]], sizeof(float) * 3);
        const uint32_t b = 4u * (uint32_t)f;
        const uint32_t tri[6] = {b, b + 1, b + 2, b, b + 2, b + 3};
        memcpy(idx + 6 * f, tri, sizeof(tri));
    }
    return tw_tileset_add_mesh(ts, pos, NULL, 24, idx, 12);
}

#endif
