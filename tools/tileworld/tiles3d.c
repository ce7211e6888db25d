/* Binary glTF, subtree files and atomic writes for 3D Tiles (tiles3d.h). */
#include "tools/tileworld/tiles3d.h"

#include <errno.h>
#include <fcntl.h>
#include <json-c/json.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tileworld/tiles.h"

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
    if (!slash)
        return TW_OK;
    const size_t n = (size_t)(slash - path);
    if (n >= sizeof(dir)) {
        snprintf(err, err_size, "%s: %s", path, strerror(ENAMETOOLONG));
        return TW_ERR_IO;
    }
    memcpy(dir, path, n);
    dir[n] = '\0';
    for (size_t k = 1; k <= n; k++) {
        if (dir[k] != '/' && dir[k] != '\0')
            continue;
        const char c = dir[k];
        dir[k] = '\0';
        if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
            snprintf(err, err_size, "%s: cannot make the folder: %s", dir, strerror(errno));
            return TW_ERR_IO;
        }
        dir[k] = c;
    }
    return TW_OK;
}

/* Writes the pieces as path through .NAME.tmp.PID and a rename. */
static int write_pieces(const char *path, const void *const *data, const size_t *size,
                        int count, char *err, size_t err_size)
{
    char tmp[4200];
    const char *slash = strrchr(path, '/');
    const int dir_len = slash ? (int)(slash - path + 1) : 0;
    const int n = snprintf(tmp, sizeof(tmp), "%.*s.%s.tmp.%ld", dir_len, path, path + dir_len,
                           (long)getpid());
    if (n < 0 || (size_t)n >= sizeof(tmp)) {
        snprintf(err, err_size, "%s: cannot write: %s", path, strerror(ENAMETOOLONG));
        return TW_ERR_IO;
    }
    const int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (fd < 0) {
        snprintf(err, err_size, "%s: cannot write: %s", path, strerror(errno));
        return TW_ERR_IO;
    }
    int e = 0;
    for (int k = 0; k < count && !e; k++) {
        const char *p = data[k];
        size_t left = size[k];
        while (left > 0) {
            const ssize_t w = write(fd, p, left);
            if (w < 0 && errno == EINTR)
                continue;
            if (w <= 0) {
                e = w < 0 ? errno : EIO;
                break;
            }
            p += w;
            left -= (size_t)w;
        }
    }
    if (close(fd) != 0 && !e)
        e = errno;
    if (!e && rename(tmp, path) != 0)
        e = errno;
    if (e) {
        unlink(tmp);
        snprintf(err, err_size, "%s: cannot write: %s", path, strerror(e));
        return TW_ERR_IO;
    }
    return TW_OK;
}

