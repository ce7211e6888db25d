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
 * reason. */
#include "tileworld/tilesets.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/confined-path.h"

#define MAX_MANIFEST_BYTES (16u << 20)
#define MAX_JSON_DEPTH 64
#define MAX_PROTOTYPES 1024
#define MAX_OBJECTS 65536
#define MAX_FILES 1024
#define MAX_INSTANCES (4u << 20)
#define DEFAULT_CLUSTER_TRIANGLES 2048

struct imported_file {
    char *path;                    /* real path: the key */
    struct tw_gltf_scene *scene;
    struct tw_gltf_binding binding;
};

struct loader {
    const char *name;              /* the manifest, for messages */
    const char *base_dir;
    struct tw_manifest_settings settings;
    const struct tw_log *log;
    struct tw_tileset *ts;
    struct imported_file *files;
    uint32_t file_count;
    uint64_t file_bytes;           /* summed sizes of the imported files */
    uint64_t instances;            /* placed so far */
    char place[160];               /* JSON place of the value being read */
    char msg[1536];
};

static int fail(struct loader *ld, int err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Records "<place>: <reason>" once: the first error wins. */
static int fail(struct loader *ld, int err, const char *fmt, ...)
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

static void set_place(struct loader *ld, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void set_place(struct loader *ld, const char *fmt, ...)
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
static int check_keys(struct loader *ld, const struct json_object *obj, const char *prefix,
                      const char *const *allowed)
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
            set_place(ld, "%s", prefix);
            return fail(ld, TW_ERR_FORMAT, "unknown key \"%.64s\" (known: %s)", key, list);
        }
    }
    return TW_OK;
}

static int get_number(struct loader *ld, const struct json_object *o, double *out)
{
    if (!json_object_is_type(o, json_type_double) && !json_object_is_type(o, json_type_int))
        return fail(ld, TW_ERR_FORMAT, "must be a number, not %s", json_type_phrase(o));
    *out = json_object_get_double(o);
    if (!isfinite(*out))
        return fail(ld, TW_ERR_FORMAT, "must be a finite number");
    return TW_OK;
}

/* A number in [lo, hi], lo excluded when open_lo. */
static int get_ranged(struct loader *ld, const struct json_object *o, double lo, bool open_lo,
                      double hi, float *out)
{
    double v;
    int err = get_number(ld, o, &v);
    if (err)
        return err;
    if (v < lo || (open_lo && v == lo) || v > hi)
        return fail(ld, TW_ERR_FORMAT, "%g is not in %s%g, %g]", v, open_lo ? "(" : "[", lo, hi);
    *out = (float)v;
    return TW_OK;
}

static int get_vector(struct loader *ld, const struct json_object *o, int n, double limit,
                      float *out)
{
    if (!json_object_is_type(o, json_type_array) || (int)json_object_array_length(o) != n)
        return fail(ld, TW_ERR_FORMAT, "must be an array of %d numbers, not %s", n,
                    json_object_is_type(o, json_type_array) ? "an array of another length"
                                                            : json_type_phrase(o));
    for (int k = 0; k < n; k++) {
        double v;
        int err = get_number(ld, json_object_array_get_idx(o, (size_t)k), &v);
        if (err)
            return err;
        if (fabs(v) > limit)
            return fail(ld, TW_ERR_FORMAT, "element %d, %g, is beyond +-%g", k, v, limit);
        out[k] = (float)v;
    }
    return TW_OK;
}

/* A string without NUL bytes, of at most max_len bytes. */
static int get_string(struct loader *ld, const struct json_object *o, size_t max_len,
                      const char **out)
{
    if (!json_object_is_type(o, json_type_string))
        return fail(ld, TW_ERR_FORMAT, "must be a string, not %s", json_type_phrase(o));
    const char *s = json_object_get_string((struct json_object *)o);
    const size_t len = (size_t)json_object_get_string_len(o);
    if (strlen(s) != len)
        return fail(ld, TW_ERR_FORMAT, "contains a NUL character");
    if (len > max_len)
        return fail(ld, TW_ERR_FORMAT, "is %zu bytes long, more than %zu", len, max_len);
    *out = s;
    return TW_OK;
}

