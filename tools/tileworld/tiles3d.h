/*
 * The files of a 3D Tiles 1.1 tileset with implicit tiling (OGC 22-025r4)
 * that `tileworld bake` writes: binary glTF 2.0 content (.glb), subtree
 * files (.subtree) and tileset.json. Plain writers: they take arrays and
 * bits, and know nothing of tilesets or cells.
 *
 * Every file is written whole or not at all: under a temporary name of its
 * own in its folder (.NAME.tmp.PID, so that machines filling one shared
 * folder never write the same temporary), then renamed. Errors come back as
 * TW_ERR_* with one line "PATH: reason" in err.
 */
#ifndef TW_TOOLS_TILES3D_H
#define TW_TOOLS_TILES3D_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* One indexed triangle mesh in glTF's frame (y up), metres, mesh-local.
 * Borrowed by the writer for the call. */
struct tw_tiles3d_mesh {
    const float *positions;     /* xyz per vertex */
    const float *normals;       /* xyz per vertex, written as they are (see below) */
    const uint8_t *colors;      /* RGBA per vertex (unorm8, as stored), or NULL: white */
    const uint32_t *indices;    /* three per triangle, each < vertex_count */
    uint32_t vertex_count;      /* > 0 */
    uint32_t triangle_count;    /* > 0 */
};

/* One placement of a mesh with a material: a glTF node. */
struct tw_tiles3d_node {
    uint32_t mesh;              /* index into the scene's meshes */
    uint32_t material;          /* index into the scene's materials */
    float transform[12];        /* affine, row-major 3x4, mesh-local -> tile-local */
};

/* What one .glb holds: meshes shared by nodes (instancing kept), and the
 * materials' base colours. Borrowed by the writer for the call. */
struct tw_tiles3d_scene {
    const struct tw_tiles3d_mesh *meshes;
    uint32_t mesh_count;
    const float (*materials)[4]; /* base colour RGBA */
    uint32_t material_count;
    const struct tw_tiles3d_node *nodes;
    uint32_t node_count;        /* > 0 */
    double error;               /* metres: a simplified tile's geometric error, written as
                                   asset.extras.geometricError when > 0 */
};

/* Writes scene as the binary glTF file path, in the layout that the 3D
 * Tiles provider reads back exactly (tilesets/tiles3d-glb.c,
 * asset.extras.tileworld.layout "instances"): a root node translated by
 * translation (metres, glTF's frame) whose children are the scene's nodes
 * in order, each with its transform as a column-major matrix (omitted when
 * it is the identity) and a glTF mesh per distinct (mesh, material) pair of
 * one primitive, whose accessors are shared by the pairs of one mesh:
 * POSITION with its min and max, NORMAL, COLOR_0 (unsigned byte,
 * normalized) when the mesh has colours, uint32 indices; one
 * double-sided material per scene material (baseColorFactor, metallic 0,
 * roughness 1). Every float is written so that it reads back to the same
 * float. NORMAL must be of unit length for glTF: a mesh with a normal
 * that is not (a scaling transform baked into a merged mesh) gets NORMAL
 * normalised and the exact normals in _TW_NORMAL. Deterministic: the same
 * scene gives the same bytes. */
int tw_tiles3d_write_glb(const char *path, const struct tw_tiles3d_scene *scene,
                         const double translation[3], char *err, size_t err_size);

/* Reads back the geometric error that tw_tiles3d_write_glb() wrote into the
 * binary glTF file path: 0 when it has none. TW_ERR_IO or TW_ERR_FORMAT,
 * with the reason in err, for a file that cannot be read or is no GLB. */
int tw_tiles3d_read_glb_error(const char *path, double *error, char *err, size_t err_size);

/* A quadtree subtree's availability: bits in Morton order, level after
 * level (level l of the subtree starts at bit (4^l - 1) / 3), as the
 * 3D Tiles bitstreams lay them out. levels: the subtree's levels. */
struct tw_tiles3d_subtree {
    uint32_t levels;
    const uint8_t *tiles;       /* (4^levels - 1) / 3 bits */
    const uint8_t *content;     /* the same number of bits */
    const uint8_t *children;    /* 4^levels bits: child subtrees */
};

/* Writes s as the subtree file path (magic "subt", version 1, a JSON chunk
 * and a binary chunk of the bitstreams; an all-0 or all-1 bitstream is a
 * constant instead). */
int tw_tiles3d_write_subtree(const char *path, const struct tw_tiles3d_subtree *s,
                             char *err, size_t err_size);

/* tw_tiles3d_tiles_below() and tw_tiles3d_morton(), the implicit tiling's
 * indices, are the provider's (tilesets/tilesets-private.h). */

/* Writes text and a newline as path, whole or not at all (see above). */
int tw_tiles3d_write_text(const char *path, const char *text, char *err, size_t err_size);

/* A JSON array of the n numbers at v. */
struct json_object *tw_tiles3d_doubles(const double *v, int n);

/* Makes the folders of path (everything before its last '/'), as mkdir -p;
 * folders that exist already, or that another process makes meanwhile,
 * are fine. */
int tw_tiles3d_make_parents(const char *path, char *err, size_t err_size);

#endif
