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

/* One indexed triangle mesh in glTF's frame (y up), metres. Borrowed by the
 * writer for the call. */
struct tw_tiles3d_mesh {
    const float *positions;     /* xyz per vertex */
    const float *normals;       /* xyz per vertex, unit length */
    const uint8_t *colors;      /* RGBA per vertex (linear, unorm8), or NULL: white */
    const uint32_t *indices;    /* three per triangle */
    uint32_t vertex_count;
    uint32_t triangle_count;
    double error;               /* metres: a simplified mesh's geometric error, written as
                                   asset.extras.geometricError when > 0 */
};

/* Writes mesh as the binary glTF file path: one node translated by
 * translation (metres, glTF's frame; the mesh's own positions stay as
 * given), one mesh of one primitive (POSITION with its min and max, NORMAL,
 * COLOR_0 when there are colours, uint32 indices), one white material.
 * Deterministic: the same mesh gives the same bytes. */
int tw_tiles3d_write_glb(const char *path, const struct tw_tiles3d_mesh *mesh,
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

/* The number of tiles of a quadtree's levels [0, levels): (4^levels - 1) / 3. */
uint64_t tw_tiles3d_tiles_below(uint32_t levels);
/* The Morton index of (x, y): x's bits in the even places, y's in the odd. */
uint64_t tw_tiles3d_morton(uint32_t x, uint32_t y);

/* Writes size bytes at data as path, whole or not at all (see above). */
int tw_tiles3d_write_file(const char *path, const void *data, size_t size, char *err,
                          size_t err_size);

/* Makes the folders of path (everything before its last '/'), as mkdir -p;
 * folders that exist already, or that another process makes meanwhile,
 * are fine. */
int tw_tiles3d_make_parents(const char *path, char *err, size_t err_size);

#endif