static struct json_object *member(const struct json_object *obj, const char *key)
{
    struct json_object *v = NULL;
    return json_object_object_get_ex(obj, key, &v) ? v : NULL;
}

/* ---- glTF files ------------------------------------------------------------------- */

struct captured_log {
    const struct tw_log *next;
    char last[1200];
};

static void capture(void *user, enum tw_log_level level, const char *msg)
{
    struct captured_log *c = user;
    if (level == TW_LOG_ERROR)
        snprintf(c->last, sizeof(c->last), "%s", msg);
    else if (c->next && c->next->fn)
        c->next->fn(c->next->user, level, msg);
}

/* The imported file named rel (at the current place), importing and binding
 * it the first time. */
static int get_file(struct loader *ld, const char *rel, struct imported_file **out)
{
    char *path = NULL;
    const char *reason = NULL;
    int err = tw_confined_path_resolve(ld->base_dir, rel, &path, &reason);
    if (err)
        return fail(ld, err == TW_ERR_NOMEM ? err : err == TW_ERR_IO ? TW_ERR_IO : TW_ERR_FORMAT,
                    "\"%.256s\" %s", rel, reason);
    for (uint32_t k = 0; k < ld->file_count; k++) {
        if (strcmp(ld->files[k].path, path) == 0) {
            free(path);
            *out = &ld->files[k];
            return TW_OK;
        }
    }
    if (ld->file_count >= MAX_FILES) {
        free(path);
        return fail(ld, TW_ERR_LIMIT, "more than %d distinct glTF files", MAX_FILES);
    }
    struct imported_file *grown = realloc(ld->files, sizeof(*grown) * (ld->file_count + 1));
    if (!grown) {
        free(path);
        return fail(ld, TW_ERR_NOMEM, "out of memory");
    }
    ld->files = grown;
    struct imported_file *f = &ld->files[ld->file_count];
    memset(f, 0, sizeof(*f));
    f->path = path;
    ld->file_count++;

    struct captured_log cap = {ld->log, ""};
    const struct tw_log capture_log = {capture, &cap};
    err = tw_gltf_import(path, &ld->settings.gltf, &capture_log, &f->scene);
    if (err)
        return fail(ld, err, "%s", cap.last[0] ? cap.last : tw_error_to_str(err));
    /* Bound the memory that many large files could take together. */
    ld->file_bytes += f->scene->vertex_count * 24 + f->scene->unique_triangles * 12;
    if (ld->file_bytes > 4 * ld->settings.gltf.max_file_bytes)
        return fail(ld, TW_ERR_LIMIT,
                    "the manifest's glTF files hold more than %llu bytes of geometry",
                    (unsigned long long)(4 * ld->settings.gltf.max_file_bytes));
    err = tw_gltf_bind(f->scene, ld->ts, &f->binding);
    if (err)
        return fail(ld, err, "cannot add \"%.256s\" to the tileset: %s", rel,
                    tw_error_to_str(err));
    *out = f;
    return TW_OK;
}

/* Places file rel in prototype proto. obj holds "gltf", "scale", "yaw" and
 * the position under position_key; prefix is obj's place. */
