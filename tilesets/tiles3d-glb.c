/* The binary glTF layout of `tileworld bake` read back into a tileset
 * (tilesets-private.h): meshes, materials and nodes map one to one to
 * tw_tileset_add_mesh, _add_material and _add_instance, vertex colours to
 * tw_mesh.colors, every float as written. The general glTF importer
 * (gltf-*.c) would split vertex colours into one mesh per colour and
 * compose node transforms; this reader gives the tile that was baked. */
#include <json-c/json.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/gltf-private.h"
#include "tilesets/tilesets-private.h"
#include "tileworld/tiles.h"

struct reader {
    json_object *doc, *accessors, *views;
    const uint8_t *bin;
    uint64_t bin_size;
    /* Bytes copied out of accessors so far: at most bin_size, as the bake
     * reads back (its accessors never overlap), so that a file of many
     * accessors over one buffer view cannot copy its binary chunk many
     * times over. */
    uint64_t copied;
    char *why;
    size_t why_size;
};

static int fail(struct reader *r, int err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

static int fail(struct reader *r, int err, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->why, r->why_size, fmt, ap);
    va_end(ap);
    return err;
}

static json_object *get(json_object *o, const char *key)
{
    json_object *v = NULL;
    return o && json_object_is_type(o, json_type_object) && json_object_object_get_ex(o, key, &v)
               ? v
               : NULL;
}

/* The length of an array, 0 for anything else. */
static size_t length(json_object *a)
{
    return a && json_object_is_type(a, json_type_array) ? json_object_array_length(a) : 0;
}

/* Element k of an array, or NULL (not an array, k out of range). */
static json_object *at(json_object *a, int64_t k)
{
    return k >= 0 && (uint64_t)k < length(a) ? json_object_array_get_idx(a, (size_t)k) : NULL;
}

/* A non-negative integer, or -1 for anything else (a double, a NaN among
 * them, is not converted). */
static int64_t index_value(json_object *v)
{
    if (!v || !json_object_is_type(v, json_type_int))
        return -1;
    const int64_t n = json_object_get_int64(v);
    return n >= 0 ? n : -1;
}

/* A non-negative integer member, or -1 when absent or not one. */
static int64_t get_index(json_object *o, const char *key)
{
    return index_value(get(o, key));
}

/* Copies accessor a (components of comp, count elements of n components)
 * into out (count * n * size bytes, malloc'd); *count its count. */
static int read_accessor(struct reader *r, int64_t a, int comp, int n, bool normalized,
                         uint32_t *count, void **out)
{
    *out = NULL;
    static const char *const types[] = {NULL, "SCALAR", NULL, "VEC3", "VEC4"};
    const size_t size = tw_gltf_component_size(comp);
    json_object *acc = at(r->accessors, a);
    json_object *type = get(acc, "type"), *norm = get(acc, "normalized");
    const int64_t view_index = get_index(acc, "bufferView"), c = get_index(acc, "count");
    if (!acc || get_index(acc, "componentType") != comp || !type ||
        strcmp(json_object_get_string(type), types[n]) != 0 ||
        (norm ? json_object_get_boolean(norm) : false) != normalized || c <= 0 ||
        c > UINT32_MAX || get(acc, "sparse"))
        return fail(r, TW_ERR_FORMAT, "accessors[%lld] is not what tileworld bake writes there",
                    (long long)a);
    json_object *view = at(r->views, view_index);
    const int64_t view_offset = get(view, "byteOffset") ? get_index(view, "byteOffset") : 0;
    const int64_t view_length = get_index(view, "byteLength");
    const int64_t offset = get(acc, "byteOffset") ? get_index(acc, "byteOffset") : 0;
    const uint64_t elem = size * (uint64_t)n;
    const int64_t stride = get(view, "byteStride") ? get_index(view, "byteStride") : (int64_t)elem;
    if (!view || get_index(view, "buffer") != 0 || view_offset < 0 || view_length < 0 ||
        offset < 0 || stride < (int64_t)elem || stride > 252 ||
        (uint64_t)view_offset > r->bin_size || (uint64_t)view_length > r->bin_size - view_offset ||
        (uint64_t)offset > (uint64_t)view_length ||
        (uint64_t)(c - 1) * stride + elem > (uint64_t)view_length - offset)
        return fail(r, TW_ERR_FORMAT, "accessors[%lld] lies outside its buffer", (long long)a);
    if ((uint64_t)c * elem > r->bin_size - r->copied)
        return fail(r, TW_ERR_FORMAT, "accessors[%lld] reads more than the binary chunk holds "
                    "(the accessors overlap)", (long long)a);
    r->copied += (uint64_t)c * elem;
    uint8_t *data = malloc((size_t)(c * elem));
    if (!data)
        return fail(r, TW_ERR_NOMEM, "out of memory");
    const uint8_t *src = r->bin + view_offset + offset;
    for (int64_t e = 0; e < c; e++)
        memcpy(data + e * elem, src + e * stride, elem);
    *count = (uint32_t)c;
    *out = data;
    return TW_OK;
}

