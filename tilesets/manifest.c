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
 * it in the tileset, and at most MAX_INSTANCES instances. */
#include "tiles/tiles-internal.h"
#include "tileworld/tilesets.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <sys/stat.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/tilesets-private.h"

#define MAX_MANIFEST_BYTES (16u << 20)
#define MAX_JSON_DEPTH 64
#define MAX_JSON_CONTAINERS (1u << 18)
#define MAX_PROTOTYPES 1024
#define MAX_OBJECTS 65536
#define MAX_FILES 1024
#define MAX_INSTANCES (1u << 20)
/* Triangles placed: a prototype draws at most the glTF limit
 * (settings.gltf.max_triangles, 10 M by default), the tileset's prototypes
 * together at most PLACED_TRIANGLES_FACTOR times it (finishing the tileset
 * visits each). */
#define PLACED_TRIANGLES_FACTOR 10ull
#define DEFAULT_CLUSTER_TRIANGLES 2048
#define MIN_FACTOR 1e-6                /* weights and scales */
#define MAX_FACTOR 1e6

struct imported_file {
    dev_t dev;                     /* the file's identity: the key */
    ino_t ino;
    struct tw_gltf_scene *scene;
    struct tw_gltf_binding binding;
    uint64_t instances;            /* what one placement adds: tileset instances */
};

/* A name as written in the manifest and the file it opened. */
struct named_file {
    char *rel;
    uint32_t file;
};

/* An open-addressing table of indices into an array that the caller owns
 * and compares (UINT32_MAX: an empty slot); grows at half load. */
struct index_table {
    uint32_t *slots;
    uint64_t *hashes;
    uint32_t size, count;
};

struct loader {
    const char *name;              /* the manifest, for messages */
    char shown[256];               /* name, escaped */
    int dir_fd;                    /* the manifest's folder */
    struct tw_manifest_settings settings;
    const struct tw_log *log;
    struct tw_tileset *ts;
    struct imported_file *files;
    uint32_t file_count;
    struct index_table file_table; /* by identity */
    struct named_file *names;      /* every distinct name seen */
    uint32_t name_count, name_cap;
    struct index_table name_table;
    struct index_table prototype_table; /* prototype names */
    uint64_t file_bytes;           /* summed sizes of the imported files */
    struct tw_gltf_shared shared;  /* bytes read and decoded by all the imports together */
    uint64_t instances;            /* placed so far */
    uint64_t triangles;            /* placed so far */
    uint64_t prototype_triangles;  /* placed so far in the current prototype */
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

/* ---- index tables ------------------------------------------------------------------ */

static uint64_t hash_bytes(const void *data, size_t n, uint64_t h)
{
    const uint8_t *p = data;
    for (size_t k = 0; k < n; k++)
        h = (h ^ p[k]) * 0x100000001b3ull;
    return h;
}

static uint64_t hash_string(const char *s)
{
    return hash_bytes(s, strlen(s), 0xcbf29ce484222325ull);
}

static void table_finish(struct index_table *t)
{
    free(t->slots);
    free(t->hashes);
    memset(t, 0, sizeof(*t));
}

/* Finds the entry of hash for which same(user, index) holds, or inserts
 * index (*found = index). Constant time on average. */
static int table_lookup(struct index_table *t, uint64_t hash,
                        bool (*same)(const void *user, uint32_t index), const void *user,
                        uint32_t index, uint32_t *found)
{
    if (2 * ((uint64_t)t->count + 1) > t->size) {
        const uint32_t size = t->size ? 2 * t->size : 64;
        uint32_t *slots = malloc(sizeof(*slots) * size);
        uint64_t *hashes = malloc(sizeof(*hashes) * size);
        if (!slots || !hashes) {
            free(slots);
            free(hashes);
            return TW_ERR_NOMEM;
        }
        for (uint32_t k = 0; k < size; k++)
            slots[k] = UINT32_MAX;
        for (uint32_t k = 0; k < t->size; k++) {
            if (t->slots[k] == UINT32_MAX)
                continue;
            uint32_t h = (uint32_t)t->hashes[k] & (size - 1);
            while (slots[h] != UINT32_MAX)
                h = (h + 1) & (size - 1);
            slots[h] = t->slots[k];
            hashes[h] = t->hashes[k];
        }
        free(t->slots);
        free(t->hashes);
        t->slots = slots;
        t->hashes = hashes;
        t->size = size;
    }
    uint32_t h = (uint32_t)hash & (t->size - 1);
    while (t->slots[h] != UINT32_MAX) {
        if (t->hashes[h] == hash && same(user, t->slots[h])) {
            *found = t->slots[h];
            return TW_OK;
        }
        h = (h + 1) & (t->size - 1);
    }
    t->slots[h] = index;
    t->hashes[h] = hash;
    t->count++;
    *found = index;
    return TW_OK;
}

/* Text quoted from the manifest, escaped and cut to fit a message. */
static const char *quote(const char *text, char *out, size_t size)
{
    return tw_log_escape(text, out, size);
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
            char shown[96];
            set_place(ld, "%s", prefix);
            return fail(ld, TW_ERR_FORMAT, "unknown key \"%s\" (known: %s)",
                        quote(key, shown, sizeof(shown)), list);
        }
    }
    return TW_OK;
}

