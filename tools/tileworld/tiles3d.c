/* Binary glTF, subtree files and atomic writes for 3D Tiles (tiles3d.h). */
#include "tools/tileworld/tiles3d.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tileworld/tiles.h"
#include "tilesets/tilesets-private.h"
#include "tools/outfile.h"
#include "tools/tileworld/report.h"

/* glTF's numbers for what the writer uses. */
enum {
    GL_UNSIGNED_BYTE = 5121,
    GL_UNSIGNED_INT = 5125,
    GL_FLOAT = 5126,
    GL_ARRAY_BUFFER = 34962,
    GL_ELEMENT_ARRAY_BUFFER = 34963,
};

int tw_tiles3d_make_parents(const char *path, char *err, size_t err_size)
{
    char dir[4096];
    const char *slash = strrchr(path, '/');
    if (!slash || slash == path)
        return TW_OK;
    const int n = snprintf(dir, sizeof(dir), "%.*s", (int)(slash - path), path);
    const int e = n < 0 || (size_t)n >= sizeof(dir) ? ENAMETOOLONG : tw_report_make_dirs(dir);
    if (e) {
        snprintf(err, err_size, "%s: cannot make the folder: %s", dir, strerror(e));
        return TW_ERR_IO;
    }
    return TW_OK;
}

/* Writes the pieces as path through .NAME.tmp.PID and a rename. */
static int write_pieces(const char *path, const void *const *data, const size_t *size,
                        int count, char *err, size_t err_size)
{
    struct tw_outfile o;
    int rc = tw_outfile_open_unique(&o, path, err, err_size);
    for (int k = 0; k < count && !rc; k++)
        tw_outfile_write(&o, data[k], size[k]);
    return rc ? rc : tw_outfile_commit(&o, err, err_size);
}

int tw_tiles3d_write_text(const char *path, const char *text, char *err, size_t err_size)
{
    const void *pieces[2] = {text, "\n"};
    const size_t sizes[2] = {strlen(text), 1};
    return write_pieces(path, pieces, sizes, 2, err, err_size);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    for (int k = 0; k < 4; k++)
        p[k] = (uint8_t)(v >> (8 * k));
}

static void put_u64(uint8_t *p, uint64_t v)
{
    for (int k = 0; k < 8; k++)
        p[k] = (uint8_t)(v >> (8 * k));
}

json_object *tw_tiles3d_doubles(const double *v, int n)
{
    json_object *a = json_object_new_array();
    for (int k = 0; k < n; k++)
        json_object_array_add(a, json_object_new_double(v[k]));
    return a;
}

/* A view of buffer 0; target and stride are left out when 0. */
static json_object *buffer_view(uint64_t offset, uint64_t length, int stride, int target)
{
    json_object *v = json_object_new_object();
    json_object_object_add(v, "buffer", json_object_new_int(0));
    json_object_object_add(v, "byteOffset", json_object_new_int64((int64_t)offset));
    json_object_object_add(v, "byteLength", json_object_new_int64((int64_t)length));
    if (target)
        json_object_object_add(v, "target", json_object_new_int(target));
    if (stride)
        json_object_object_add(v, "byteStride", json_object_new_int(stride));
    return v;
}

/* An accessor; offset is left out when 0. */
static json_object *accessor(int view, uint64_t offset, int component, uint32_t count,
                             const char *type, bool normalized)
{
    json_object *a = json_object_new_object();
    json_object_object_add(a, "bufferView", json_object_new_int(view));
    json_object_object_add(a, "componentType", json_object_new_int(component));
    if (normalized)
        json_object_object_add(a, "normalized", json_object_new_boolean(1));
    json_object_object_add(a, "count", json_object_new_int64(count));
    json_object_object_add(a, "type", json_object_new_string(type));
    if (offset)
        json_object_object_add(a, "byteOffset", json_object_new_int64((int64_t)offset));
    return a;
}

/* A float as the shortest JSON number that reads back to the same float
 * (9 significant digits always do), a negative zero included. */
