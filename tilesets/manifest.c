/* Tileset manifests (tilesets.h): a JSON file, read with json-c, that
 * composes glTF files into the prototypes of a tileset.
 *
 *   {
 *     "name": "kenney-city",            optional; default: the file name without ".json"
 *     "footprint": [60, 60],            required: W (along x) and D (along z), metres
 *     "max_cluster_triangles": 2048,    optional: cluster size for tw_tileset_finish();
 *                                       0 never splits; default 2048
 *     "comment": "...",                 optional, ignored (allowed in every object)
 *     "prototypes": [                   required, 1 to 1024 prototypes, each either
 *       {                               ... one glTF scene:
 *         "name": "tower",              required, unique, at most 47 bytes
 *         "weight": 1,                  optional selection weight, > 0; default 1
 *         "gltf": "tower.glb",          the file
 *         "scale": 10,                  optional, > 0; default 1
 *         "yaw": 0,                     optional, degrees about +y; default 0
 *         "offset": [30, 0, 30]         optional, metres; default [0, 0, 0]
 *       },
 *       {                               ... or several placed glTF scenes:
 *         "name": "block",
 *         "weight": 2,
 *         "objects": [                  1 to 65536 objects
 *           {"gltf": "road.glb", "position": [5, 0, 5], "yaw": 90, "scale": 10}
 *         ]                             position default [0, 0, 0], yaw 0, scale 1
 *       }
 *     ]
 *   }
 *
 * A placed scene is scaled (uniformly), turned by yaw about +y (0 keeps +z,
 * 90 turns +z towards +x, as camera yaw in DESIGN.md §9) and then moved to
 * position/offset, in tile-local metres: the tile spans [0, W] x [0, D] in x
 * and z, y is up.
 *
 * File names are relative to the manifest's folder and must stay inside it:
 * absolute paths, URIs ("file:", "http:", ...), backslashes, ".." that climb
 * out and symbolic links that lead out are refused. So are unknown keys
 * (a typo must not pass silently), wrong types, non-finite numbers, and
 * anything beyond the limits. Each distinct file is imported once and its
 * meshes are shared by every placement. Every error is one line naming the
 * manifest, the place in it (e.g. prototypes[2].objects[0].gltf) and the
 * reason; text quoted from the manifest is escaped (tiles.h tw_log_escape()).
 *
 * Files are opened beneath the manifest's folder in one step (no window
 * between checking a name and opening it: confined-path.h), and a file is
 * known by its identity (device and inode), however it is named.
 *
 * What a frame can afford (tiles.h): a weight and a scale lie in [1e-6, 1e6];
 * every placed scene lies within +-TW_TILES_MAX_COORD of its tile and spans
 * at most TW_TILES_MAX_SPAN footprints; and a view of the default distance
 * (TW_TILES_REFERENCE_VIEW_DISTANCE) over the tileset considers at most
 * TW_TILES_MAX_CELLS_IN_VIEW cells, which needs tiles of at least about
 * 4.7 m. Memory is bounded by the file: at most MAX_MANIFEST_BYTES of text
 * and MAX_JSON_CONTAINERS objects and arrays (json-c costs about 700 bytes
 * each). What the files cost together is bounded before it is spent: the
 * glTF imports share one budget of bytes read (4 times the glTF
 * max_file_bytes, so that a buffer named by many files is not read without
 * end) and of decoded images (256 MiB; an image file named by several is
 * decoded once), their geometry is at most 4 times max_file_bytes, and the
 * triangles placed are counted from each file's count before placing: at
 * most the glTF max_triangles in a prototype, PLACED_TRIANGLES_FACTOR times
 * it in the tileset, and at most MAX_INSTANCES instances.
 *
 * This file reads the text and checks its values; manifest-compose.c
 * composes the tileset from them (manifest-private.h). */
#include "tiles/tiles-internal.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/manifest-private.h"

#define MAX_MANIFEST_BYTES (16u << 20)
#define MAX_JSON_DEPTH 64
#define MAX_JSON_CONTAINERS (1u << 18)
#define MAX_PROTOTYPES 1024
#define MAX_OBJECTS 65536
#define DEFAULT_CLUSTER_TRIANGLES 2048
#define MIN_FACTOR 1e-6                /* weights and scales */
#define MAX_FACTOR 1e6

