/*
 * gltf-private.h: the glTF importer's insides, shared by its files; private
 * to tilesets/. tinygltf parses (gltf-shim.cpp); these files check everything
 * themselves and convert:
 *   gltf-import.c     the entry points (tilesets.h), the import context and
 *                     its messages, the document's version, required
 *                     extensions and memory estimate; bind and place
 *   gltf-io.c         the file and its external buffers, the GLB container,
 *                     images
 *   gltf-accessors.c  buffer views and accessors: checks and reads
 *   gltf-meshes.c     mesh primitives: checks and conversion to triangles
 *   gltf-colours.c    base colour textures and vertex colours: primitives
 *                     split by colour into baked materials
 *   gltf-nodes.c      the node hierarchy, its transforms, and the scene built
 *                     by walking it
 * An import is one struct tw_gltf_importer, used by one thread. The first
 * problem found ends the import: tw_gltf_fail() keeps its message.
 */
#ifndef TW_TILESETS_GLTF_PRIVATE_H
#define TW_TILESETS_GLTF_PRIVATE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tilesets/gltf-scan.h"
#include "tilesets/gltf-shim.h"
#include "tilesets/tilesets-private.h"
#include "tileworld/tilesets.h"

/* Memory is bounded by the size of the document: what tinygltf, the shim and
 * the importer will hold for the document's JSON (estimated from the scan,
 * before anything is parsed) may not exceed TW_GLTF_MEMORY_BASE +
 * TW_GLTF_MEMORY_PER_BYTE bytes per byte of JSON text, nor TW_GLTF_MEMORY_MAX;
 * converting its meshes, as much per byte of file and buffers. Real documents
 * need a few bytes per byte (their bulk is binary); a file of empty objects
 * would need hundreds. Buffers and images are bounded by max_file_bytes on
 * their own. */
#define TW_GLTF_MEMORY_BASE (64ull << 20)
#define TW_GLTF_MEMORY_PER_BYTE 32ull
#define TW_GLTF_MEMORY_MAX (2ull << 30)

/* Accessor component types (glTF 2.0 §3.6.2.2). */
enum {
    TW_GLTF_COMP_BYTE = 5120,
    TW_GLTF_COMP_UNSIGNED_BYTE = 5121,
    TW_GLTF_COMP_SHORT = 5122,
    TW_GLTF_COMP_UNSIGNED_SHORT = 5123,
    TW_GLTF_COMP_UNSIGNED_INT = 5125,
    TW_GLTF_COMP_FLOAT = 5126,
};

/* tinygltf's TINYGLTF_TYPE_* codes. */
enum {
    TW_GLTF_TYPE_VEC2 = 2,
    TW_GLTF_TYPE_VEC3 = 3,
    TW_GLTF_TYPE_VEC4 = 4,
    TW_GLTF_TYPE_MAT2 = 32 + 2,
    TW_GLTF_TYPE_MAT3 = 32 + 3,
    TW_GLTF_TYPE_MAT4 = 32 + 4,
    TW_GLTF_TYPE_SCALAR = 64 + 1,
};

/* One import: its input, limits, error and what its checks learnt. */
struct tw_gltf_importer {
    const char *name;                 /* for messages */
    char shown[256];                  /* name, escaped (tiles.h tw_log_escape()) */
    int dir_fd;                       /* folder of external files; -1: none allowed */
    struct tw_gltf_settings settings;
    uint64_t bytes_read;              /* the file and its external buffers */
    const struct tw_gltf_doc *doc;
    const struct tw_gltf_scan *scan;  /* the JSON's first pass: raw buffer URIs */
    uint8_t *uri_used;                /* per scan buffer URI: handed to tinygltf already */
    char msg[1024];                   /* the first error, "<element>: <reason>" */
    int io_error;                     /* set by the external-file reader */
    char io_msg[800];
    const struct tw_log *log;         /* for warnings */
    struct tw_gltf_shared *shared;    /* bytes read and decoded with other imports */
    bool own_shared;                  /* shared is own */
    struct tw_gltf_shared own;
    struct tw_gltf_image_cache *images; /* images in the document, by source */
    struct tw_gltf_decoded_image **image_of; /* per document image, once resolved */
    struct tw_gltf_material_texture *material_textures; /* per document material */
    uint32_t texture_warnings;        /* shown, then only counted */
    struct tw_gltf_accessor_facts *facts; /* per accessor, what its checks found */
    uint64_t checked_bytes;           /* of accessor data read by the checks */
    uint32_t skipped_primitives;      /* points and lines, not drawn */
    char skipped_first[160];          /* the first of them, for the warning */
};