static int place_object(struct loader *ld, uint32_t proto, const struct json_object *obj,
                        const char *prefix, const char *position_key)
{
    float position[3] = {0, 0, 0}, yaw = 0.0f, scale = 1.0f;
    const char *rel = NULL;
    struct json_object *v;
    int err;

    set_place(ld, "%s.gltf", prefix);
    if (!(v = member(obj, "gltf")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_string(ld, v, 4096, &rel)))
        return err;
    if ((v = member(obj, "scale"))) {
        set_place(ld, "%s.scale", prefix);
        if ((err = get_ranged(ld, v, 0.0, true, 1e6, &scale)))
            return err;
    }
    if ((v = member(obj, "yaw"))) {
        set_place(ld, "%s.yaw", prefix);
        if ((err = get_ranged(ld, v, -3600.0, false, 3600.0, &yaw)))
            return err;
    }
    if ((v = member(obj, position_key))) {
        set_place(ld, "%s.%s", prefix, position_key);
        if ((err = get_vector(ld, v, 3, 1e7, position)))
            return err;
    }
    set_place(ld, "%s.gltf", prefix);
    struct imported_file *f;
    if ((err = get_file(ld, rel, &f)))
        return err;
    uint64_t added = 0;
    for (uint32_t k = 0; k < f->scene->instance_count; k++)
        added += f->scene->meshes[f->scene->instances[k].mesh].primitive_count;
    if ((ld->instances += added) > MAX_INSTANCES)
        return fail(ld, TW_ERR_LIMIT, "the tileset would hold more than %u instances",
                    MAX_INSTANCES);
    float placement[12];
    tw_gltf_placement(position, yaw, scale, placement);
    err = tw_gltf_place(f->scene, &f->binding, ld->ts, proto, placement);
    if (err)
        return fail(ld, err, "cannot place \"%.256s\": %s", rel, tw_error_to_str(err));
    return TW_OK;
}

/* ---- the document ------------------------------------------------------------------ */

static int read_prototype(struct loader *ld, const struct json_object *p, uint32_t index)
{
    static const char *const single_keys[] = {"name", "weight", "gltf", "scale", "yaw",
                                              "offset", NULL};
    static const char *const composed_keys[] = {"name", "weight", "objects", NULL};
    static const char *const object_keys[] = {"gltf", "position", "yaw", "scale", NULL};
    char prefix[64];
    snprintf(prefix, sizeof(prefix), "prototypes[%u]", index);
    struct json_object *v;
    int err;

    set_place(ld, "%s", prefix);
    if (!json_object_is_type(p, json_type_object))
        return fail(ld, TW_ERR_FORMAT, "must be an object, not %s", json_type_phrase(p));
    const bool single = member(p, "gltf") != NULL;
    const bool composed = member(p, "objects") != NULL;
    if (single == composed)
        return fail(ld, TW_ERR_FORMAT, "must have either \"gltf\" or \"objects\"%s",
                    single ? ", not both" : "");
    if ((err = check_keys(ld, p, prefix, single ? single_keys : composed_keys)))
        return err;

    const char *name = NULL;
    set_place(ld, "%s.name", prefix);
    if (!(v = member(p, "name")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_string(ld, v, sizeof(ld->ts->prototypes[0].name) - 1, &name)))
        return err;
    if (!name[0])
        return fail(ld, TW_ERR_FORMAT, "is empty");
    for (uint32_t k = 0; k < ld->ts->prototype_count; k++)
        if (strcmp(ld->ts->prototypes[k].name, name) == 0)
            return fail(ld, TW_ERR_FORMAT, "\"%s\" is already the name of prototypes[%u]", name,
                        k);
    float weight = 1.0f;
    if ((v = member(p, "weight"))) {
        set_place(ld, "%s.weight", prefix);
        if ((err = get_ranged(ld, v, 0.0, true, 1e6, &weight)))
            return err;
    }
    const int proto = tw_tileset_add_prototype(ld->ts, name, weight);
    if (proto < 0) {
        set_place(ld, "%s", prefix);
        return fail(ld, proto, "cannot add the prototype: %s", tw_error_to_str(proto));
    }
    if (single)
        return place_object(ld, (uint32_t)proto, p, prefix, "offset");

    set_place(ld, "%s.objects", prefix);
    v = member(p, "objects");
    if (!json_object_is_type(v, json_type_array))
        return fail(ld, TW_ERR_FORMAT, "must be an array, not %s", json_type_phrase(v));
    const size_t n = json_object_array_length(v);
    if (n < 1 || n > MAX_OBJECTS)
        return fail(ld, TW_ERR_FORMAT, "has %zu objects, not 1 to %d", n, MAX_OBJECTS);
    for (size_t k = 0; k < n; k++) {
        const struct json_object *o = json_object_array_get_idx(v, k);
        char object_prefix[96];
        snprintf(object_prefix, sizeof(object_prefix), "%s.objects[%zu]", prefix, k);
        set_place(ld, "%s", object_prefix);
        if (!json_object_is_type(o, json_type_object))
            return fail(ld, TW_ERR_FORMAT, "must be an object, not %s", json_type_phrase(o));
        if ((err = check_keys(ld, o, object_prefix, object_keys)) ||
            (err = place_object(ld, (uint32_t)proto, o, object_prefix, "position")))
            return err;
    }
    return TW_OK;
}

