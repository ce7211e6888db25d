/* The flat-shaded shapes of the procedural models (shapes.h). */
#include "tilesets/shapes.h"

#include <math.h>
#include <string.h>

/* ---- polygons ---------------------------------------------------------------------- */

/* A fan of the n points p with its own vertices and the face normal, wound
 * counter-clockwise seen from facing; dropped when the cross product of
 * its first two edges is no longer than min_cross. */
static void emit_fan(struct tw_mesh_builder *b, const float p[][3], uint32_t n,
                     const float facing[3], float min_cross)
{
    if (b->err)
        return;
    const float e1[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const float e2[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    float c[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                  e1[0] * e2[1] - e1[1] * e2[0]};
    const float len = sqrtf(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(len > min_cross))
        return;
    const bool flip = c[0] * facing[0] + c[1] * facing[1] + c[2] * facing[2] < 0.0f;
    const float sign = flip ? -1.0f / len : 1.0f / len;
    for (int k = 0; k < 3; k++)
        c[k] *= sign;
    if (b->count_only) {
        b->vertex_count += n;
        b->triangle_count += n - 2;
        return;
    }
    if (!tw_mesh_builder_reserve(b, n, n - 2))
        return;
    const uint32_t base = b->vertex_count;
    for (uint32_t v = 0; v < n; v++) {
        const float *q = p[flip ? (n - v) % n : v];
        memcpy(b->positions + 3 * (size_t)(base + v), q, sizeof(float) * 3);
        memcpy(b->normals + 3 * (size_t)(base + v), c, sizeof(float) * 3);
    }
    for (uint32_t t = 0; t + 2 < n; t++) {
        uint32_t *tri = b->indices + 3 * (size_t)(b->triangle_count + t);
        tri[0] = base;
        tri[1] = base + t + 1;
        tri[2] = base + t + 2;
    }
    b->vertex_count += n;
    b->triangle_count += n - 2;
}

void tw_shape_polygon(struct tw_mesh_builder *b, const float p[][3], uint32_t n,
                      const float facing[3])
{
    emit_fan(b, p, n, facing, 1e-6f);
}

void tw_shape_quad(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                   const float p2[3], const float p3[3], const float facing[3])
{
    float p[4][3];
    memcpy(p[0], p0, sizeof(p[0]));
    memcpy(p[1], p1, sizeof(p[1]));
    memcpy(p[2], p2, sizeof(p[2]));
    memcpy(p[3], p3, sizeof(p[3]));
    tw_shape_polygon(b, (const float(*)[3])p, 4, facing);
}

void tw_shape_triangle(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                       const float p2[3], const float facing[3])
{
    float p[3][3];
    memcpy(p[0], p0, sizeof(p[0]));
    memcpy(p[1], p1, sizeof(p[1]));
    memcpy(p[2], p2, sizeof(p[2]));
    emit_fan(b, (const float(*)[3])p, 3, facing, 1e-7f);
}

void tw_shape_outward(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                      const float p2[3], const float inside[3])
{
    float facing[3];
    for (int k = 0; k < 3; k++)
        facing[k] = (p0[k] + p1[k] + p2[k]) / 3.0f - inside[k];
    tw_shape_triangle(b, p0, p1, p2, facing);
}

void tw_shape_two_sided(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                        const float p2[3])
{
    const float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    const float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                        e1[0] * e2[1] - e1[1] * e2[0]};
    const float m[3] = {-n[0], -n[1], -n[2]};
    tw_shape_triangle(b, p0, p1, p2, n);
    tw_shape_triangle(b, p0, p1, p2, m);
}

/* ---- boxes, prisms, frusta --------------------------------------------------------- */

void tw_shape_box(struct tw_mesh_builder *b, const float lo[3], const float hi[3],
                  unsigned mask)
{
    for (int axis = 0; axis < 3; axis++) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        for (int side = 0; side < 2; side++) {
            if (!(mask & (1u << (2 * axis + side))))
                continue;
            float facing[3] = {0, 0, 0};
            facing[axis] = side ? 1.0f : -1.0f;
            float p[4][3];
            for (int k = 0; k < 4; k++) {
                p[k][axis] = side ? hi[axis] : lo[axis];
                p[k][u] = (k == 1 || k == 2) ? hi[u] : lo[u];
                p[k][v] = (k >= 2) ? hi[v] : lo[v];
            }
            tw_shape_polygon(b, (const float(*)[3])p, 4, facing);
        }
    }
}