static json_object *float_number(float v)
{
    /* "-0" would read back as the integer 0. */
    if (v == 0.0f && signbit(v))
        return json_object_new_double_s(-0.0, "-0.0");
    char text[32];
    for (int digits = 6; digits <= 9; digits++) {
        snprintf(text, sizeof(text), "%.*g", digits, (double)v);
        if (strtof(text, NULL) == v && (float)strtod(text, NULL) == v)
            break;
    }
    return json_object_new_double_s((double)strtod(text, NULL), text);
}

static json_object *float_array(const float *v, int n)
{
    json_object *a = json_object_new_array();
    for (int k = 0; k < n; k++)
        json_object_array_add(a, float_number(v[k]));
    return a;
}

/* Whether every normal of m is of unit length as glTF wants it (well
 * within the Khronos validator's tolerance). */
static bool unit_normals(const struct tw_tiles3d_mesh *m)
{
    for (uint32_t v = 0; v < m->vertex_count; v++) {
        const float *n = m->normals + 3 * (size_t)v;
        const double l = (double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2];
        if (!(fabs(l - 1.0) <= 1e-3))
            return false;
    }
    return true;
}

/* Whether t is the identity, bit for bit (a -0 is written). */
static bool is_identity(const float t[12])
{
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    return memcmp(t, id, sizeof(id)) == 0;
}

/* One glTF mesh: a (mesh, material) pair. */
struct pair {
    uint32_t mesh, material;
};

static int compare_pairs(const void *a, const void *b)
{
    const struct pair *x = a, *y = b;
    if (x->mesh != y->mesh)
        return x->mesh < y->mesh ? -1 : 1;
    return (x->material > y->material) - (x->material < y->material);
}

/* Where one mesh's arrays lie in the binary chunk, and its accessors. */
struct mesh_layout {
    uint64_t pos, nrm, exact, col, idx;   /* byte offsets within their views */
    bool unit;                            /* NORMAL is exact */
    int32_t a_pos, a_nrm, a_exact, a_col, a_idx;
};