/* Adds the tileset mesh of glTF mesh g's primitive: *mesh its index. */
static int add_mesh(struct reader *r, struct tw_tileset *ts, json_object *prim, int *mesh)
{
    json_object *attributes = get(prim, "attributes");
    const int64_t exact = get_index(attributes, "_TW_NORMAL");
    const int64_t normal = exact >= 0 ? exact : get_index(attributes, "NORMAL");
    const int64_t colour = get_index(attributes, "COLOR_0");
    float *pos = NULL, *nrm = NULL;
    uint32_t *idx = NULL;
    uint8_t *rgba = NULL;
    uint32_t nv = 0, nn = 0, nc = 0, ni = 0;
    int rc = read_accessor(r, get_index(attributes, "POSITION"), TW_GLTF_COMP_FLOAT, 3, false,
                           &nv, (void **)&pos);
    if (!rc)
        rc = read_accessor(r, normal, TW_GLTF_COMP_FLOAT, 3, false, &nn, (void **)&nrm);
    if (!rc && colour >= 0)
        rc = read_accessor(r, colour, TW_GLTF_COMP_UNSIGNED_BYTE, 4, true, &nc, (void **)&rgba);
    if (!rc)
        rc = read_accessor(r, get_index(prim, "indices"), TW_GLTF_COMP_UNSIGNED_INT, 1, false,
                           &ni, (void **)&idx);
    if (!rc && (nn != nv || (rgba && nc != nv) || ni % 3 != 0))
        rc = fail(r, TW_ERR_FORMAT, "a mesh's accessors do not agree in count");
    if (!rc) {
        *mesh = tw_tileset_add_mesh(ts, pos, nrm, nv, idx, ni / 3);
        if (*mesh < 0)
            rc = fail(r, *mesh, "a mesh that cannot be a tile's (%s)", tw_error_to_str(*mesh));
    }
    if (!rc && rgba) {
        /* Owned by the tileset from here, as tw_tileset_finish()'s merged
         * meshes' colours are. */
        ts->meshes[*mesh].colors = rgba;
        rgba = NULL;
    }
    free(pos);
    free(nrm);
    free(idx);
    free(rgba);
    return rc;
}

