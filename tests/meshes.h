/*
 * Meshes the tests build tilesets from, alike.
 */
#ifndef TW_TESTS_MESHES_H
#define TW_TESTS_MESHES_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
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

/* A grid of n x n quads, size metres across: a wavy height field over
 * [0, size]^2 in x and z, or (upright) a flat wall in the plane z = 0.
 * Returns the mesh's index in ts or a negative error. */
static inline int add_grid(struct tw_tileset *ts, uint32_t n, float size, bool upright)
{
    const uint32_t nv = (n + 1) * (n + 1);
    float *pos = malloc(sizeof(float) * 3 * nv);
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * n * n);
    if (!pos || !idx) {
        free(pos);
        free(idx);
        return TW_ERR_NOMEM;
    }
    for (uint32_t j = 0; j <= n; j++)
        for (uint32_t i = 0; i <= n; i++) {
            float *p = pos + 3 * (j * (n + 1) + i);
            const float u = size * (float)i / (float)n, v = size * (float)j / (float)n;
            p[0] = u;
            p[1] = upright ? v : 0.5f * sinf(u * 0.3f) * cosf(v * 0.2f);
            p[2] = upright ? 0.0f : v;
        }
    uint32_t t = 0;
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
            const uint32_t q[6] = {a, c, b, b, c, d};
            memcpy(idx + 6 * t++, q, sizeof(q));
        }
    const int m = tw_tileset_add_mesh(ts, pos, NULL, nv, idx, 2 * n * n);
    free(pos);
    free(idx);
    return m;
}

/* 400 small buildings on a 20 x 20 grid of 2 m (cube of mesh cube, heights
 * 1 to 7 m) into prototype proto: what edge collapse stalls on. False if
 * an instance was refused. */
static inline bool add_houses(struct tw_tileset *ts, int proto, int cube, int material)
{
    bool ok = true;
    for (int k = 0; k < 400; k++) {
        const float x = 2.0f * (float)(k % 20), z = 2.0f * (float)(k / 20);
        const float h = 1.0f + (float)(k % 7);
        const float m[12] = {1, 0, 0, x, 0, h, 0, 0, 0, 0, 1, z};
        ok &= tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)material,
                                      m) >= 0;
    }
    return ok;
}

/* A 20 x 20 m wall (a grid of n x n quads) with 100 dark 1 x 1 m windows
 * 5 cm in front of it, 2 m apart: the windows are mesh win, the wall mesh
 * wall. */
static inline void add_facade(struct tw_tileset *ts, uint32_t n, int *wall, int *win)
{
    *wall = add_grid(ts, n, 20.0f, true);
    float wpos[100 * 4 * 3];
    uint32_t widx[100 * 6];
    for (uint32_t k = 0; k < 100; k++) {
        const float x = 0.5f + 2.0f * (float)(k % 10), y = 0.5f + 2.0f * (float)(k / 10);
        const float corner[4][3] = {{x, y, 0.05f}, {x + 1, y, 0.05f}, {x, y + 1, 0.05f},
                                    {x + 1, y + 1, 0.05f}};
        memcpy(wpos + 12 * k, corner, sizeof(corner));
        const uint32_t b = 4 * k, q[6] = {b, b + 1, b + 2, b + 1, b + 3, b + 2};
        memcpy(widx + 6 * k, q, sizeof(q));
    }
    *win = tw_tileset_add_mesh(ts, wpos, NULL, 400, widx, 200);
}

/* Rough ground: n x n quads, size metres across, heights at random (seed)
 * up to 4 m, each quad in one of colours materials at random, as prototype
 * proto: little of it simplifies, so its levels take long to build (and
 * to measure). False where the builder refused a part. */
static inline bool add_rough_ground(struct tw_tileset *ts, int proto, uint32_t n, float size,
                                    uint32_t colours, uint64_t seed)
{
    const uint32_t nv = (n + 1) * (n + 1);
    float *pos = malloc(sizeof(float) * 3 * nv);
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * (size_t)n * n);
    bool ok = pos && idx && proto >= 0;
    uint64_t h = seed;
    for (uint32_t v = 0; v < nv && ok; v++) {
        h = h * 6364136223846793005ull + 1442695040888963407ull;
        pos[3 * v] = size * (float)(v % (n + 1)) / (float)n;
        pos[3 * v + 1] = (float)((h >> 33) % 1000) * 0.004f;
        pos[3 * v + 2] = size * (float)(v / (n + 1)) / (float)n;
    }
    for (uint32_t c = 0; c < colours && ok; c++) {
        uint32_t nt = 0;
        for (uint32_t q = 0; q < n * n; q++) {
            const uint64_t hq = (q + 1) * 0x9E3779B97F4A7C15ull ^ seed;
            if ((hq >> 40) % colours != c)
                continue;
            const uint32_t v = (q / n) * (n + 1) + q % n;
            const uint32_t quad[6] = {v, v + n + 1, v + 1, v + 1, v + n + 1, v + n + 2};
            memcpy(idx + 3 * (size_t)nt, quad, sizeof(quad));
            nt += 2;
        }
        const float k = (float)c / (float)colours;
        const int mat = tw_tileset_add_material(ts, (const float[4]){0.1f + 0.8f * k, 0.5f,
                                                                     0.9f - 0.8f * k, 1.0f});
        const int mesh = tw_tileset_add_mesh(ts, pos, NULL, nv, idx, nt);
        ok = mat >= 0 && mesh >= 0 &&
             tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)mesh, (uint32_t)mat, NULL) >= 0;
    }
    free(pos);
    free(idx);
    return ok;
}

#endif