/* Records "<place>: <reason>" once: the first error wins. */
int tw_manifest_fail(struct tw_manifest_loader *ld, int err, const char *fmt, ...)
{
    if (ld->msg[0])
        return err;
    char reason[1280];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(reason, sizeof(reason), fmt, ap);
    va_end(ap);
    if (ld->place[0])
        snprintf(ld->msg, sizeof(ld->msg), "%s: %s", ld->place, reason);
    else
        snprintf(ld->msg, sizeof(ld->msg), "%s", reason);
    return err;
}

void tw_manifest_set_place(struct tw_manifest_loader *ld, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ld->place, sizeof(ld->place), fmt, ap);
    va_end(ap);
}

/* ---- typed reads ------------------------------------------------------------------ */

static const char *json_type_phrase(const struct json_object *o)
{
    switch (json_object_get_type(o)) {
    case json_type_null: return "null";
    case json_type_boolean: return "a boolean";
    case json_type_double:
    case json_type_int: return "a number";
    case json_type_object: return "an object";
    case json_type_array: return "an array";
    case json_type_string: return "a string";
    }
    return "a value of an unknown type";
}

/* Refuses keys of obj that are not in allowed (NULL-terminated); "comment"
 * is always allowed. prefix is the object's place. */
static int check_keys(struct tw_manifest_loader *ld, const struct json_object *obj,
                      const char *prefix, const char *const *allowed)
{
    struct json_object_iterator it = json_object_iter_begin((struct json_object *)obj);
    struct json_object_iterator end = json_object_iter_end(obj);
    for (; !json_object_iter_equal(&it, &end); json_object_iter_next(&it)) {
        const char *key = json_object_iter_peek_name(&it);
        bool known = strcmp(key, "comment") == 0;
        for (const char *const *a = allowed; *a && !known; a++)
            known = strcmp(key, *a) == 0;
        if (!known) {
            char list[256] = "";
            size_t n = 0;
            for (const char *const *a = allowed; *a; a++)
                n += (size_t)snprintf(list + n, n < sizeof(list) ? sizeof(list) - n : 0, "%s%s",
                                      a == allowed ? "" : ", ", *a);
            char shown[96];
            tw_manifest_set_place(ld, "%s", prefix);
            return tw_manifest_fail(ld, TW_ERR_FORMAT, "unknown key \"%s\" (known: %s)",
                                    tw_log_escape(key, shown, sizeof(shown)), list);
        }
    }
    return TW_OK;
}

static int get_number(struct tw_manifest_loader *ld, const struct json_object *o, double *out)
{
    /* Set on every path: optimising GCC cannot tell tw_manifest_fail() from
     * success. */
    *out = 0.0;
    if (!json_object_is_type(o, json_type_double) && !json_object_is_type(o, json_type_int))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be a number, not %s", json_type_phrase(o));
    *out = json_object_get_double(o);
    if (!isfinite(*out))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be a finite number");
    return TW_OK;
}

/* A number in [lo, hi], lo excluded when open_lo. */
static int get_ranged(struct tw_manifest_loader *ld, const struct json_object *o, double lo,
                      bool open_lo, double hi, float *out)
{
    double v;
    int err = get_number(ld, o, &v);
    if (err)
        return err;
    if (v < lo || (open_lo && v == lo) || v > hi)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "%g is not in %s%g, %g]", v, open_lo ? "(" : "[",
                                lo, hi);
    *out = (float)v;
    return TW_OK;
}

/* A string without control characters (C0, DEL, C1): a name that is
 * printed later (tileworld info, reports) must not drive a terminal. */
static int check_printable(struct tw_manifest_loader *ld, const char *s)
{
    char shown[64];
    for (size_t k = 0; s[k]; k++) {
        const unsigned char c = (unsigned char)s[k];
        const bool c1 = c == 0xc2 && (unsigned char)s[k + 1] >= 0x80 &&
                        (unsigned char)s[k + 1] <= 0x9f;
        if (c < 0x20 || c == 0x7f || c1)
            return tw_manifest_fail(ld, TW_ERR_FORMAT,
                                    "\"%s\" contains a control character at byte %zu",
                                    tw_log_escape(s, shown, sizeof(shown)), k);
    }
    return TW_OK;
}