static int read_document(struct reader *r, struct tw_tileset *ts, uint32_t proto,
                         const double *shift)
{
    json_object *materials = get(r->doc, "materials"), *meshes = get(r->doc, "meshes");
    json_object *nodes = get(r->doc, "nodes"), *scenes = get(r->doc, "scenes");
    const size_t material_count = length(materials), mesh_count = length(meshes);
    const size_t accessor_count = length(r->accessors);
    int *material_map = malloc(sizeof(int) * (material_count + 1));
    int *mesh_map = malloc(sizeof(int) * (mesh_count + 1));
    int64_t *by_position = malloc(sizeof(int64_t) * (accessor_count + 1));
    int rc = TW_OK;
    if (!material_map || !mesh_map || !by_position) {
        rc = fail(r, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    for (size_t k = 0; k < accessor_count; k++)
        by_position[k] = -1;
    for (size_t k = 0; k < material_count && !rc; k++) {
        json_object *factor = get(get(at(materials, (int64_t)k), "pbrMetallicRoughness"),
                                  "baseColorFactor");
        float rgba[4] = {1.0f, 1.0f, 1.0f, 1.0f};
        if (factor && length(factor) != 4) {
            rc = fail(r, TW_ERR_FORMAT, "materials[%zu].baseColorFactor is not 4 numbers", k);
            break;
        }
        for (size_t c = 0; factor && c < 4; c++)
            rgba[c] = (float)json_object_get_double(at(factor, (int64_t)c));
        material_map[k] = tw_tileset_add_material(ts, rgba);
        if (material_map[k] < 0)
            rc = fail(r, material_map[k], "materials[%zu] cannot be a tile's (%s)", k,
                      tw_error_to_str(material_map[k]));
    }
    /* One tileset mesh per POSITION accessor, in the order of the glTF
     * meshes (the writer's order of the tile's meshes). */
    for (size_t k = 0; k < mesh_count && !rc; k++) {
        json_object *prims = get(at(meshes, (int64_t)k), "primitives");
        json_object *prim = length(prims) == 1 ? at(prims, 0) : NULL;
        const int64_t position = get_index(get(prim, "attributes"), "POSITION");
        const int64_t material = get_index(prim, "material");
        const int64_t mode = get(prim, "mode") ? get_index(prim, "mode") : 4;
        if (!prim || position < 0 || (size_t)position >= accessor_count || material < 0 ||
            (size_t)material >= material_count || mode != 4) {
            rc = fail(r, TW_ERR_FORMAT, "meshes[%zu] is not one primitive of triangles with a "
                      "position and a material", k);
            break;
        }
        if (by_position[position] < 0) {
            int mesh = -1;
            rc = add_mesh(r, ts, prim, &mesh);
            by_position[position] = mesh;
        }
        mesh_map[k] = (int)by_position[position];
    }
    json_object *scene = at(scenes, get(r->doc, "scene") ? get_index(r->doc, "scene") : 0);
    json_object *roots = get(scene, "nodes");
    if (rc)
        goto out;
    const int64_t root_index = length(roots) == 1 ? index_value(at(roots, 0)) : -1;
    json_object *root = at(nodes, root_index);
    json_object *children = get(root, "children"), *translation = get(root, "translation");
    double offset[3] = {0.0, 0.0, 0.0};
    if (!root || !children || !json_object_is_type(children, json_type_array) ||
        (translation && length(translation) != 3)) {
        rc = fail(r, TW_ERR_FORMAT, "the scene is not one root node with children");
        goto out;
    }
    for (int a = 0; a < 3 && shift; a++)
        offset[a] = shift[a] + (translation ? json_object_get_double(at(translation, a)) : 0.0);
    for (size_t k = 0; k < length(children) && !rc; k++) {
        const int64_t c = index_value(at(children, (int64_t)k));
        json_object *node = c != root_index ? at(nodes, c) : NULL;
        const int64_t g = get_index(node, "mesh");
        json_object *matrix = get(node, "matrix");
        if (!node || g < 0 || (size_t)g >= mesh_count || get(node, "children") ||
            get(node, "translation") || get(node, "rotation") || get(node, "scale") ||
            (matrix && length(matrix) != 16)) {
            rc = fail(r, TW_ERR_FORMAT, "nodes[%lld] is not a mesh placed by a matrix",
                      (long long)c);
            break;
        }
        float t[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
        for (int col = 0; matrix && col < 4; col++)
            for (int row = 0; row < 3; row++)
                t[4 * row + col] = (float)json_object_get_double(at(matrix, 4 * col + row));
        for (int a = 0; a < 3 && shift; a++)
            t[4 * a + 3] = (float)((double)t[4 * a + 3] + offset[a]);
        json_object *prim = at(get(at(meshes, g), "primitives"), 0);
        const int64_t material = get_index(prim, "material");
        const int in = tw_tileset_add_instance(ts, proto, (uint32_t)mesh_map[g],
                                               (uint32_t)material_map[material], t);
        if (in < 0)
            rc = fail(r, in, "nodes[%lld] cannot be placed in a tile (%s)", (long long)c,
                      tw_error_to_str(in));
    }
out:
    free(material_map);
    free(mesh_map);
    free(by_position);
    return rc;
}

/* The JSON chunk of the binary glTF file at data into *doc, its length in
 * *json_len; why says what is wrong. */
static int parse_json(const uint8_t *d, size_t size, json_object **doc, uint64_t *json_len,
                      const char **why)
{
    *doc = NULL;
    if (size < 20 || memcmp(d, "glTF", 4) != 0 || tw_gltf_le32(d + 4) != 2 ||
        memcmp(d + 16, "JSON", 4) != 0) {
        *why = "not a binary glTF 2.0 file";
        return TW_ERR_FORMAT;
    }
    *json_len = tw_gltf_le32(d + 12);
    if (*json_len > size - 20 || *json_len > INT32_MAX) {
        *why = "its JSON chunk is longer than the file";
        return TW_ERR_FORMAT;
    }
    json_tokener *tok = json_tokener_new();
    if (!tok) {
        *why = "out of memory";
        return TW_ERR_NOMEM;
    }
    *doc = json_tokener_parse_ex(tok, (const char *)d + 20, (int)*json_len);
    json_tokener_free(tok);
    if (!*doc) {
        *why = "its JSON chunk does not parse";
        return TW_ERR_FORMAT;
    }
    return TW_OK;
}

static double error_of(json_object *doc)
{
    json_object *e = get(get(get(doc, "asset"), "extras"), "geometricError");
    return e ? json_object_get_double(e) : 0.0;
}

int tw_tiles3d_glb_error(const void *data, size_t size, double *error)
{
    json_object *doc;
    uint64_t json_len;
    const char *why;
    const int rc = parse_json(data, size, &doc, &json_len, &why);
    *error = rc ? 0.0 : error_of(doc);
    json_object_put(doc);
    return rc;
}

int tw_tiles3d_glb_read(const void *data, size_t size, struct tw_tileset *ts, uint32_t proto,
                        const double *shift, double *error, char *why, size_t why_size)
{
    struct reader r = {.why = why, .why_size = why_size};
    const uint8_t *d = data;
    why[0] = '\0';
    if (error)
        *error = 0.0;
    uint64_t json_len;
    const char *problem = NULL;
    int rc = parse_json(d, size, &r.doc, &json_len, &problem);
    if (rc)
        return fail(&r, rc, "%s", problem);
    json_object *layout = get(get(get(get(r.doc, "asset"), "extras"), "tileworld"), "layout");
    if (!layout || !json_object_is_type(layout, json_type_string) ||
        strcmp(json_object_get_string(layout), "instances") != 0) {
        rc = fail(&r, TW_ERR_FORMAT, "not a tile in tileworld bake's layout "
                  "(asset.extras.tileworld.layout \"instances\")");
        goto out;
    }
    if (error)
        *error = error_of(r.doc);
    const uint64_t bin_at = 20 + json_len;
    if (bin_at + 8 > size || memcmp(d + bin_at + 4, "BIN\0", 4) != 0 ||
        tw_gltf_le32(d + bin_at) > size - bin_at - 8) {
        rc = fail(&r, TW_ERR_FORMAT, "no binary chunk after the JSON");
        goto out;
    }
    r.bin = d + bin_at + 8;
    r.bin_size = tw_gltf_le32(d + bin_at);
    r.accessors = get(r.doc, "accessors");
    r.views = get(r.doc, "bufferViews");
    if (!r.accessors || !json_object_is_type(r.accessors, json_type_array) || !r.views ||
        !json_object_is_type(r.views, json_type_array)) {
        rc = fail(&r, TW_ERR_FORMAT, "no accessors or buffer views");
        goto out;
    }
    rc = read_document(&r, ts, proto, shift);
out:
    json_object_put(r.doc);
    return rc;
}