int tw_tiles3d_write_file(const char *path, const void *data, size_t size, char *err,
                          size_t err_size)
{
    return write_pieces(path, &data, &size, 1, err, err_size);
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

static json_object *int_array(const int64_t *v, int n)
{
    json_object *a = json_object_new_array();
    for (int k = 0; k < n; k++)
        json_object_array_add(a, json_object_new_int64(v[k]));
    return a;
}

static json_object *double_array(const double *v, int n)
{
    json_object *a = json_object_new_array();
    for (int k = 0; k < n; k++)
        json_object_array_add(a, json_object_new_double(v[k]));
    return a;
}

static json_object *buffer_view(uint64_t offset, uint64_t length, int target)
{
    json_object *v = json_object_new_object();
    json_object_object_add(v, "buffer", json_object_new_int(0));
    json_object_object_add(v, "byteOffset", json_object_new_int64((int64_t)offset));
    json_object_object_add(v, "byteLength", json_object_new_int64((int64_t)length));
    json_object_object_add(v, "target", json_object_new_int(target));
    return v;
}

static json_object *accessor(int view, int component, uint32_t count, const char *type,
                             bool normalized)
{
    json_object *a = json_object_new_object();
    json_object_object_add(a, "bufferView", json_object_new_int(view));
    json_object_object_add(a, "componentType", json_object_new_int(component));
    if (normalized)
        json_object_object_add(a, "normalized", json_object_new_boolean(1));
    json_object_object_add(a, "count", json_object_new_int64(count));
    json_object_object_add(a, "type", json_object_new_string(type));
    return a;
}

int tw_tiles3d_write_glb(const char *path, const struct tw_tiles3d_mesh *m,
                         const double translation[3], char *err, size_t err_size)
{
    const uint64_t nv = m->vertex_count, nt = m->triangle_count;
    const uint64_t pos_bytes = 12 * nv, nrm_bytes = 12 * nv, col_bytes = m->colors ? 4 * nv : 0;
    const uint64_t idx_bytes = 12 * nt;
    const uint64_t bin_bytes = pos_bytes + nrm_bytes + col_bytes + idx_bytes;
    if (nv == 0 || nt == 0 || bin_bytes > UINT32_MAX - 4096) {
        snprintf(err, err_size, "%s: a mesh of %llu vertices and %llu triangles is not one "
                 "glTF file can hold", path, (unsigned long long)nv, (unsigned long long)nt);
        return TW_ERR_LIMIT;
    }
    double lo[3] = {0}, hi[3] = {0};
    for (int a = 0; a < 3; a++)
        lo[a] = hi[a] = m->positions[a];
    for (uint64_t v = 0; v < nv; v++)
        for (int a = 0; a < 3; a++) {
            const double x = m->positions[3 * v + a];
            lo[a] = x < lo[a] ? x : lo[a];
            hi[a] = x > hi[a] ? x : hi[a];
        }

    json_object *root = json_object_new_object();
    json_object *asset = json_object_new_object();
    json_object_object_add(asset, "version", json_object_new_string("2.0"));
    json_object_object_add(asset, "generator", json_object_new_string("tileworld bake"));
    if (m->error > 0.0) {
        json_object *extras = json_object_new_object();
        json_object_object_add(extras, "geometricError", json_object_new_double(m->error));
        json_object_object_add(asset, "extras", extras);
    }
    json_object_object_add(root, "asset", asset);
    json_object_object_add(root, "scene", json_object_new_int(0));
    json_object *scene = json_object_new_object();
    const int64_t zero = 0;
    json_object_object_add(scene, "nodes", int_array(&zero, 1));
    json_object *scenes = json_object_new_array();
    json_object_array_add(scenes, scene);
    json_object_object_add(root, "scenes", scenes);
    json_object *node = json_object_new_object();
    json_object_object_add(node, "mesh", json_object_new_int(0));
    if (translation[0] != 0.0 || translation[1] != 0.0 || translation[2] != 0.0)
        json_object_object_add(node, "translation", double_array(translation, 3));
    json_object *nodes = json_object_new_array();
    json_object_array_add(nodes, node);
    json_object_object_add(root, "nodes", nodes);

    json_object *attributes = json_object_new_object();
    json_object_object_add(attributes, "POSITION", json_object_new_int(0));
    json_object_object_add(attributes, "NORMAL", json_object_new_int(1));
    if (m->colors)
        json_object_object_add(attributes, "COLOR_0", json_object_new_int(3));
    json_object *primitive = json_object_new_object();
    json_object_object_add(primitive, "attributes", attributes);
    json_object_object_add(primitive, "indices", json_object_new_int(2));
    json_object_object_add(primitive, "material", json_object_new_int(0));
    json_object_object_add(primitive, "mode", json_object_new_int(4));
    json_object *primitives = json_object_new_array();
    json_object_array_add(primitives, primitive);
    json_object *mesh = json_object_new_object();
    json_object_object_add(mesh, "primitives", primitives);
    json_object *meshes = json_object_new_array();
    json_object_array_add(meshes, mesh);
    json_object_object_add(root, "meshes", meshes);

    /* The colours are the materials, baked per vertex; the tileset's
     * instances may mirror meshes, so both faces are drawn. */
    json_object *pbr = json_object_new_object();
    const double white[4] = {1.0, 1.0, 1.0, 1.0};
    json_object_object_add(pbr, "baseColorFactor", double_array(white, 4));
    json_object_object_add(pbr, "metallicFactor", json_object_new_double(0.0));
    json_object_object_add(pbr, "roughnessFactor", json_object_new_double(1.0));
    json_object *material = json_object_new_object();
    json_object_object_add(material, "pbrMetallicRoughness", pbr);
    json_object_object_add(material, "doubleSided", json_object_new_boolean(1));
    json_object *materials = json_object_new_array();
    json_object_array_add(materials, material);
    json_object_object_add(root, "materials", materials);

    json_object *views = json_object_new_array();
    json_object_array_add(views, buffer_view(0, pos_bytes, GL_ARRAY_BUFFER));
    json_object_array_add(views, buffer_view(pos_bytes, nrm_bytes, GL_ARRAY_BUFFER));
    json_object_array_add(views, buffer_view(pos_bytes + nrm_bytes + col_bytes, idx_bytes,
                                             GL_ELEMENT_ARRAY_BUFFER));
    if (m->colors)
        json_object_array_add(views, buffer_view(pos_bytes + nrm_bytes, col_bytes,
                                                 GL_ARRAY_BUFFER));
    json_object_object_add(root, "bufferViews", views);
    json_object *accessors = json_object_new_array();
    json_object *position = accessor(0, GL_FLOAT, (uint32_t)nv, "VEC3", false);
    json_object_object_add(position, "min", double_array(lo, 3));
    json_object_object_add(position, "max", double_array(hi, 3));
    json_object_array_add(accessors, position);
    json_object_array_add(accessors, accessor(1, GL_FLOAT, (uint32_t)nv, "VEC3", false));
    json_object_array_add(accessors, accessor(2, GL_UNSIGNED_INT, (uint32_t)(3 * nt), "SCALAR",
                                              false));
    if (m->colors)
        json_object_array_add(accessors, accessor(3, GL_UNSIGNED_BYTE, (uint32_t)nv, "VEC4", true));
    json_object_object_add(root, "accessors", accessors);
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
    uint8_t *head = malloc(head_bytes);
    uint8_t *bin = malloc(bin_padded);
    int rc = TW_OK;
    if (!head || !bin) {
        snprintf(err, err_size, "%s: %s", path, tw_error_to_str(TW_ERR_NOMEM));
        rc = TW_ERR_NOMEM;
        goto out;
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
    uint8_t *p = bin;
    memcpy(p, m->positions, pos_bytes);
    p += pos_bytes;
    memcpy(p, m->normals, nrm_bytes);
    p += nrm_bytes;
    if (m->colors) {
        memcpy(p, m->colors, col_bytes);
        p += col_bytes;
    }
    memcpy(p, m->indices, idx_bytes);
    p += idx_bytes;
    memset(p, 0, bin_padded - bin_bytes);
    const void *pieces[2] = {head, bin};
    const size_t sizes[2] = {head_bytes, bin_padded};
    rc = write_pieces(path, pieces, sizes, 2, err, err_size);
out:
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
    uint8_t head[20];
    char *json = NULL;
    int rc = TW_ERR_FORMAT;
    if (fread(head, 1, sizeof(head), f) != sizeof(head) || memcmp(head, "glTF", 4) != 0 ||
        memcmp(head + 16, "JSON", 4) != 0)
        goto out;
    const uint32_t n = get_u32(head + 12);
    if (n > (64u << 20) || !(json = malloc((size_t)n + 1)) || fread(json, 1, n, f) != n)
        goto out;
    json[n] = '\0';
    json_object *root = json_tokener_parse(json);
    if (!root)
        goto out;
    json_object *asset = NULL, *extras = NULL, *e = NULL;
    if (json_object_object_get_ex(root, "asset", &asset) &&
        json_object_object_get_ex(asset, "extras", &extras) &&
        json_object_object_get_ex(extras, "geometricError", &e))
        *error = json_object_get_double(e);
    json_object_put(root);
    rc = TW_OK;
out:
    if (rc)
        snprintf(err, err_size, "%s: not a binary glTF file of tileworld bake", path);
    free(json);
    fclose(f);
    return rc;
}

uint64_t tw_tiles3d_tiles_below(uint32_t levels)
{
    return ((1ull << (2 * levels)) - 1) / 3;
}

uint64_t tw_tiles3d_morton(uint32_t x, uint32_t y)
{
    uint64_t m = 0;
    for (int b = 0; b < 32; b++)
        m |= (uint64_t)((x >> b) & 1u) << (2 * b) | (uint64_t)((y >> b) & 1u) << (2 * b + 1);
    return m;
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
    json_object *v = json_object_new_object();
    json_object_object_add(v, "buffer", json_object_new_int(0));
    json_object_object_add(v, "byteOffset", json_object_new_int64((int64_t)*used));
    json_object_object_add(v, "byteLength", json_object_new_int64((int64_t)bytes));
    json_object_object_add(a, "bitstream", json_object_new_int((int)json_object_array_length(views)));
    json_object_object_add(a, "availableCount", json_object_new_int64((int64_t)set));
    json_object_array_add(views, v);
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