static int get_vector(struct tw_manifest_loader *ld, const struct json_object *o, int n,
                      double limit, float *out)
{
    if (!json_object_is_type(o, json_type_array) || (int)json_object_array_length(o) != n)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an array of %d numbers, not %s", n,
                                json_object_is_type(o, json_type_array)
                                    ? "an array of another length"
                                    : json_type_phrase(o));
    for (int k = 0; k < n; k++) {
        double v;
        int err = get_number(ld, json_object_array_get_idx(o, (size_t)k), &v);
        if (err)
            return err;
        if (fabs(v) > limit)
            return tw_manifest_fail(ld, TW_ERR_FORMAT, "element %d, %g, is beyond +-%g", k, v,
                                    limit);
        out[k] = (float)v;
    }
    return TW_OK;
}

/* A string without NUL bytes, of at most max_len bytes. */
static int get_string(struct tw_manifest_loader *ld, const struct json_object *o, size_t max_len,
                      const char **out)
{
    if (!json_object_is_type(o, json_type_string))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be a string, not %s", json_type_phrase(o));
    const char *s = json_object_get_string((struct json_object *)o);
    const size_t len = (size_t)json_object_get_string_len(o);
    if (strlen(s) != len)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "contains a NUL character");
    if (len > max_len)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is %zu bytes long, more than %zu", len,
                                max_len);
    *out = s;
    return TW_OK;
}

static struct json_object *member(const struct json_object *obj, const char *key)
{
    struct json_object *v = NULL;
    return json_object_object_get_ex(obj, key, &v) ? v : NULL;
}

/* ---- the document ------------------------------------------------------------------ */

/* Places file rel in prototype proto. obj holds "gltf", "scale", "yaw" and
 * the position under position_key; prefix is obj's place. */
static int place_object(struct tw_manifest_loader *ld, uint32_t proto,
                        const struct json_object *obj, const char *prefix, const char *position_key)
{
    float position[3] = {0, 0, 0}, yaw = 0.0f, scale = 1.0f;
    const char *rel = NULL;
    struct json_object *v;
    int err;

    tw_manifest_set_place(ld, "%s.gltf", prefix);
    if (!(v = member(obj, "gltf")))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_string(ld, v, 4096, &rel)))
        return err;
    if ((v = member(obj, "scale"))) {
        tw_manifest_set_place(ld, "%s.scale", prefix);
        if ((err = get_ranged(ld, v, MIN_FACTOR, false, MAX_FACTOR, &scale)))
            return err;
    }
    if ((v = member(obj, "yaw"))) {
        tw_manifest_set_place(ld, "%s.yaw", prefix);
        if ((err = get_ranged(ld, v, -3600.0, false, 3600.0, &yaw)))
            return err;
    }
    if ((v = member(obj, position_key))) {
        tw_manifest_set_place(ld, "%s.%s", prefix, position_key);
        if ((err = get_vector(ld, v, 3, TW_TILES_MAX_COORD, position)))
            return err;
    }
    return tw_manifest_place(ld, proto, prefix, rel, position, yaw, scale);
}