int tw_tiles3d_write_glb(const char *path, const struct tw_tiles3d_scene *sc,
                         const double translation[3], char *err, size_t err_size)
{
    const uint32_t nm = sc->mesh_count, nn = sc->node_count;
    struct mesh_layout *lay = calloc(nm ? nm : 1, sizeof(*lay));
    struct pair *pairs = malloc(sizeof(*pairs) * (nn ? nn : 1));
    uint8_t *head = NULL, *bin = NULL;
    json_object *root = NULL;
    int rc = TW_OK;
    if (!lay || !pairs) {
        rc = TW_ERR_NOMEM;
        goto nomem;
    }
    if (nn == 0) {
        snprintf(err, err_size, "%s: a tile of no node is not one to write", path);
        rc = TW_ERR_INVALID;
        goto out;
    }
    /* The binary chunk: every float array (stride 12), then the colours
     * (stride 4), then the indices. */
    uint64_t floats = 0, colours = 0, indices = 0;
    for (uint32_t k = 0; k < nm; k++) {
        const struct tw_tiles3d_mesh *m = &sc->meshes[k];
        struct mesh_layout *l = &lay[k];
        l->unit = unit_normals(m);
        l->pos = floats;
        floats += 12ull * m->vertex_count;
        l->nrm = floats;
        floats += 12ull * m->vertex_count;
        if (!l->unit) {
            l->exact = floats;
            floats += 12ull * m->vertex_count;
        }
        if (m->colors) {
            l->col = colours;
            colours += 4ull * m->vertex_count;
        }
        l->idx = indices;
        indices += 12ull * m->triangle_count;
    }
    const uint64_t bin_bytes = floats + colours + indices;
    if (bin_bytes > UINT32_MAX - (64u << 20)) {
        snprintf(err, err_size, "%s: %llu bytes of geometry are more than one glTF file can "
                 "hold", path, (unsigned long long)bin_bytes);
        rc = TW_ERR_LIMIT;
        goto out;
    }
    for (uint32_t k = 0; k < nn; k++)
        pairs[k] = (struct pair){sc->nodes[k].mesh, sc->nodes[k].material};
    qsort(pairs, nn, sizeof(*pairs), compare_pairs);
    uint32_t pair_count = 0;
    for (uint32_t k = 0; k < nn; k++)
        if (pair_count == 0 || compare_pairs(&pairs[pair_count - 1], &pairs[k]) != 0)
            pairs[pair_count++] = pairs[k];

    root = json_object_new_object();
    json_object *asset = json_object_new_object();
    json_object_object_add(asset, "version", json_object_new_string("2.0"));
    json_object_object_add(asset, "generator", json_object_new_string("tileworld bake"));
    json_object *extras = json_object_new_object();
    if (sc->error > 0.0)
        json_object_object_add(extras, "geometricError", json_object_new_double(sc->error));
    json_object *tw = json_object_new_object();
    json_object_object_add(tw, "layout", json_object_new_string("instances"));
    json_object_object_add(extras, "tileworld", tw);
    json_object_object_add(asset, "extras", extras);
    json_object_object_add(root, "asset", asset);
    json_object_object_add(root, "scene", json_object_new_int(0));
    json_object *scene = json_object_new_object();
    json_object *scene_nodes = json_object_new_array();
    json_object_array_add(scene_nodes, json_object_new_int(0));
    json_object_object_add(scene, "nodes", scene_nodes);
    json_object *scenes = json_object_new_array();
    json_object_array_add(scenes, scene);
    json_object_object_add(root, "scenes", scenes);

    json_object *nodes = json_object_new_array();
    json_object *top = json_object_new_object();
    if (translation[0] != 0.0 || translation[1] != 0.0 || translation[2] != 0.0)
        json_object_object_add(top, "translation", tw_tiles3d_doubles(translation, 3));
    json_object *children = json_object_new_array();
    for (uint32_t k = 0; k < nn; k++)
        json_object_array_add(children, json_object_new_int64((int64_t)k + 1));
    json_object_object_add(top, "children", children);
    json_object_array_add(nodes, top);
    for (uint32_t k = 0; k < nn; k++) {
        const struct tw_tiles3d_node *n = &sc->nodes[k];
        const struct pair key = {n->mesh, n->material};
        const struct pair *found = bsearch(&key, pairs, pair_count, sizeof(*pairs),
                                           compare_pairs);
        json_object *node = json_object_new_object();
        json_object_object_add(node, "mesh", json_object_new_int64(found - pairs));
        if (!is_identity(n->transform)) {
            const float *t = n->transform;
            const float m[16] = {t[0], t[4], t[8], 0, t[1], t[5], t[9], 0,
                                 t[2], t[6], t[10], 0, t[3], t[7], t[11], 1};
            json_object_object_add(node, "matrix", float_array(m, 16));
        }
        json_object_array_add(nodes, node);
    }
    json_object_object_add(root, "nodes", nodes);

    /* Views: 0 the floats, 1 the indices, 2 the colours (if any). */
    json_object *views = json_object_new_array();
    json_object_array_add(views, buffer_view(0, floats, 12, GL_ARRAY_BUFFER));
    json_object_array_add(views, buffer_view(floats + colours, indices, 0,
                                              GL_ELEMENT_ARRAY_BUFFER));
    if (colours)
        json_object_array_add(views, buffer_view(floats, colours, 4, GL_ARRAY_BUFFER));
    json_object_object_add(root, "bufferViews", views);
    json_object *accessors = json_object_new_array();
    int32_t next = 0;
    for (uint32_t k = 0; k < nm; k++) {
        const struct tw_tiles3d_mesh *m = &sc->meshes[k];
        struct mesh_layout *l = &lay[k];
        float lo[3], hi[3];
        for (int a = 0; a < 3; a++)
            lo[a] = hi[a] = m->positions[a];
        for (uint32_t v = 0; v < m->vertex_count; v++)
            for (int a = 0; a < 3; a++) {
                const float x = m->positions[3 * (size_t)v + a];
                lo[a] = x < lo[a] ? x : lo[a];
                hi[a] = x > hi[a] ? x : hi[a];
            }
        json_object *position = accessor(0, l->pos, GL_FLOAT, m->vertex_count, "VEC3", false);
        json_object_object_add(position, "min", float_array(lo, 3));
        json_object_object_add(position, "max", float_array(hi, 3));
        json_object_array_add(accessors, position);
        l->a_pos = next++;
        json_object_array_add(accessors, accessor(0, l->nrm, GL_FLOAT, m->vertex_count,
                                                     "VEC3", false));
        l->a_nrm = next++;
        l->a_exact = -1;
        if (!l->unit) {
            json_object_array_add(accessors, accessor(0, l->exact, GL_FLOAT, m->vertex_count,
                                                         "VEC3", false));
            l->a_exact = next++;
        }
        l->a_col = -1;
        if (m->colors) {
            json_object_array_add(accessors, accessor(2, l->col, GL_UNSIGNED_BYTE,
                                                         m->vertex_count, "VEC4", true));
            l->a_col = next++;
        }
        json_object_array_add(accessors, accessor(1, l->idx, GL_UNSIGNED_INT,
                                                     3 * m->triangle_count, "SCALAR", false));
        l->a_idx = next++;
    }
    json_object_object_add(root, "accessors", accessors);

    json_object *meshes = json_object_new_array();
    for (uint32_t k = 0; k < pair_count; k++) {
        const struct mesh_layout *l = &lay[pairs[k].mesh];
        json_object *attributes = json_object_new_object();
        json_object_object_add(attributes, "POSITION", json_object_new_int(l->a_pos));
        json_object_object_add(attributes, "NORMAL", json_object_new_int(l->a_nrm));
        if (l->a_exact >= 0)
            json_object_object_add(attributes, "_TW_NORMAL", json_object_new_int(l->a_exact));
        if (l->a_col >= 0)
            json_object_object_add(attributes, "COLOR_0", json_object_new_int(l->a_col));
        json_object *primitive = json_object_new_object();
        json_object_object_add(primitive, "attributes", attributes);
        json_object_object_add(primitive, "indices", json_object_new_int(l->a_idx));
        json_object_object_add(primitive, "material", json_object_new_int64(pairs[k].material));
        json_object_object_add(primitive, "mode", json_object_new_int(4));
        json_object *primitives = json_object_new_array();
        json_object_array_add(primitives, primitive);
        json_object *mesh = json_object_new_object();
        json_object_object_add(mesh, "primitives", primitives);
        json_object_array_add(meshes, mesh);
    }
    json_object_object_add(root, "meshes", meshes);

    /* Instances may mirror meshes: both faces are drawn. */
    json_object *materials = json_object_new_array();
    for (uint32_t k = 0; k < sc->material_count; k++) {
        json_object *pbr = json_object_new_object();
        json_object_object_add(pbr, "baseColorFactor", float_array(sc->materials[k], 4));
        json_object_object_add(pbr, "metallicFactor", json_object_new_double(0.0));
        json_object_object_add(pbr, "roughnessFactor", json_object_new_double(1.0));
        json_object *material = json_object_new_object();
        json_object_object_add(material, "pbrMetallicRoughness", pbr);
        json_object_object_add(material, "doubleSided", json_object_new_boolean(1));
        json_object_array_add(materials, material);
    }
    json_object_object_add(root, "materials", materials);
    json_object *buffer = json_object_new_object();
    json_object_object_add(buffer, "byteLength", json_object_new_int64((int64_t)bin_bytes));
    json_object *buffers = json_object_new_array();
    json_object_array_add(buffers, buffer);
    json_object_object_add(root, "buffers", buffers);

    const char *json = json_object_to_json_string_ext(root, JSON_C_TO_STRING_PLAIN |
                                                                JSON_C_TO_STRING_NOSLASHESCAPE);
    const size_t json_len = strlen(json), json_padded = (json_len + 3) & ~(size_t)3;
    const size_t bin_padded = (size_t)((bin_bytes + 3) & ~(uint64_t)3);
    const size_t head_bytes = 12 + 8 + json_padded + 8;
    if (head_bytes + bin_padded > UINT32_MAX) {
        snprintf(err, err_size, "%s: more than one glTF file can hold", path);
        rc = TW_ERR_LIMIT;
        goto out;
    }
    head = malloc(head_bytes);
    bin = malloc(bin_padded ? bin_padded : 1);
    if (!head || !bin) {
        rc = TW_ERR_NOMEM;
        goto nomem;
    }
    memcpy(head, "glTF", 4);
    put_u32(head + 4, 2);
    put_u32(head + 8, (uint32_t)(head_bytes + bin_padded));
    put_u32(head + 12, (uint32_t)json_padded);
    memcpy(head + 16, "JSON", 4);
    memcpy(head + 20, json, json_len);
    memset(head + 20 + json_len, ' ', json_padded - json_len);
    put_u32(head + 20 + json_padded, (uint32_t)bin_padded);
    memcpy(head + 24 + json_padded, "BIN\0", 4);
    for (uint32_t k = 0; k < nm; k++) {
        const struct tw_tiles3d_mesh *m = &sc->meshes[k];
        const struct mesh_layout *l = &lay[k];
        const size_t nv = m->vertex_count;
        memcpy(bin + l->pos, m->positions, 12 * nv);
        float *nrm = (float *)(bin + l->nrm);
        if (l->unit) {
            memcpy(nrm, m->normals, 12 * nv);
        } else {
            memcpy(bin + l->exact, m->normals, 12 * nv);
            /* glTF wants unit normals: a transform that scales leaves them longer. */
            for (size_t v = 0; v < nv; v++) {
                const float *n = m->normals + 3 * v;
                const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
                const bool ok = len > 1e-20f && isfinite(len);
                for (int a = 0; a < 3; a++)
                    nrm[3 * v + a] = ok ? n[a] / len : (a == 1 ? 1.0f : 0.0f);
            }
        }
        if (m->colors)
            memcpy(bin + floats + l->col, m->colors, 4 * nv);
        memcpy(bin + floats + colours + l->idx, m->indices, 12 * (size_t)m->triangle_count);
    }
    memset(bin + bin_bytes, 0, bin_padded - bin_bytes);
    const void *pieces[2] = {head, bin};
    const size_t sizes[2] = {head_bytes, bin_padded};
    rc = write_pieces(path, pieces, sizes, 2, err, err_size);
    goto out;
nomem:
    snprintf(err, err_size, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
out:
    free(lay);
    free(pairs);
    free(head);
    free(bin);
    json_object_put(root);
    return rc;
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

int tw_tiles3d_read_glb_error(const char *path, double *error, char *err, size_t err_size)
{
    *error = 0.0;
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, err_size, "%s: %s", path, strerror(errno));
        return TW_ERR_IO;
    }
    /* The header and the JSON chunk only: the binary chunk is not needed. */
    uint8_t head[20];
    uint8_t *start = NULL;
    int rc = TW_ERR_FORMAT;
    if (fread(head, 1, sizeof(head), f) == sizeof(head)) {
        const uint32_t n = get_u32(head + 12);
        if (n <= (64u << 20) && (start = malloc(20 + (size_t)n))) {
            memcpy(start, head, 20);
            if (fread(start + 20, 1, n, f) == n)
                rc = tw_tiles3d_glb_error(start, 20 + (size_t)n, error);
        }
    }
    if (rc)
        snprintf(err, err_size, "%s: not a binary glTF file of tileworld bake", path);
    free(start);
    fclose(f);
    return rc;
}

