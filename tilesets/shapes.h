/*
 * Private to tilesets/: the flat-shaded shapes that the procedural models
 * (buildings.c, trees.c) and layouts are made of. Every triangle gets its
 * own vertices and the face normal, wound counter-clockwise seen from the
 * side its facing vector points to, because the renderer culls back faces.
 * In a count_only builder (mesh-builder.h) the shapes only count. Not
 * installed, not public API.
 */
#ifndef TW_TILESETS_SHAPES_H
#define TW_TILESETS_SHAPES_H

#include <stdbool.h>
#include <stdint.h>

#include "tilesets/mesh-builder.h"

#define TW_TAU 6.28318530717958647692f

/* A planar convex polygon of n points as a triangle fan, facing.
 * Degenerate polygons (cross product of the first two edges up to 1e-6)
 * are dropped, in count_only mode too, so that counts agree. */
void tw_shape_polygon(struct tw_mesh_builder *b, const float p[][3], uint32_t n,
                      const float facing[3]);
/* The quadrilateral p0 p1 p2 p3 (convex, planar), facing. */
void tw_shape_quad(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                   const float p2[3], const float p3[3], const float facing[3]);
/* One triangle, facing; dropped only when its cross product is up to 1e-7,
 * so that the forest's small leaves survive. */
void tw_shape_triangle(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                       const float p2[3], const float facing[3]);
/* A triangle of a solid that is star-shaped around inside: it faces away
 * from inside. */
void tw_shape_outward(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                      const float p2[3], const float inside[3]);
/* Both sides of a thin triangle (a leaf). */
void tw_shape_two_sided(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                        const float p2[3]);

/* Faces of an axis-aligned box: bit 2 * axis + side, side 1 the + face. */
enum tw_box_face {
    TW_FACE_NX = 1 << 0, TW_FACE_PX = 1 << 1,
    TW_FACE_NY = 1 << 2, TW_FACE_PY = 1 << 3,
    TW_FACE_NZ = 1 << 4, TW_FACE_PZ = 1 << 5,
    TW_FACES_SIDES = TW_FACE_NX | TW_FACE_PX | TW_FACE_NZ | TW_FACE_PZ,
    TW_FACES_NO_BOTTOM = TW_FACES_SIDES | TW_FACE_PY,
};

/* The faces of the box [lo, hi] that mask (enum tw_box_face) selects. */
void tw_shape_box(struct tw_mesh_builder *b, const float lo[3], const float hi[3],
                  unsigned mask);

/* A vertical prism about (cx, cz) from y0 to y1 whose section is a regular
 * polygon of sides (at most 16) corners on radius: its sides, and its top
 * when asked. Quads, angles in double precision. */
void tw_shape_prism(struct tw_mesh_builder *b, float cx, float cz, float radius, float y0,
                    float y1, uint32_t sides, bool top);

/* A vertical frustum about (cx, cz) from radius r0 at y0 to r1 at y1 (r1 =
 * 0: a cone), sides faces, the ring turned by phase radians; a bottom cap
 * facing down when asked. Triangles, angles in single precision. */
void tw_shape_frustum(struct tw_mesh_builder *b, float cx, float cz, float y0, float y1,
                      float r0, float r1, uint32_t sides, float phase, bool bottom_cap);

/* An ellipsoid of radius about centre: an icosahedron with every face
 * split into n x n triangles, its points pushed onto the ellipsoid
 * (centre + radius * v / |v|): 20 n^2 triangles. */
void tw_shape_ellipsoid(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                        uint32_t n);

/* A smooth radial bumpiness for blobs: a function of the direction only,
 * so that the vertices shared by neighbouring faces agree and no cracks
 * open. */
struct tw_lumps {
    float axis[4][3];
    float freq[4], phase[4], amp[4];
};

/* Draws lumps from r; amount scales their height (1: within 1 +- 0.36). */
void tw_lumps_init(struct tw_lumps *l, struct tw_rng *r, float amount);

/* A blob: the icosahedron of tw_shape_ellipsoid() pushed onto the lumpy
 * ellipsoid centre + radius * lumps(d) * d (d = v / |v|; lumps NULL:
 * smooth) and cut flat at floor_y; every triangle faces away from centre.
 * 20 n^2 triangles. */
void tw_shape_blob(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                   uint32_t n, const struct tw_lumps *lumps, float floor_y);

#endif