static int read_prototype(struct tw_manifest_loader *ld, const struct json_object *p,
                          uint32_t index)
{
    static const char *const single_keys[] = {"name", "weight", "gltf", "scale", "yaw",
                                              "offset", NULL};
    static const char *const composed_keys[] = {"name", "weight", "objects", NULL};
    static const char *const object_keys[] = {"gltf", "position", "yaw", "scale", NULL};
    char prefix[64];
    snprintf(prefix, sizeof(prefix), "prototypes[%u]", index);
    struct json_object *v;
    int err;

    tw_manifest_set_place(ld, "%s", prefix);
    ld->prototype_triangles = 0;
    if (!json_object_is_type(p, json_type_object))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an object, not %s",
                                json_type_phrase(p));
    const bool single = member(p, "gltf") != NULL;
    const bool composed = member(p, "objects") != NULL;
    if (single == composed)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must have either \"gltf\" or \"objects\"%s",
                                single ? ", not both" : "");
    if ((err = check_keys(ld, p, prefix, single ? single_keys : composed_keys)))
        return err;

    const char *name = NULL;
    tw_manifest_set_place(ld, "%s.name", prefix);
    if (!(v = member(p, "name")))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_string(ld, v, sizeof(ld->ts->prototypes[0].name) - 1, &name)))
        return err;
    if (!name[0])
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is empty");
    if ((err = check_printable(ld, name)))
        return err;
    float weight = 1.0f;
    if ((v = member(p, "weight"))) {
        tw_manifest_set_place(ld, "%s.weight", prefix);
        if ((err = get_ranged(ld, v, MIN_FACTOR, false, MAX_FACTOR, &weight)))
            return err;
    }
    uint32_t proto;
    if ((err = tw_manifest_add_prototype(ld, prefix, name, weight, &proto)))
        return err;
    if (single)
        return place_object(ld, proto, p, prefix, "offset");

    tw_manifest_set_place(ld, "%s.objects", prefix);
    v = member(p, "objects");
    if (!json_object_is_type(v, json_type_array))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an array, not %s", json_type_phrase(v));
    const size_t n = json_object_array_length(v);
    if (n < 1 || n > MAX_OBJECTS)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "has %zu objects, not 1 to %d", n, MAX_OBJECTS);
    for (size_t k = 0; k < n; k++) {
        const struct json_object *o = json_object_array_get_idx(v, k);
        char object_prefix[96];
        snprintf(object_prefix, sizeof(object_prefix), "%s.objects[%zu]", prefix, k);
        tw_manifest_set_place(ld, "%s", object_prefix);
        if (!json_object_is_type(o, json_type_object))
            return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an object, not %s",
                                    json_type_phrase(o));
        if ((err = check_keys(ld, o, object_prefix, object_keys)) ||
            (err = place_object(ld, proto, o, object_prefix, "position")))
            return err;
    }
    return TW_OK;
}

/* The default tileset name: the manifest's file name without ".json",
 * escaped (a file name may hold anything). */
static void default_name(const char *name, char *out, size_t size)
{
    const char *slash = strrchr(name, '/');
    const char *base = slash ? slash + 1 : name;
    size_t n = strlen(base);
    if (n > 5 && strcmp(base + n - 5, ".json") == 0)
        n -= 5;
    tw_log_escape_bytes(base, n, out, size);
}

static int read_manifest(struct tw_manifest_loader *ld, const struct json_object *root)
{
    static const char *const keys[] = {"name", "footprint", "max_cluster_triangles",
                                       "prototypes", NULL};
    struct json_object *v;
    int err;

    tw_manifest_set_place(ld, "%s", "");
    if (!json_object_is_type(root, json_type_object))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "the manifest must be a JSON object, not %s",
                                json_type_phrase(root));
    if ((err = check_keys(ld, root, "(top level)", keys)))
        return err;

    char name[64];
    default_name(ld->name, name, sizeof(name));
    if ((v = member(root, "name"))) {
        const char *given;
        tw_manifest_set_place(ld, "name");
        if ((err = get_string(ld, v, sizeof(name) - 1, &given)) ||
            (err = check_printable(ld, given)))
            return err;
        snprintf(name, sizeof(name), "%s", given);
    }

    float footprint[2];
    tw_manifest_set_place(ld, "footprint");
    if (!(v = member(root, "footprint")))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_vector(ld, v, 2, TW_TILES_MAX_COORD, footprint)))
        return err;
    if (!(footprint[0] > 0.0f) || !(footprint[1] > 0.0f))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "both sides must be positive");

    uint32_t cluster = ld->settings.max_cluster_triangles;
    if ((v = member(root, "max_cluster_triangles"))) {
        tw_manifest_set_place(ld, "max_cluster_triangles");
        if (!json_object_is_type(v, json_type_int))
            return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an integer, not %s",
                                    json_type_phrase(v));
        const int64_t c = json_object_get_int64(v);
        if (c < 0 || c > (1 << 24))
            return tw_manifest_fail(ld, TW_ERR_FORMAT, "%lld is not in [0, %d]", (long long)c,
                                    1 << 24);
        if (!cluster)
            cluster = (uint32_t)c;
    } else if (!cluster) {
        cluster = DEFAULT_CLUSTER_TRIANGLES;
    }

    tw_manifest_set_place(ld, "prototypes");
    if (!(v = member(root, "prototypes")))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "is missing");
    if (!json_object_is_type(v, json_type_array))
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "must be an array, not %s", json_type_phrase(v));
    const size_t n = json_object_array_length(v);
    if (n < 1 || n > MAX_PROTOTYPES)
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "has %zu prototypes, not 1 to %d", n,
                                MAX_PROTOTYPES);

    if ((err = tw_manifest_create_tileset(ld, name, footprint)))
        return err;
    for (size_t k = 0; k < n; k++)
        if ((err = read_prototype(ld, json_object_array_get_idx(v, k), (uint32_t)k)))
            return err;
    return tw_manifest_finish_tileset(ld, cluster);
}