/* The number of bits set among the first bits of s. */
static uint64_t count_bits(const uint8_t *s, uint64_t bits)
{
    uint64_t n = 0;
    for (uint64_t b = 0; b < bits; b++)
        n += (s[b / 8] >> (b % 8)) & 1u;
    return n;
}

/* One availability: a constant when every bit is the same, else a bitstream
 * appended to bin (8-byte aligned, as buffer views of a subtree must be). */
static json_object *availability(const uint8_t *s, uint64_t bits, uint8_t *bin, uint64_t *used,
                                 json_object *views)
{
    const uint64_t set = count_bits(s, bits);
    json_object *a = json_object_new_object();
    if (set == 0 || set == bits) {
        json_object_object_add(a, "constant", json_object_new_int(set ? 1 : 0));
        return a;
    }
    const uint64_t bytes = (bits + 7) / 8;
    memcpy(bin + *used, s, bytes);
    /* Bits past the end are zero (the caller's array may hold more). */
    if (bits % 8)
        bin[*used + bytes - 1] &= (uint8_t)((1u << (bits % 8)) - 1u);
    json_object_object_add(a, "bitstream", json_object_new_int((int)json_object_array_length(views)));
    json_object_object_add(a, "availableCount", json_object_new_int64((int64_t)set));
    json_object_array_add(views, buffer_view(*used, bytes, 0, 0));
    *used += (bytes + 7) & ~(uint64_t)7;
    return a;
}