void tw_shape_prism(struct tw_mesh_builder *b, float cx, float cz, float radius, float y0,
                    float y1, uint32_t sides, bool top)
{
    float ring[16][2];
    if (sides > 16)
        sides = 16;
    for (uint32_t k = 0; k < sides; k++) {
        const double a = 2.0 * 3.14159265358979323846 * k / sides;
        ring[k][0] = cx + radius * (float)cos(a);
        ring[k][1] = cz + radius * (float)sin(a);
    }
    for (uint32_t k = 0; k < sides; k++) {
        const float *a = ring[k], *c = ring[(k + 1) % sides];
        const float p0[3] = {a[0], y0, a[1]}, p1[3] = {c[0], y0, c[1]};
        const float p2[3] = {c[0], y1, c[1]}, p3[3] = {a[0], y1, a[1]};
        const float facing[3] = {(a[0] + c[0]) * 0.5f - cx, 0.0f, (a[1] + c[1]) * 0.5f - cz};
        tw_shape_quad(b, p0, p1, p2, p3, facing);
    }
    if (top) {
        float p[16][3];
        for (uint32_t k = 0; k < sides; k++) {
            p[k][0] = ring[k][0];
            p[k][1] = y1;
            p[k][2] = ring[k][1];
        }
        const float up[3] = {0, 1, 0};
        tw_shape_polygon(b, (const float(*)[3])p, sides, up);
    }
}

void tw_shape_frustum(struct tw_mesh_builder *b, float cx, float cz, float y0, float y1,
                      float r0, float r1, uint32_t sides, float phase, bool bottom_cap)
{
    for (uint32_t k = 0; k < sides; k++) {
        const float a0 = phase + TW_TAU * (float)k / (float)sides;
        const float a1 = phase + TW_TAU * (float)(k + 1) / (float)sides;
        const float c0 = cosf(a0), s0 = sinf(a0), c1 = cosf(a1), s1 = sinf(a1);
        const float p0[3] = {cx + r0 * c0, y0, cz + r0 * s0};
        const float p1[3] = {cx + r0 * c1, y0, cz + r0 * s1};
        const float p2[3] = {cx + r1 * c1, y1, cz + r1 * s1};
        const float p3[3] = {cx + r1 * c0, y1, cz + r1 * s0};
        /* Outward in the horizontal: right for any slope. */
        const float facing[3] = {c0 + c1, 0.0f, s0 + s1};
        tw_shape_triangle(b, p0, p1, p2, facing);
        if (r1 > 0.0f)
            tw_shape_triangle(b, p0, p2, p3, facing);
    }
    if (bottom_cap) {
        const float down[3] = {0.0f, -1.0f, 0.0f};
        const float first[3] = {cx + r0 * cosf(phase), y0, cz + r0 * sinf(phase)};
        for (uint32_t k = 1; k + 1 < sides; k++) {
            const float a0 = phase + TW_TAU * (float)k / (float)sides;
            const float a1 = phase + TW_TAU * (float)(k + 1) / (float)sides;
            const float p1[3] = {cx + r0 * cosf(a0), y0, cz + r0 * sinf(a0)};
            const float p2[3] = {cx + r0 * cosf(a1), y0, cz + r0 * sinf(a1)};
            tw_shape_triangle(b, first, p1, p2, down);
        }
    }
}

/* ---- ellipsoids and blobs ---------------------------------------------------------- */

/* One triangle of a subdivided icosahedron: corners v, points on its
 * faces (not normalised), and their distances len from its centre, so
 * that v[k] / len[k] lies on the unit sphere. */
typedef void (*icosphere_triangle_fn)(void *user, const float v[3][3], const float len[3]);

/* Calls triangle(user, ...) for each of the 20 n^2 triangles of an
 * icosahedron with every face split into n x n, face by face, always in
 * the same order. */