/* The default tileset name: the manifest's file name without ".json". */
static void default_name(const char *name, char *out, size_t size)
{
    const char *slash = strrchr(name, '/');
    const char *base = slash ? slash + 1 : name;
    size_t n = strlen(base);
    if (n > 5 && strcmp(base + n - 5, ".json") == 0)
        n -= 5;
    if (n >= size)
        n = size - 1;
    memcpy(out, base, n);
    out[n] = '\0';
}

static int read_manifest(struct loader *ld, const struct json_object *root)
{
    static const char *const keys[] = {"name", "footprint", "max_cluster_triangles",
                                       "prototypes", NULL};
    struct json_object *v;
    int err;

    set_place(ld, "%s", "");
    if (!json_object_is_type(root, json_type_object))
        return fail(ld, TW_ERR_FORMAT, "the manifest must be a JSON object, not %s",
                    json_type_phrase(root));
    if ((err = check_keys(ld, root, "(top level)", keys)))
        return err;

    char name[64];
    default_name(ld->name, name, sizeof(name));
    if ((v = member(root, "name"))) {
        const char *given;
        set_place(ld, "name");
        if ((err = get_string(ld, v, sizeof(name) - 1, &given)))
            return err;
        snprintf(name, sizeof(name), "%s", given);
    }

    float footprint[2];
    set_place(ld, "footprint");
    if (!(v = member(root, "footprint")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_vector(ld, v, 2, 1e5, footprint)))
        return err;
    if (!(footprint[0] > 0.0f) || !(footprint[1] > 0.0f))
        return fail(ld, TW_ERR_FORMAT, "both sides must be positive");

    uint32_t cluster = ld->settings.max_cluster_triangles;
    if ((v = member(root, "max_cluster_triangles"))) {
        set_place(ld, "max_cluster_triangles");
        if (!json_object_is_type(v, json_type_int))
            return fail(ld, TW_ERR_FORMAT, "must be an integer, not %s", json_type_phrase(v));
        const int64_t c = json_object_get_int64(v);
        if (c < 0 || c > (1 << 24))
            return fail(ld, TW_ERR_FORMAT, "%lld is not in [0, %d]", (long long)c, 1 << 24);
        if (!cluster)
            cluster = (uint32_t)c;
    } else if (!cluster) {
        cluster = DEFAULT_CLUSTER_TRIANGLES;
    }

    set_place(ld, "prototypes");
    if (!(v = member(root, "prototypes")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if (!json_object_is_type(v, json_type_array))
        return fail(ld, TW_ERR_FORMAT, "must be an array, not %s", json_type_phrase(v));
    const size_t n = json_object_array_length(v);
    if (n < 1 || n > MAX_PROTOTYPES)
        return fail(ld, TW_ERR_FORMAT, "has %zu prototypes, not 1 to %d", n, MAX_PROTOTYPES);

    set_place(ld, "%s", "");
    if ((err = tw_tileset_create(name, footprint[0], footprint[1], &ld->ts)))
        return fail(ld, err, "cannot create the tileset: %s", tw_error_to_str(err));
    for (size_t k = 0; k < n; k++)
        if ((err = read_prototype(ld, json_object_array_get_idx(v, k), (uint32_t)k)))
            return err;
    set_place(ld, "%s", "");
    if ((err = tw_tileset_finish(ld->ts, cluster)))
        return fail(ld, err, "cannot finish the tileset: %s", tw_error_to_str(err));
    return TW_OK;
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

static int parse(struct loader *ld, const char *text, size_t size, struct tw_tileset **out)
{
    struct json_tokener *tok = NULL;
    struct json_object *root = NULL;
    int err = TW_OK;

    set_place(ld, "%s", "");
    if (size > MAX_MANIFEST_BYTES) {
        err = fail(ld, TW_ERR_LIMIT, "is %zu bytes, more than the limit of %u", size,
                   MAX_MANIFEST_BYTES);
        goto out;
    }
    if (memchr(text, '\0', size)) {
        err = fail(ld, TW_ERR_FORMAT, "contains a NUL byte: not a JSON text");
        goto out;
    }
    tok = json_tokener_new_ex(MAX_JSON_DEPTH);
    if (!tok) {
        err = fail(ld, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    json_tokener_set_flags(tok, JSON_TOKENER_STRICT);
    root = json_tokener_parse_ex(tok, text, (int)size);
    enum json_tokener_error jerr = json_tokener_get_error(tok);
    if (jerr == json_tokener_continue) {
        err = fail(ld, TW_ERR_FORMAT, "JSON ends early (an unclosed string, array or object)");
        goto out;
    }
    if (!root || jerr != json_tokener_success) {
        unsigned line, column;
        line_column(text, json_tokener_get_parse_end(tok), &line, &column);
        err = fail(ld, TW_ERR_FORMAT, "line %u, column %u: invalid JSON: %s", line, column,
                   json_tokener_error_desc(jerr));
        goto out;
    }
    for (size_t k = json_tokener_get_parse_end(tok); k < size; k++) {
        if (text[k] != ' ' && text[k] != '\t' && text[k] != '\n' && text[k] != '\r') {
            unsigned line, column;
            line_column(text, k, &line, &column);
            err = fail(ld, TW_ERR_FORMAT, "line %u, column %u: text after the JSON value", line,
                       column);
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

static int finish_loader(struct loader *ld, int err)
{
    for (uint32_t k = 0; k < ld->file_count; k++) {
        free(ld->files[k].path);
        tw_gltf_scene_destroy(ld->files[k].scene);
    }
    free(ld->files);
    tw_tileset_destroy(ld->ts);
    if (err)
        tw_log_printf(ld->log, TW_LOG_ERROR, "%s: %s", ld->name,
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
    struct loader ld = {0};
    ld.name = name ? name : "(manifest)";
    ld.base_dir = base_dir ? base_dir : ".";
    ld.log = log;
    resolve_settings(settings, &ld.settings);
    if (!text && size)
        return finish_loader(&ld, fail(&ld, TW_ERR_INVALID, "no text (caller's bug)"));
    return finish_loader(&ld, parse(&ld, text ? text : "", size, out));
}

int tw_tilesets_load_manifest_ex(const char *path, const struct tw_manifest_settings *settings,
                                 const struct tw_log *log, struct tw_tileset **out)
{
    if (!out || !path) {
        tw_log_printf(log, TW_LOG_ERROR, "manifest: %s is NULL (caller's bug)",
                      out ? "path" : "out");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    struct loader ld = {0};
    ld.name = path;
    ld.log = log;
    resolve_settings(settings, &ld.settings);
    char *text = NULL, *dir = NULL;
    int err = TW_OK;
    FILE *f = fopen(path, "rb");
    if (!f) {
        err = fail(&ld, TW_ERR_IO, "cannot open: %s", strerror(errno));
        goto out;
    }
    text = malloc(MAX_MANIFEST_BYTES + 1);
    dir = tw_confined_path_dirname(path);
    if (!text || !dir) {
        err = fail(&ld, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    const size_t size = fread(text, 1, MAX_MANIFEST_BYTES + 1, f);
    if (ferror(f)) {
        err = fail(&ld, TW_ERR_IO, "cannot read: %s", strerror(errno));
        goto out;
    }
    ld.base_dir = dir;
    err = parse(&ld, text, size, out);
out:
    if (f)
        fclose(f);
    free(text);
    free(dir);
    return finish_loader(&ld, err);
}

int tw_tilesets_load_manifest(const char *path, const struct tw_log *log,
                              struct tw_tileset **out)
{
    return tw_tilesets_load_manifest_ex(path, NULL, log, out);
}