int tw_tiles3d_write_subtree(const char *path, const struct tw_tiles3d_subtree *s, char *err,
                             size_t err_size)
{
    const uint64_t tile_bits = tw_tiles3d_tiles_below(s->levels);
    const uint64_t child_bits = 1ull << (2 * s->levels);
    const uint64_t room = 3 * ((child_bits + 7) / 8 + 8) + 8;
    uint8_t *bin = calloc(1, room);
    if (!bin) {
        snprintf(err, err_size, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
        return TW_ERR_NOMEM;
    }
    uint64_t used = 0;
    json_object *root = json_object_new_object();
    json_object *views = json_object_new_array();
    json_object *tiles = availability(s->tiles, tile_bits, bin, &used, views);
    json_object *content = availability(s->content, tile_bits, bin, &used, views);
    json_object *children = availability(s->children, child_bits, bin, &used, views);
    if (used > 0) {
        json_object *buffer = json_object_new_object();
        json_object_object_add(buffer, "byteLength", json_object_new_int64((int64_t)used));
        json_object *buffers = json_object_new_array();
        json_object_array_add(buffers, buffer);
        json_object_object_add(root, "buffers", buffers);
        json_object_object_add(root, "bufferViews", views);
    } else {
        json_object_put(views);
    }
    json_object_object_add(root, "tileAvailability", tiles);
    json_object *contents = json_object_new_array();
    json_object_array_add(contents, content);
    json_object_object_add(root, "contentAvailability", contents);
    json_object_object_add(root, "childSubtreeAvailability", children);

    const char *json = json_object_to_json_string_ext(root, JSON_C_TO_STRING_PLAIN |
                                                                JSON_C_TO_STRING_NOSLASHESCAPE);
    const size_t json_len = strlen(json), json_padded = (json_len + 7) & ~(size_t)7;
    uint8_t *head = malloc(24 + json_padded);
    int rc = TW_OK;
    if (!head) {
        snprintf(err, err_size, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
        rc = TW_ERR_NOMEM;
        goto out;
    }
    memcpy(head, "subt", 4);
    put_u32(head + 4, 1);
    put_u64(head + 8, json_padded);
    put_u64(head + 16, used);
    memcpy(head + 24, json, json_len);
    memset(head + 24 + json_len, ' ', json_padded - json_len);
    const void *pieces[2] = {head, bin};
    const size_t sizes[2] = {24 + json_padded, (size_t)used};
    rc = write_pieces(path, pieces, sizes, 2, err, err_size);
out:
    free(head);
    free(bin);
    json_object_put(root);
    return rc;
}