static int get_number(struct loader *ld, const struct json_object *o, double *out)
{
    *out = 0.0;     /* set on every path: optimising GCC cannot tell fail() from success */
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

/* A string without control characters (C0, DEL, C1): a name that is
 * printed later (tileworld info, reports) must not drive a terminal. */
static int check_printable(struct loader *ld, const char *s)
{
    char shown[64];
    for (size_t k = 0; s[k]; k++) {
        const unsigned char c = (unsigned char)s[k];
        const bool c1 = c == 0xc2 && (unsigned char)s[k + 1] >= 0x80 &&
                        (unsigned char)s[k + 1] <= 0x9f;
        if (c < 0x20 || c == 0x7f || c1)
            return fail(ld, TW_ERR_FORMAT, "\"%s\" contains a control character at byte %zu",
                        quote(s, shown, sizeof(shown)), k);
    }
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

static bool same_file(const void *user, uint32_t index)
{
    const struct loader *ld = user;
    const struct imported_file *probe = &ld->files[ld->file_count];
    return ld->files[index].dev == probe->dev && ld->files[index].ino == probe->ino;
}

static bool same_name(const void *user, uint32_t index)
{
    const struct loader *ld = user;
    return ld->names[index].rel && strcmp(ld->names[index].rel, ld->names[ld->name_count].rel) == 0;
}

/* The imported file named rel (at the current place), importing and binding
 * it the first time. A name seen before costs a table lookup; a new name
 * is opened beneath the manifest's folder, and the file it opens is
 * imported unless another name opened it already. */
static int get_file(struct loader *ld, const char *rel, struct imported_file **out)
{
    char shown[256];
    quote(rel, shown, sizeof(shown));
    /* Names first: the same text always names the same file. */
    if (ld->name_count == ld->name_cap) {
        const uint32_t cap = ld->name_cap ? 2 * ld->name_cap : 16;
        struct named_file *grown = realloc(ld->names, sizeof(*grown) * (cap + 1));
        if (!grown)
            return fail(ld, TW_ERR_NOMEM, "out of memory");
        ld->names = grown;
        ld->name_cap = cap;
    }
    /* The probe sits one past the last entry until it is kept. */
    ld->names[ld->name_count].rel = (char *)rel;
    uint32_t found;
    int err = table_lookup(&ld->name_table, hash_string(rel), same_name, ld, ld->name_count,
                           &found);
    if (err)
        return fail(ld, err, "out of memory");
    if (found != ld->name_count) {
        if (ld->names[found].file == UINT32_MAX)
            return fail(ld, TW_ERR_STATE, "\"%s\" could not be opened before", shown);
        *out = &ld->files[ld->names[found].file];
        return TW_OK;
    }
    const size_t n = strlen(rel) + 1;
    char *copy = malloc(n);
    if (!copy) {
        /* The table holds the entry now: keep it valid (a name that
         * matches nothing). */
        ld->names[ld->name_count].rel = NULL;
        ld->names[ld->name_count].file = UINT32_MAX;
        ld->name_count++;
        return fail(ld, TW_ERR_NOMEM, "out of memory");
    }
    memcpy(copy, rel, n);
    struct named_file *named = &ld->names[ld->name_count++];
    named->rel = copy;
    named->file = UINT32_MAX;

    int fd = -1, dir_fd = -1;
    const char *reason = NULL;
    err = tw_confined_open(ld->dir_fd, rel, TW_CONFINED_AUTO, &fd, &reason);
    if (err)
        return fail(ld, err, "\"%s\" %s", shown, reason ? reason : tw_error_to_str(err));
    struct stat st;
    if (fstat(fd, &st) != 0) {
        close(fd);
        return fail(ld, TW_ERR_IO, "\"%s\" cannot be read: %s", shown, strerror(errno));
    }
    struct imported_file *grown = realloc(ld->files, sizeof(*grown) * (ld->file_count + 1));
    if (!grown) {
        close(fd);
        return fail(ld, TW_ERR_NOMEM, "out of memory");
    }
    ld->files = grown;
    struct imported_file *f = &ld->files[ld->file_count];
    memset(f, 0, sizeof(*f));
    f->dev = st.st_dev;
    f->ino = st.st_ino;
    const uint64_t key[2] = {(uint64_t)st.st_dev, (uint64_t)st.st_ino};
    err = table_lookup(&ld->file_table, hash_bytes(key, sizeof(key), 0xcbf29ce484222325ull),
                       same_file, ld, ld->file_count, &found);
    if (err) {
        close(fd);
        return fail(ld, err, "out of memory");
    }
    if (found != ld->file_count) {
        close(fd);
        named->file = found;
        *out = &ld->files[found];
        return TW_OK;
    }
    if (ld->file_count >= MAX_FILES) {
        close(fd);
        return fail(ld, TW_ERR_LIMIT, "more than %d distinct glTF files", MAX_FILES);
    }
    ld->file_count++;
    named->file = ld->file_count - 1;

    /* The glTF file's own external files resolve in its folder, beneath
     * the manifest's. */
    err = tw_confined_open_parent(ld->dir_fd, rel, TW_CONFINED_AUTO, &dir_fd, &reason);
    if (err) {
        close(fd);
        return fail(ld, err, "\"%s\" %s", shown, reason ? reason : tw_error_to_str(err));
    }
    struct captured_log cap = {ld->log, ""};
    const struct tw_log capture_log = {capture, &cap};
    err = tw_gltf_import_fd(fd, dir_fd, rel, &ld->settings.gltf, &ld->shared, &capture_log,
                            &f->scene);
    close(fd);
    close(dir_fd);
    if (err)
        return fail(ld, err, "%s", cap.last[0] ? cap.last : tw_error_to_str(err));
    /* Bound the memory that many large files could take together. */
    ld->file_bytes += f->scene->vertex_count * 24 + f->scene->unique_triangles * 12;
    if (ld->file_bytes > 4 * ld->settings.gltf.max_file_bytes)
        return fail(ld, TW_ERR_LIMIT,
                    "the manifest's glTF files hold more than %llu bytes of geometry",
                    (unsigned long long)(4 * ld->settings.gltf.max_file_bytes));
    for (uint32_t k = 0; k < f->scene->instance_count; k++)
        f->instances += f->scene->meshes[f->scene->instances[k].mesh].primitive_count;
    err = tw_gltf_bind(f->scene, ld->ts, &f->binding);
    if (err)
        return fail(ld, err, "cannot add \"%s\" to the tileset: %s", shown,
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
    char shown[256];
    int err;

    set_place(ld, "%s.gltf", prefix);
    if (!(v = member(obj, "gltf")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_string(ld, v, 4096, &rel)))
        return err;
    if ((v = member(obj, "scale"))) {
        set_place(ld, "%s.scale", prefix);
        if ((err = get_ranged(ld, v, MIN_FACTOR, false, MAX_FACTOR, &scale)))
            return err;
    }
    if ((v = member(obj, "yaw"))) {
        set_place(ld, "%s.yaw", prefix);
        if ((err = get_ranged(ld, v, -3600.0, false, 3600.0, &yaw)))
            return err;
    }
    if ((v = member(obj, position_key))) {
        set_place(ld, "%s.%s", prefix, position_key);
        if ((err = get_vector(ld, v, 3, TW_TILES_MAX_COORD, position)))
            return err;
    }
    set_place(ld, "%s.gltf", prefix);
    struct imported_file *f = NULL;
    if ((err = get_file(ld, rel, &f)))
        return err;
    float placement[12];
    tw_gltf_placement(position, yaw, scale, placement);
    /* What a frame can afford (tiles.h): the placed scene stays within reach
     * of its tile and spans a few footprints at most. */
    set_place(ld, "%s", prefix);
    const struct tw_box placed = tw_box_transform(&f->scene->bounds, placement);
    const float *footprint = ld->ts->footprint;
    for (int a = 0; a < 3; a++) {
        if (!(placed.min[a] >= -TW_TILES_MAX_COORD) || !(placed.max[a] <= TW_TILES_MAX_COORD))
            return fail(ld, TW_ERR_LIMIT,
                        "the placed scene reaches %c = %g m, beyond +-%g m of the tile (scale "
                        "%g, position [%g, %g, %g])",
                        "xyz"[a], !(placed.min[a] >= -TW_TILES_MAX_COORD) ? placed.min[a]
                                                                         : placed.max[a],
                        (double)TW_TILES_MAX_COORD, scale, position[0], position[1],
                        position[2]);
        if (a == 1)
            continue;
        const double span = (double)placed.max[a] - placed.min[a];
        const double most = (double)TW_TILES_MAX_SPAN * footprint[a / 2];
        if (span > most)
            return fail(ld, TW_ERR_LIMIT,
                        "the placed scene spans %g m along %c, more than %g footprints (%g m): "
                        "every frame would have to consider the cells it overhangs (scale %g)",
                        span, "xyz"[a], (double)TW_TILES_MAX_SPAN, most, scale);
    }
    /* Counted before anything is placed: a file of many triangles placed
     * many times multiplies what finishing the tileset and every frame cost. */
    set_place(ld, "%s.gltf", prefix);
    if ((ld->instances += f->instances) > MAX_INSTANCES)
        return fail(ld, TW_ERR_LIMIT, "the tileset would hold more than %u instances",
                    MAX_INSTANCES);
    ld->prototype_triangles += f->scene->triangle_count;
    ld->triangles += f->scene->triangle_count;
    if (ld->prototype_triangles > ld->settings.gltf.max_triangles)
        return fail(ld, TW_ERR_LIMIT,
                    "placing \"%s\" (%llu triangles) here makes the prototype draw %llu "
                    "triangles, more than the limit of %llu",
                    quote(rel, shown, sizeof(shown)),
                    (unsigned long long)f->scene->triangle_count,
                    (unsigned long long)ld->prototype_triangles,
                    (unsigned long long)ld->settings.gltf.max_triangles);
    if (ld->triangles > PLACED_TRIANGLES_FACTOR * ld->settings.gltf.max_triangles)
        return fail(ld, TW_ERR_LIMIT,
                    "placing \"%s\" (%llu triangles) here makes the tileset's prototypes draw "
                    "%llu triangles together, more than the limit of %llu",
                    quote(rel, shown, sizeof(shown)),
                    (unsigned long long)f->scene->triangle_count,
                    (unsigned long long)ld->triangles,
                    (unsigned long long)(PLACED_TRIANGLES_FACTOR *
                                         ld->settings.gltf.max_triangles));
    err = tw_gltf_place(f->scene, &f->binding, ld->ts, proto, placement);
    if (err) {
        return fail(ld, err, "cannot place \"%s\": %s", quote(rel, shown, sizeof(shown)),
                    tw_error_to_str(err));
    }
    return TW_OK;
}

/* ---- the document ------------------------------------------------------------------ */

static bool same_prototype_name(const void *user, uint32_t index)
{
    const struct loader *ld = user;
    const struct tw_tileset *ts = ld->ts;
    return strcmp(ts->prototypes[index].name, ts->prototypes[ts->prototype_count - 1].name) == 0;
}

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
    ld->prototype_triangles = 0;
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
    if ((err = check_printable(ld, name)))
        return err;
    float weight = 1.0f;
    if ((v = member(p, "weight"))) {
        set_place(ld, "%s.weight", prefix);
        if ((err = get_ranged(ld, v, MIN_FACTOR, false, MAX_FACTOR, &weight)))
            return err;
    }
    const int proto = tw_tileset_add_prototype(ld->ts, name, weight);
    if (proto < 0) {
        set_place(ld, "%s", prefix);
        return fail(ld, proto, "cannot add the prototype: %s", tw_error_to_str(proto));
    }
    /* Unique names, in constant time each. */
    uint32_t found;
    if ((err = table_lookup(&ld->prototype_table, hash_string(name), same_prototype_name, ld,
                            (uint32_t)proto, &found)))
        return fail(ld, err, "out of memory");
    if (found != (uint32_t)proto) {
        char shown[64];
        set_place(ld, "%s.name", prefix);
        return fail(ld, TW_ERR_FORMAT, "\"%s\" is already the name of prototypes[%u]",
                    quote(name, shown, sizeof(shown)), found);
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

/* The cells a frame at the default view distance would consider. */
static int check_reach(struct loader *ld, const struct tw_box *box, const char *what)
{
    const float *fp = ld->ts ? ld->ts->footprint : NULL;
    const double cells = tw_tiles_cells_in_reach(box, fp[0], fp[1],
                                                 TW_TILES_REFERENCE_VIEW_DISTANCE);
    if (cells <= TW_TILES_MAX_CELLS_IN_VIEW)
        return TW_OK;
    return fail(ld, TW_ERR_LIMIT,
                "%s on %g x %g m tiles: a frame at the default view distance of %g m would "
                "consider about %.3g cells, more than the limit of %u (tiles of %.3g m or more "
                "fit, or content that spans fewer of them)",
                what, fp[0], fp[1], (double)TW_TILES_REFERENCE_VIEW_DISTANCE, cells,
                TW_TILES_MAX_CELLS_IN_VIEW,
                2.0 * TW_TILES_REFERENCE_VIEW_DISTANCE /
                    (sqrt((double)TW_TILES_MAX_CELLS_IN_VIEW) - 2.0));
}

/* After tw_tileset_finish() refused the tileset's span, or the reach check
 * did: the prototype that spans the most footprints. */
static uint32_t widest_prototype(const struct tw_tileset *ts)
{
    uint32_t widest = 0;
    double most = -1.0;
    for (uint32_t k = 0; k < ts->prototype_count; k++) {
        const struct tw_box *b = &ts->prototypes[k].box;
        const double span = fmax(((double)b->max[0] - b->min[0]) / ts->footprint[0],
                                 ((double)b->max[2] - b->min[2]) / ts->footprint[1]);
        if (span > most) {
            most = span;
            widest = k;
        }
    }
    return widest;
}

/* After tw_tileset_finish() refused the tileset as invalid: the first
 * prototype of which every instance's mesh lost all its triangles to
 * tw_tileset_finish() (triangles without area are dropped), or -1. */
static int prototype_without_area(const struct tw_tileset *ts)
{
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        bool empty = proto->instance_count > 0;
        for (uint32_t k = 0; k < proto->instance_count && empty; k++)
            empty = ts->meshes[proto->instances[k].mesh].triangle_count == 0;
        if (empty)
            return (int)p;
    }
    return -1;
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
        if ((err = get_string(ld, v, sizeof(name) - 1, &given)) ||
            (err = check_printable(ld, given)))
            return err;
        snprintf(name, sizeof(name), "%s", given);
    }

    float footprint[2];
    set_place(ld, "footprint");
    if (!(v = member(root, "footprint")))
        return fail(ld, TW_ERR_FORMAT, "is missing");
    if ((err = get_vector(ld, v, 2, TW_TILES_MAX_COORD, footprint)))
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
    /* The footprint alone bounds the cells in view (tiles of 1 cm: 10^10). */
    set_place(ld, "footprint");
    const struct tw_box point = {{0, 0, 0}, {0, 0, 0}};
    if ((err = check_reach(ld, &point, "tiles")))
        return err;
    for (size_t k = 0; k < n; k++)
        if ((err = read_prototype(ld, json_object_array_get_idx(v, k), (uint32_t)k)))
            return err;
    set_place(ld, "%s", "");
    if ((err = tw_tileset_finish(ld->ts, cluster))) {
        if (err == TW_ERR_LIMIT) {
            const uint32_t w = widest_prototype(ld->ts);
            set_place(ld, "prototypes[%u]", w);
            return fail(ld, err, "spans more than %g footprints: every frame would have to "
                                 "consider the cells it overhangs",
                        (double)TW_TILES_MAX_SPAN);
        }
        const int empty = prototype_without_area(ld->ts);
        if (err == TW_ERR_INVALID && empty >= 0) {
            char shown[64];
            set_place(ld, "prototypes[%d]", empty);
            return fail(ld, TW_ERR_FORMAT,
                        "every triangle of \"%s\" has no area (collinear or coincident "
                        "corners): it would draw nothing",
                        quote(ld->ts->prototypes[empty].name, shown, sizeof(shown)));
        }
        return fail(ld, err, "cannot finish the tileset: %s", tw_error_to_str(err));
    }
    set_place(ld, "prototypes[%u]", widest_prototype(ld->ts));
    return check_reach(ld, &ld->ts->common_box, "the tileset's content");
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
    const char *nul = memchr(text, '\0', size);
    if (nul) {
        unsigned line, column;
        line_column(text, (size_t)(nul - text), &line, &column);
        err = fail(ld, TW_ERR_FORMAT, "line %u, column %u: a NUL byte: not a JSON text", line,
                   column);
        goto out;
    }
    const uint64_t containers = count_containers(text, size);
    if (containers > MAX_JSON_CONTAINERS) {
        err = fail(ld, TW_ERR_LIMIT, "holds %llu JSON objects and arrays, more than the limit "
                                     "of %u",
                   (unsigned long long)containers, MAX_JSON_CONTAINERS);
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

static void init_loader(struct loader *ld, const char *name,
                        const struct tw_manifest_settings *settings, const struct tw_log *log)
{
    memset(ld, 0, sizeof(*ld));
    ld->name = name;
    tw_log_escape(name, ld->shown, sizeof(ld->shown));
    ld->dir_fd = -1;
    ld->log = log;
    resolve_settings(settings, &ld->settings);
}

static int finish_loader(struct loader *ld, int err)
{
    for (uint32_t k = 0; k < ld->file_count; k++)
        tw_gltf_scene_destroy(ld->files[k].scene);
    free(ld->files);
    for (uint32_t k = 0; k < ld->name_count; k++)
        free(ld->names[k].rel);
    free(ld->names);
    table_finish(&ld->file_table);
    table_finish(&ld->name_table);
    table_finish(&ld->prototype_table);
    tw_gltf_shared_finish(&ld->shared);
    tw_tileset_destroy(ld->ts);
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
    struct loader ld;
    init_loader(&ld, name ? name : "(manifest)", settings, log);
    if (!text && size)
        return finish_loader(&ld, fail(&ld, TW_ERR_INVALID, "no text (caller's bug)"));
    ld.dir_fd = tw_confined_open_folder(base_dir ? base_dir : ".");
    if (ld.dir_fd < 0) {
        char shown[256];
        return finish_loader(&ld, fail(&ld, TW_ERR_IO, "the folder \"%s\" cannot be opened: %s",
                                       quote(base_dir ? base_dir : ".", shown, sizeof(shown)),
                                       strerror(errno)));
    }
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
    struct loader ld;
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
        return finish_loader(&ld, fail(&ld, err, "%s", why));
    ld.dir_fd = tw_confined_open_folder_of(path);
    if (ld.dir_fd < 0) {
        free(text);
        return finish_loader(&ld, fail(&ld, TW_ERR_IO, "its folder cannot be opened: %s",
                                       strerror(errno)));
    }
    err = parse(&ld, (const char *)text, size, out);
    free(text);
    return finish_loader(&ld, err);
}

int tw_tilesets_load_manifest(const char *path, const struct tw_log *log,
                              struct tw_tileset **out)
{
    return tw_tilesets_load_manifest_ex(path, NULL, log, out);
}