/* What the data checks learnt of an accessor: each is read once per import
 * however many primitives use it. */
enum {
    TW_GLTF_FACT_POSITIONS_OK = 1,    /* finite and within bounds */
    TW_GLTF_FACT_INDICES_READ = 2,    /* index_max and TW_GLTF_FACT_RESTART known */
    TW_GLTF_FACT_RESTART = 4,         /* holds its type's largest value */
};

struct tw_gltf_accessor_facts {
    uint8_t flags;
    uint32_t index_max;
};

/* Where an image's bytes come from, which makes two images one: a file (by
 * its identity, however it is named; shared between the imports of a
 * manifest), a byte range of a buffer, or the bytes of a data: URI (by
 * content). */
enum tw_gltf_image_source {
    TW_GLTF_SOURCE_FILE = 1,
    TW_GLTF_SOURCE_VIEW,
    TW_GLTF_SOURCE_DATA,
};

/* An image, by source, and its RGBA pixels once decoded. */
struct tw_gltf_decoded_image {
    enum tw_gltf_image_source source;
    uint64_t key[3];                  /* FILE: device, inode; VIEW: buffer, offset, length;
                                         DATA: hash, size */
    const uint8_t *bytes;             /* DATA: the document's, to compare */
    uint64_t hash;
    int state;                        /* 1 decoded, -1 unusable (warned once) */
    uint32_t width, height;
    uint8_t *rgba;
};

/* A material's usable baseColorTexture, resolved once per import. */
struct tw_gltf_material_texture {
    int state;                        /* 0 not resolved, 1 textured, -1 none */
    const struct tw_gltf_decoded_image *image;
    int32_t wrap_s, wrap_t;
    uint32_t texcoord;
    /* KHR_texture_transform (how quantised texture coordinates are
     * dequantised): uv' = offset + [[a, b], [c, d]] uv. */
    bool transformed;
    double offset[2], a, b, c, d;
};

/* Materials made of baked colours, shared by every primitive of the scene:
 * an open-addressing table from RGBA8 to material index. */
struct tw_gltf_palette {
    uint32_t *keys;
    uint32_t *materials;              /* UINT32_MAX: empty slot */
    uint32_t size;                    /* a power of two */
    uint32_t count;
    uint32_t material_capacity;       /* of sc->materials */
    uint32_t primitive_capacity;      /* of sc->primitives */
};

/* The little-endian uint32_t at p (GLB headers, accessor data). */
static inline uint32_t tw_gltf_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* ---- gltf-import.c ---- */

/* Records "<element>: <reason>" as the import's error, unless one is
 * recorded already; returns err. */