/* Line and column (1-based) of byte offset in text. */
static void line_column(const char *text, size_t offset, unsigned *line, unsigned *column)
{
    *line = 1;
    *column = 1;
    for (size_t k = 0; k < offset; k++) {
        if (text[k] == '\n') {
            ++*line;
            *column = 1;
        } else {
            ++*column;
        }
    }
}

/* Objects and arrays in text, outside strings: json-c spends hundreds of
 * bytes on each, so their number bounds the memory a manifest takes. */
static uint64_t count_containers(const char *text, size_t size)
{
    uint64_t n = 0;
    bool in_string = false;
    for (size_t k = 0; k < size; k++) {
        const char c = text[k];
        if (in_string) {
            if (c == '\\')
                k++;
            else if (c == '"')
                in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            n++;
        }
    }
    return n;
}

static int parse(struct tw_manifest_loader *ld, const char *text, size_t size,
                 struct tw_tileset **out)
{
    struct json_tokener *tok = NULL;
    struct json_object *root = NULL;
    int err = TW_OK;

    tw_manifest_set_place(ld, "%s", "");
    if (size > MAX_MANIFEST_BYTES) {
        err = tw_manifest_fail(ld, TW_ERR_LIMIT, "is %zu bytes, more than the limit of %u", size,
                               MAX_MANIFEST_BYTES);
        goto out;
    }
    const char *nul = memchr(text, '\0', size);
    if (nul) {
        unsigned line, column;
        line_column(text, (size_t)(nul - text), &line, &column);
        err = tw_manifest_fail(ld, TW_ERR_FORMAT, "line %u, column %u: a NUL byte: not a JSON text",
                               line, column);
        goto out;
    }
    const uint64_t containers = count_containers(text, size);
    if (containers > MAX_JSON_CONTAINERS) {
        err = tw_manifest_fail(ld, TW_ERR_LIMIT,
                               "holds %llu JSON objects and arrays, more than the limit "
                               "of %u",
                               (unsigned long long)containers, MAX_JSON_CONTAINERS);
        goto out;
    }
    tok = json_tokener_new_ex(MAX_JSON_DEPTH);
    if (!tok) {
        err = tw_manifest_fail(ld, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    json_tokener_set_flags(tok, JSON_TOKENER_STRICT);
    root = json_tokener_parse_ex(tok, text, (int)size);
    enum json_tokener_error jerr = json_tokener_get_error(tok);
    if (jerr == json_tokener_continue) {
        err = tw_manifest_fail(ld, TW_ERR_FORMAT,
                               "JSON ends early (an unclosed string, array or object)");
        goto out;
    }
    if (!root || jerr != json_tokener_success) {
        unsigned line, column;
        line_column(text, json_tokener_get_parse_end(tok), &line, &column);
        err = tw_manifest_fail(ld, TW_ERR_FORMAT, "line %u, column %u: invalid JSON: %s", line,
                               column, json_tokener_error_desc(jerr));
        goto out;
    }
    for (size_t k = json_tokener_get_parse_end(tok); k < size; k++) {
        if (text[k] != ' ' && text[k] != '\t' && text[k] != '\n' && text[k] != '\r') {
            unsigned line, column;
            line_column(text, k, &line, &column);
            err = tw_manifest_fail(ld, TW_ERR_FORMAT,
                                   "line %u, column %u: text after the JSON value", line, column);
            goto out;
        }
    }
    if ((err = read_manifest(ld, root)))
        goto out;
    *out = ld->ts;
    ld->ts = NULL;
out:
    json_object_put(root);
    if (tok)
        json_tokener_free(tok);
    return err;
}

static void resolve_settings(const struct tw_manifest_settings *given,
                             struct tw_manifest_settings *s)
{
    memset(s, 0, sizeof(*s));
    tw_gltf_default_settings(&s->gltf);
    if (!given)
        return;
    s->max_cluster_triangles = given->max_cluster_triangles;
    if (given->gltf.max_file_bytes)
        s->gltf.max_file_bytes = given->gltf.max_file_bytes;
    if (given->gltf.max_triangles)
        s->gltf.max_triangles = given->gltf.max_triangles;
}

static void init_loader(struct tw_manifest_loader *ld, const char *name,
                        const struct tw_manifest_settings *settings, const struct tw_log *log)
{
    memset(ld, 0, sizeof(*ld));
    ld->name = name;
    tw_log_escape(name, ld->shown, sizeof(ld->shown));
    ld->dir_fd = -1;
    ld->log = log;
    resolve_settings(settings, &ld->settings);
}

static int finish_loader(struct tw_manifest_loader *ld, int err)
{
    tw_manifest_compose_finish(ld);
    if (ld->dir_fd >= 0)
        close(ld->dir_fd);
    if (err)
        tw_log_printf(ld->log, TW_LOG_ERROR, "%s: %s", ld->shown,
                      ld->msg[0] ? ld->msg : tw_error_to_str(err));
    return err;
}

int tw_tilesets_parse_manifest(const char *text, size_t size, const char *name,
                               const char *base_dir, const struct tw_manifest_settings *settings,
                               const struct tw_log *log, struct tw_tileset **out)
{
    if (!out) {
        tw_log_printf(log, TW_LOG_ERROR, "manifest: out is NULL (caller's bug)");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    struct tw_manifest_loader ld;
    init_loader(&ld, name ? name : "(manifest)", settings, log);
    if (!text && size)
        return finish_loader(&ld, tw_manifest_fail(&ld, TW_ERR_INVALID, "no text (caller's bug)"));
    ld.dir_fd = tw_confined_open_folder(base_dir ? base_dir : ".");
    if (ld.dir_fd < 0) {
        char shown[256];
        return finish_loader(
            &ld, tw_manifest_fail(&ld, TW_ERR_IO, "the folder \"%s\" cannot be opened: %s",
                                  tw_log_escape(base_dir ? base_dir : ".", shown, sizeof(shown)),
                                  strerror(errno)));
    }
    return finish_loader(&ld, parse(&ld, text ? text : "", size, out));
}

int tw_tilesets_load_manifest(const char *path, const struct tw_manifest_settings *settings,
                              const struct tw_log *log, struct tw_tileset **out)
{
    if (!out || !path) {
        tw_log_printf(log, TW_LOG_ERROR, "manifest: %s is NULL (caller's bug)",
                      out ? "path" : "out");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    struct tw_manifest_loader ld;
    init_loader(&ld, path, settings, log);
    uint8_t *text = NULL;
    size_t size = 0;
    char why[512];
    int fd = -1;
    /* Opened non-blocking and checked before anything is read: a FIFO or a
     * device is refused, never waited on. */
    int err = tw_confined_open_user(path, &fd, why, sizeof(why));
    if (!err) {
        err = tw_confined_read(fd, MAX_MANIFEST_BYTES, &text, &size, why, sizeof(why));
        close(fd);
    }
    if (err)
        return finish_loader(&ld, tw_manifest_fail(&ld, err, "%s", why));
    ld.dir_fd = tw_confined_open_folder_of(path);
    if (ld.dir_fd < 0) {
        free(text);
        return finish_loader(
            &ld,
            tw_manifest_fail(&ld, TW_ERR_IO, "its folder cannot be opened: %s", strerror(errno)));
    }
    err = parse(&ld, (const char *)text, size, out);
    free(text);
    return finish_loader(&ld, err);
}
