/*
 * The C face of the tinygltf shim, private to tilesets/ (the importer,
 * gltf-*.c, is its only user). tinygltf parses a glTF 2.0 document; the shim hands back its raw
 * content as plain C data and nothing else: it validates nothing beyond what
 * tinygltf itself refuses, so that every check lives in C (gltf-*.c).
 *
 * Every C++ exception (std::bad_alloc included) is caught inside the shim and
 * becomes an error code; nothing throws across this header. No global state:
 * two loads may run in two threads at once.
 */
#ifndef TW_TILESETS_GLTF_SHIM_H
#define TW_TILESETS_GLTF_SHIM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tilesets/gltf-scan.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Indices into the document's arrays are int32_t; -1 means absent (tinygltf
 * does not tell an explicit -1 from a missing property). Any other value may
 * be out of range: the reader checks. Counts of values given in the file for
 * fixed-size properties (matrix, translation, ...) are kept so that a
 * malformed length can be refused; only the first values are copied. */

struct tw_gltf_doc_node {
    int32_t mesh;
    const int *children;            /* child_count entries */
    uint32_t child_count;
    const double *matrix;           /* column-major, as in glTF; matrix_count values */
    uint32_t matrix_count;          /* values given; 0: absent */
    uint32_t translation_count;
    const double *translation;
    const double *rotation;         /* quaternion x, y, z, w */
    uint32_t rotation_count;
    uint32_t scale_count;
    const double *scale;
};

struct tw_gltf_doc_attribute {
    const char *name;               /* "POSITION", "NORMAL", "TEXCOORD_0", ... */
    int32_t accessor;
};

struct tw_gltf_doc_primitive {
    int32_t mode;                   /* glTF mode: 0 points ... 6 triangle fan */
    int32_t indices;                /* accessor, or -1: not indexed */
    int32_t material;
    const struct tw_gltf_doc_attribute *attributes;
    uint32_t attribute_count;
    uint32_t target_count;          /* morph targets (ignored) */
};

struct tw_gltf_doc_mesh {
    const struct tw_gltf_doc_primitive *primitives;
    uint32_t primitive_count;
};

struct tw_gltf_doc_accessor {
    int32_t buffer_view;            /* -1: all zeros (or only sparse values) */
    uint64_t byte_offset;
    int32_t component_type;         /* 5120 ... 5126 (GL enums) */
    int32_t type;                   /* tinygltf's TINYGLTF_TYPE_*: 2, 3, 4, 34, 35, 36, 65 */
    uint64_t count;
    bool normalized;
    bool sparse;
    int32_t sparse_count;
    int32_t sparse_indices_view;
    int32_t sparse_indices_offset;
    int32_t sparse_indices_component_type;
    int32_t sparse_values_view;
    int32_t sparse_values_offset;
};

struct tw_gltf_doc_buffer_view {
    int32_t buffer;
    uint64_t byte_offset;
    uint64_t byte_length;
    uint64_t byte_stride;           /* 0: tightly packed */
};

struct tw_gltf_doc_buffer {
    const uint8_t *data;            /* size bytes, owned by the document */
    uint64_t size;
};

struct tw_gltf_doc_material {
    double base_color[4];
    uint32_t base_color_count;      /* values given (4 when defaulted) */
    int32_t base_color_texture;     /* pbrMetallicRoughness.baseColorTexture.index, or -1 */
    int32_t base_color_texcoord;    /* its texCoord: n of TEXCOORD_n */
    /* The texture's KHR_texture_transform, if any (identity otherwise):
     * uv' = T(offset) R(rotation) S(scale) uv; texcoord >= 0 overrides the
     * texCoord above. Values as given (not checked). */
    bool has_uv_transform;
    double uv_offset[2];
    double uv_rotation;
    double uv_scale[2];
    int32_t uv_texcoord;
};

struct tw_gltf_doc_texture {
    int32_t sampler;                /* or -1 */
    int32_t source;                 /* an image, or -1 */
};

struct tw_gltf_doc_sampler {
    int32_t wrap_s;                 /* GL enums; 10497 (REPEAT) when absent */
    int32_t wrap_t;
};

/* An image: at most one of uri, buffer_view and data is given. */
struct tw_gltf_doc_image {
    const char *uri;                /* an external file as written (not URL-decoded), or NULL */
    int32_t buffer_view;            /* or -1 */
    const char *mime_type;          /* "" when absent */
    const uint8_t *data;            /* the bytes of a data: URI (size bytes), or NULL */
    uint64_t size;
};

struct tw_gltf_doc_scene {
    const int *nodes;
    uint32_t node_count;
};

/* A parsed document. Every pointer points into memory that the shim owns
 * until tw_gltf_shim_free(). */
struct tw_gltf_doc {
    const char *version;            /* asset.version */
    const char *min_version;        /* asset.minVersion, "" when absent */
    int32_t default_scene;          /* "scene", or -1 */
    const char *const *extensions_required;
    uint32_t extensions_required_count;
    const struct tw_gltf_doc_node *nodes;
    uint32_t node_count;
    const struct tw_gltf_doc_mesh *meshes;
    uint32_t mesh_count;
    const struct tw_gltf_doc_accessor *accessors;
    uint32_t accessor_count;
    const struct tw_gltf_doc_buffer_view *buffer_views;
    uint32_t buffer_view_count;
    const struct tw_gltf_doc_buffer *buffers;
    uint32_t buffer_count;
    const struct tw_gltf_doc_material *materials;
    uint32_t material_count;
    const struct tw_gltf_doc_scene *scenes;
    uint32_t scene_count;
    const struct tw_gltf_doc_texture *textures;
    uint32_t texture_count;
    const struct tw_gltf_doc_sampler *samplers;
    uint32_t sampler_count;
    const struct tw_gltf_doc_image *images;
    uint32_t image_count;
    void *internal;                 /* the shim's */
};

/* How the shim reads a buffer's external file. read is called with the
 * URL-decoded uri exactly as the document gives it (never joined to a
 * folder: resolving and confining it is the callee's job) and returns 0 with
 * a malloc()ed block that the shim frees, or a negative tw_error. NULL read:
 * external files are refused. */
struct tw_gltf_shim_io {
    int (*read)(void *user, const char *uri, uint8_t **data, size_t *size);
    void *user;
};

/* Parses a .gltf (JSON) or .glb (binary, told by its magic) document held in
 * data[0, size). data is only read during the call. Images are neither read
 * nor decoded: external ones keep their uri, data: URIs their bytes, and
 * bufferView ones their view (unchecked). reserve (NULL: none) gives the
 * element count of each top-level array (gltf-scan.h), so that tinygltf's
 * arrays are allocated once at their size instead of grown (a grown array
 * briefly holds its old and new copies). On success returns 0 and fills
 * *out, which the caller frees with tw_gltf_shim_free(). On failure returns
 * a negative tw_error, leaves *out zeroed and writes tinygltf's reason (one
 * line) to msg. */
int tw_gltf_shim_load(const uint8_t *data, size_t size, const struct tw_gltf_shim_io *io,
                      const uint64_t reserve[TW_GLTF_KIND_COUNT], struct tw_gltf_doc *out,
                      char *msg, size_t msg_size);

/* Bytes that tinygltf and the shim hold for each element of a top-level
 * array of this kind, before any string or array inside it (for budgets). */
uint64_t tw_gltf_shim_element_bytes(enum tw_gltf_kind kind);

/* Frees a document filled by tw_gltf_shim_load(); accepts a zeroed one. */
void tw_gltf_shim_free(struct tw_gltf_doc *doc);

#ifdef __cplusplus
}
#endif

#endif