int tw_gltf_fail(struct tw_gltf_importer *im, int err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Logs a warning about a texture or colour; past a few per import they are
 * only counted. */
void tw_gltf_warn_texture(struct tw_gltf_importer *im, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* n bytes as "4.3 GiB", "17 MiB", "300 KiB" or "12 bytes", in out. */
const char *tw_gltf_byte_size(uint64_t n, char *out, size_t size);

/* ---- gltf-io.c ---- */

/* Reads the open file fd whole, within the import's byte budgets. */
int tw_gltf_read_fd(struct tw_gltf_importer *im, int fd, uint8_t **data, size_t *size, char *why,
                    size_t why_size);
/* The shim's reader of external buffers (struct tw_gltf_shim_io); user is
 * the importer. */
int tw_gltf_read_external(void *user, const char *uri, uint8_t **data, size_t *size);
/* The JSON text of a .gltf, or of a .glb after checking its container. */
int tw_gltf_find_json(struct tw_gltf_importer *im, const uint8_t *data, size_t *size,
                      const uint8_t **text, size_t *text_len);
/* Frees a cache of decoded images; accepts NULL. */
void tw_gltf_image_cache_destroy(struct tw_gltf_image_cache *c);
/* Document image index, decoded; NULL (warned) if unusable. */
const struct tw_gltf_decoded_image *tw_gltf_load_image(struct tw_gltf_importer *im,
                                                       uint32_t index);

/* ---- gltf-accessors.c ---- */

uint32_t tw_gltf_component_size(int32_t comp);
const char *tw_gltf_type_name(int32_t type);
const char *tw_gltf_component_name(int32_t comp);
int tw_gltf_check_buffer_views(struct tw_gltf_importer *im);
int tw_gltf_check_accessors(struct tw_gltf_importer *im);
/* Charges n more bytes of accessor data read by the checks to the budget. */
int tw_gltf_charge_check(struct tw_gltf_importer *im, int32_t acc, uint64_t n);
uint32_t tw_gltf_load_uint(const uint8_t *p, int32_t comp);
float tw_gltf_load_float(const uint8_t *p);
/* Start and stride of a checked accessor's data; NULL: no buffer view. */
const uint8_t *tw_gltf_accessor_base(const struct tw_gltf_doc *d,
                                     const struct tw_gltf_doc_accessor *a, uint64_t *stride);
/* The data at byte offset of buffer view view (both checked). */
const uint8_t *tw_gltf_view_data(const struct tw_gltf_doc *d, int32_t view, int32_t offset);
/* A checked accessor's elements, sparse substitutes applied: n components
 * each as floats, or unsigned integers. */
int tw_gltf_read_floats(struct tw_gltf_importer *im, uint32_t index, uint32_t n, float *out);
int tw_gltf_read_uints(struct tw_gltf_importer *im, uint32_t index, uint32_t *out);

/* ---- gltf-meshes.c ---- */

/* The accessor of primitive p's attribute name, or -1. */
int32_t tw_gltf_find_attribute(const struct tw_gltf_doc_primitive *p, const char *name);
/* Whether p's mode is triangles, a triangle strip or a fan. */
bool tw_gltf_draws_triangles(const struct tw_gltf_doc_primitive *p);
/* Whether comp is an 8- or 16-bit integer type. */
bool tw_gltf_is_integer(int32_t comp);
int tw_gltf_check_meshes(struct tw_gltf_importer *im);
/* Checks the data of every triangle primitive, without allocating. */
int tw_gltf_check_mesh_data(struct tw_gltf_importer *im);
/* Triangles of primitive k of mesh m (checked), from its counts alone. */
int tw_gltf_primitive_triangles(struct tw_gltf_importer *im, uint32_t m, uint32_t k,
                                uint64_t *tris);
/* Primitive k of mesh m as a triangle list in out (zeroed); grey is the
 * material of a primitive without one. */
int tw_gltf_convert_primitive(struct tw_gltf_importer *im, uint32_t m, uint32_t k, uint32_t grey,
                              struct tw_gltf_primitive *out);

/* ---- gltf-colours.c ---- */

void tw_gltf_palette_finish(struct tw_gltf_palette *pal);
/* Appends converted primitive k of mesh m to sc as part of gm, split by
 * colour when it has a usable base colour texture or COLOR_0; takes prim's
 * arrays. */
int tw_gltf_add_primitive(struct tw_gltf_importer *im, uint32_t m, uint32_t k,
                          struct tw_gltf_palette *pal, struct tw_gltf_scene *sc,
                          struct tw_gltf_mesh *gm, struct tw_gltf_primitive *prim);

/* ---- gltf-nodes.c ---- */

bool tw_gltf_all_finite(const double *v, uint32_t n);
/* Checks the nodes; parent (node_count entries) gets each node's parent, -1
 * for a root. */
int tw_gltf_check_nodes(struct tw_gltf_importer *im, int32_t *parent);
/* out = a b, row-major affine 3x4 transforms. */
void tw_gltf_compose(const double a[12], const double b[12], double out[12]);
/* Builds sc from the checked document; parent from tw_gltf_check_nodes(). */
int tw_gltf_build_scene(struct tw_gltf_importer *im, const int32_t *parent,
                        struct tw_gltf_scene *sc);

#endif