static void icosphere_each(uint32_t n, icosphere_triangle_fn triangle, void *user)
{
#define PHI 1.6180339887f
    static const float ico[12][3] = {
        {-1, PHI, 0}, {1, PHI, 0}, {-1, -PHI, 0}, {1, -PHI, 0}, {0, -1, PHI}, {0, 1, PHI},
        {0, -1, -PHI}, {0, 1, -PHI}, {PHI, 0, -1}, {PHI, 0, 1}, {-PHI, 0, -1}, {-PHI, 0, 1},
    };
#undef PHI
    static const uint8_t faces[20][3] = {
        {0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
        {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
        {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1},
    };
    for (int f = 0; f < 20; f++) {
        const float *a = ico[faces[f][0]], *b = ico[faces[f][1]], *c = ico[faces[f][2]];
        for (uint32_t i = 0; i < n; i++) {
            for (uint32_t j = 0; i + j < n; j++) {
                /* Two triangles per grid cell, one where the cell is cut by
                 * the face's edge. */
                const uint32_t corners[2][3][2] = {
                    {{i, j}, {i + 1, j}, {i, j + 1}},
                    {{i + 1, j}, {i + 1, j + 1}, {i, j + 1}},
                };
                for (int t = 0; t < (i + j + 1 < n ? 2 : 1); t++) {
                    float v[3][3], len[3];
                    for (int k = 0; k < 3; k++) {
                        const uint32_t ci = corners[t][k][0], cj = corners[t][k][1];
                        for (int d = 0; d < 3; d++)
                            v[k][d] = a[d] + (b[d] - a[d]) * (float)ci / (float)n +
                                      (c[d] - a[d]) * (float)cj / (float)n;
                        len[k] = sqrtf(v[k][0] * v[k][0] + v[k][1] * v[k][1] + v[k][2] * v[k][2]);
                    }
                    triangle(user, (const float(*)[3])v, len);
                }
            }
        }
    }
}

struct ellipsoid {
    struct tw_mesh_builder *b;
    const float *centre, *radius;
};

static void ellipsoid_triangle(void *user, const float v[3][3], const float len[3])
{
    const struct ellipsoid *el = user;
    float p[3][3];
    float facing[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
        for (int d = 0; d < 3; d++)
            p[k][d] = el->centre[d] + el->radius[d] * v[k][d] / len[k];
        for (int d = 0; d < 3; d++)
            facing[d] += (p[k][d] - el->centre[d]) / el->radius[d];
    }
    tw_shape_polygon(el->b, (const float(*)[3])p, 3, facing);
}

void tw_shape_ellipsoid(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                        uint32_t n)
{
    struct ellipsoid el = {b, centre, radius};
    icosphere_each(n, ellipsoid_triangle, &el);
}

void tw_lumps_init(struct tw_lumps *l, struct tw_rng *r, float amount)
{
    for (int k = 0; k < 4; k++) {
        const float y = tw_rng_range(r, -1.0f, 1.0f), a = tw_rng_range(r, 0.0f, TW_TAU);
        const float h = sqrtf(fmaxf(0.0f, 1.0f - y * y));
        l->axis[k][0] = h * cosf(a);
        l->axis[k][1] = y;
        l->axis[k][2] = h * sinf(a);
        l->freq[k] = tw_rng_range(r, 1.5f, 4.0f);
        l->phase[k] = tw_rng_range(r, 0.0f, TW_TAU);
        l->amp[k] = amount * tw_rng_range(r, 0.04f, 0.09f);
    }
}

static float lumps_at(const struct tw_lumps *l, const float d[3])
{
    float s = 1.0f;
    for (int k = 0; k < 4; k++)
        s += l->amp[k] * sinf(l->freq[k] * (d[0] * l->axis[k][0] + d[1] * l->axis[k][1] +
                                            d[2] * l->axis[k][2]) + l->phase[k]);
    return s;
}

struct blob {
    struct tw_mesh_builder *b;
    const float *centre, *radius;
    const struct tw_lumps *lumps;   /* NULL: smooth */
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
    tw_shape_outward(bl->b, p[0], p[1], p[2], bl->centre);
}

void tw_shape_blob(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                   uint32_t n, const struct tw_lumps *lumps, float floor_y)
{
    struct blob bl = {b, centre, radius, lumps, floor_y};
    icosphere_each(n, blob_triangle, &bl);
}
