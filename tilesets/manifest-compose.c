/* Tileset manifests, the tileset composed from the values manifest.c read
 * (manifest-private.h): each glTF file imported and bound once, however it
 * is named (by its identity), and placed within what a frame can afford;
 * prototype names unique; the tileset finished, and what it refuses named. */
#include "tiles/tiles-internal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/manifest-private.h"

#define MAX_FILES 1024
#define MAX_INSTANCES (1u << 20)
/* Triangles placed: a prototype draws at most the glTF limit
 * (settings.gltf.max_triangles, 10 M by default), the tileset's prototypes
 * together at most PLACED_TRIANGLES_FACTOR times it (finishing the tileset
 * visits each). */
#define PLACED_TRIANGLES_FACTOR 10ull

struct tw_manifest_imported_file {
    dev_t dev;                     /* the file's identity: the key */
    ino_t ino;
    struct tw_gltf_scene *scene;
    struct tw_gltf_binding binding;
    uint64_t instances;            /* what one placement adds: tileset instances */
};

/* A name as written in the manifest and the file it opened. */
struct tw_manifest_named_file {
    char *rel;
    uint32_t file;
};

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

static void table_finish(struct tw_manifest_index_table *t)
{
    free(t->slots);
    free(t->hashes);
    memset(t, 0, sizeof(*t));
}

/* Finds the entry of hash for which same(user, index) holds, or inserts
 * index (*found = index). Constant time on average. */
static int table_lookup(struct tw_manifest_index_table *t, uint64_t hash,
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
    const struct tw_manifest_loader *ld = user;
    const struct tw_manifest_imported_file *probe = &ld->files[ld->file_count];
    return ld->files[index].dev == probe->dev && ld->files[index].ino == probe->ino;
}

static bool same_name(const void *user, uint32_t index)
{
    const struct tw_manifest_loader *ld = user;
    return ld->names[index].rel && strcmp(ld->names[index].rel, ld->names[ld->name_count].rel) == 0;
}

/* The imported file named rel (at the current place), importing and binding
 * it the first time. A name seen before costs a table lookup; a new name
 * is opened beneath the manifest's folder, and the file it opens is
 * imported unless another name opened it already. */
static int get_file(struct tw_manifest_loader *ld, const char *rel,
                    struct tw_manifest_imported_file **out)
{
    char shown[256];
    tw_log_escape(rel, shown, sizeof(shown));
    /* Names first: the same text always names the same file. */
    if (ld->name_count == ld->name_cap) {
        const uint32_t cap = ld->name_cap ? 2 * ld->name_cap : 16;
        struct tw_manifest_named_file *grown = realloc(ld->names, sizeof(*grown) * (cap + 1));
        if (!grown)
            return tw_manifest_fail(ld, TW_ERR_NOMEM, "out of memory");
        ld->names = grown;
        ld->name_cap = cap;
    }
    /* The probe sits one past the last entry until it is kept. */
    ld->names[ld->name_count].rel = (char *)rel;
    uint32_t found;
    int err = table_lookup(&ld->name_table, hash_string(rel), same_name, ld, ld->name_count,
                           &found);
    if (err)
        return tw_manifest_fail(ld, err, "out of memory");
    if (found != ld->name_count) {
        if (ld->names[found].file == UINT32_MAX)
            return tw_manifest_fail(ld, TW_ERR_STATE, "\"%s\" could not be opened before", shown);
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
        return tw_manifest_fail(ld, TW_ERR_NOMEM, "out of memory");
    }
    memcpy(copy, rel, n);
    struct tw_manifest_named_file *named = &ld->names[ld->name_count++];
    named->rel = copy;
    named->file = UINT32_MAX;

    int fd = -1, dir_fd = -1;
    const char *reason = NULL;
    err = tw_confined_open(ld->dir_fd, rel, TW_CONFINED_AUTO, &fd, &reason);
    if (err)
        return tw_manifest_fail(ld, err, "\"%s\" %s", shown,
                                reason ? reason : tw_error_to_str(err));
    struct stat st;
    if (fstat(fd, &st) != 0) {
        close(fd);
        return tw_manifest_fail(ld, TW_ERR_IO, "\"%s\" cannot be read: %s", shown, strerror(errno));
    }
    struct tw_manifest_imported_file *grown =
        realloc(ld->files, sizeof(*grown) * (ld->file_count + 1));
    if (!grown) {
        close(fd);
        return tw_manifest_fail(ld, TW_ERR_NOMEM, "out of memory");
    }
    ld->files = grown;
    struct tw_manifest_imported_file *f = &ld->files[ld->file_count];
    memset(f, 0, sizeof(*f));
    f->dev = st.st_dev;
    f->ino = st.st_ino;
    const uint64_t key[2] = {(uint64_t)st.st_dev, (uint64_t)st.st_ino};
    err = table_lookup(&ld->file_table, hash_bytes(key, sizeof(key), 0xcbf29ce484222325ull),
                       same_file, ld, ld->file_count, &found);
    if (err) {
        close(fd);
        return tw_manifest_fail(ld, err, "out of memory");
    }
    if (found != ld->file_count) {
        close(fd);
        named->file = found;
        *out = &ld->files[found];
        return TW_OK;
    }
    if (ld->file_count >= MAX_FILES) {
        close(fd);
        return tw_manifest_fail(ld, TW_ERR_LIMIT, "more than %d distinct glTF files", MAX_FILES);
    }
    ld->file_count++;
    named->file = ld->file_count - 1;

    /* The glTF file's own external files resolve in its folder, beneath
     * the manifest's. */
    err = tw_confined_open_parent(ld->dir_fd, rel, TW_CONFINED_AUTO, &dir_fd, &reason);
    if (err) {
        close(fd);
        return tw_manifest_fail(ld, err, "\"%s\" %s", shown,
                                reason ? reason : tw_error_to_str(err));
    }
    struct captured_log cap = {ld->log, ""};
    const struct tw_log capture_log = {capture, &cap};
    err = tw_gltf_import_fd(fd, dir_fd, rel, &ld->settings.gltf, &ld->shared, &capture_log,
                            &f->scene);
    close(fd);
    close(dir_fd);
    if (err)
        return tw_manifest_fail(ld, err, "%s", cap.last[0] ? cap.last : tw_error_to_str(err));
    /* Bound the memory that many large files could take together. */
    ld->file_bytes += f->scene->vertex_count * 24 + f->scene->unique_triangles * 12;
    if (ld->file_bytes > 4 * ld->settings.gltf.max_file_bytes)
        return tw_manifest_fail(ld, TW_ERR_LIMIT,
                                "the manifest's glTF files hold more than %llu bytes of geometry",
                                (unsigned long long)(4 * ld->settings.gltf.max_file_bytes));
    for (uint32_t k = 0; k < f->scene->instance_count; k++)
        f->instances += f->scene->meshes[f->scene->instances[k].mesh].primitive_count;
    err = tw_gltf_bind(f->scene, ld->ts, &f->binding);
    if (err)
        return tw_manifest_fail(ld, err, "cannot add \"%s\" to the tileset: %s", shown,
                                tw_error_to_str(err));
    *out = f;
    return TW_OK;
}

/* Places file rel (at prefix.gltf) in prototype proto: scaled, turned by
 * yaw and moved to position. */
int tw_manifest_place(struct tw_manifest_loader *ld, uint32_t proto, const char *prefix,
                      const char *rel, const float position[3], float yaw, float scale)
{
    char shown[256];
    int err;

    tw_manifest_set_place(ld, "%s.gltf", prefix);
    struct tw_manifest_imported_file *f = NULL;
    if ((err = get_file(ld, rel, &f)))
        return err;
    float placement[12];
    tw_gltf_placement(position, yaw, scale, placement);
    /* What a frame can afford (tiles.h): the placed scene stays within reach
     * of its tile and spans a few footprints at most. */
    tw_manifest_set_place(ld, "%s", prefix);
    const struct tw_box placed = tw_box_transform(&f->scene->bounds, placement);
    const float *footprint = ld->ts->footprint;
    for (int a = 0; a < 3; a++) {
        if (!(placed.min[a] >= -TW_TILES_MAX_COORD) || !(placed.max[a] <= TW_TILES_MAX_COORD))
            return tw_manifest_fail(
                ld, TW_ERR_LIMIT,
                "the placed scene reaches %c = %g m, beyond +-%g m of the tile (scale "
                "%g, position [%g, %g, %g])",
                "xyz"[a], !(placed.min[a] >= -TW_TILES_MAX_COORD) ? placed.min[a] : placed.max[a],
                (double)TW_TILES_MAX_COORD, scale, position[0], position[1], position[2]);
        if (a == 1)
            continue;
        const double span = (double)placed.max[a] - placed.min[a];
        const double most = (double)TW_TILES_MAX_SPAN * footprint[a / 2];
        if (span > most)
            return tw_manifest_fail(
                ld, TW_ERR_LIMIT,
                "the placed scene spans %g m along %c, more than %g footprints (%g m): "
                "every frame would have to consider the cells it overhangs (scale %g)",
                span, "xyz"[a], (double)TW_TILES_MAX_SPAN, most, scale);
    }
    /* Counted before anything is placed: a file of many triangles placed
     * many times multiplies what finishing the tileset and every frame cost. */
    tw_manifest_set_place(ld, "%s.gltf", prefix);
    if ((ld->instances += f->instances) > MAX_INSTANCES)
        return tw_manifest_fail(ld, TW_ERR_LIMIT, "the tileset would hold more than %u instances",
                                MAX_INSTANCES);
    ld->prototype_triangles += f->scene->triangle_count;
    ld->triangles += f->scene->triangle_count;
    if (ld->prototype_triangles > ld->settings.gltf.max_triangles)
        return tw_manifest_fail(
            ld, TW_ERR_LIMIT,
            "placing \"%s\" (%llu triangles) here makes the prototype draw %llu "
            "triangles, more than the limit of %llu",
            tw_log_escape(rel, shown, sizeof(shown)), (unsigned long long)f->scene->triangle_count,
            (unsigned long long)ld->prototype_triangles,
            (unsigned long long)ld->settings.gltf.max_triangles);
    if (ld->triangles > PLACED_TRIANGLES_FACTOR * ld->settings.gltf.max_triangles)
        return tw_manifest_fail(
            ld, TW_ERR_LIMIT,
            "placing \"%s\" (%llu triangles) here makes the tileset's prototypes draw "
            "%llu triangles together, more than the limit of %llu",
            tw_log_escape(rel, shown, sizeof(shown)), (unsigned long long)f->scene->triangle_count,
            (unsigned long long)ld->triangles,
            (unsigned long long)(PLACED_TRIANGLES_FACTOR * ld->settings.gltf.max_triangles));
    err = tw_gltf_place(f->scene, &f->binding, ld->ts, proto, placement);
    if (err) {
        return tw_manifest_fail(ld, err, "cannot place \"%s\": %s",
                                tw_log_escape(rel, shown, sizeof(shown)), tw_error_to_str(err));
    }
    return TW_OK;
}

static bool same_prototype_name(const void *user, uint32_t index)
{
    const struct tw_manifest_loader *ld = user;
    const struct tw_tileset *ts = ld->ts;
    return strcmp(ts->prototypes[index].name, ts->prototypes[ts->prototype_count - 1].name) == 0;
}

/* Adds prototype name (at prefix.name) to the tileset, its name unique. */
int tw_manifest_add_prototype(struct tw_manifest_loader *ld, const char *prefix, const char *name,
                              float weight, uint32_t *out)
{
    int err;
    const int proto = tw_tileset_add_prototype(ld->ts, name, weight);
    if (proto < 0) {
        tw_manifest_set_place(ld, "%s", prefix);
        return tw_manifest_fail(ld, proto, "cannot add the prototype: %s", tw_error_to_str(proto));
    }
    /* Unique names, in constant time each. */
    uint32_t found;
    if ((err = table_lookup(&ld->prototype_table, hash_string(name), same_prototype_name, ld,
                            (uint32_t)proto, &found)))
        return tw_manifest_fail(ld, err, "out of memory");
    if (found != (uint32_t)proto) {
        char shown[64];
        tw_manifest_set_place(ld, "%s.name", prefix);
        return tw_manifest_fail(ld, TW_ERR_FORMAT, "\"%s\" is already the name of prototypes[%u]",
                                tw_log_escape(name, shown, sizeof(shown)), found);
    }
    *out = (uint32_t)proto;
    return TW_OK;
}

/* The cells a frame at the default view distance would consider. */
static int check_reach(struct tw_manifest_loader *ld, const struct tw_box *box, const char *what)
{
    const float *fp = ld->ts->footprint;
    const double cells = tw_tiles_cells_in_reach(box, fp[0], fp[1],
                                                 TW_TILES_REFERENCE_VIEW_DISTANCE);
    if (cells <= TW_TILES_MAX_CELLS_IN_VIEW)
        return TW_OK;
    return tw_manifest_fail(
        ld, TW_ERR_LIMIT,
        "%s on %g x %g m tiles: a frame at the default view distance of %g m would "
        "consider about %.3g cells, more than the limit of %u (tiles of %.3g m or more "
        "fit, or content that spans fewer of them)",
        what, fp[0], fp[1], (double)TW_TILES_REFERENCE_VIEW_DISTANCE, cells,
        TW_TILES_MAX_CELLS_IN_VIEW,
        2.0 * TW_TILES_REFERENCE_VIEW_DISTANCE / (sqrt((double)TW_TILES_MAX_CELLS_IN_VIEW) - 2.0));
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

int tw_manifest_create_tileset(struct tw_manifest_loader *ld, const char *name,
                               const float footprint[2])
{
    int err;
    tw_manifest_set_place(ld, "%s", "");
    if ((err = tw_tileset_create(name, footprint[0], footprint[1], &ld->ts)))
        return tw_manifest_fail(ld, err, "cannot create the tileset: %s", tw_error_to_str(err));
    /* The footprint alone bounds the cells in view (tiles of 1 cm: 10^10). */
    tw_manifest_set_place(ld, "footprint");
    const struct tw_box point = {{0, 0, 0}, {0, 0, 0}};
    return check_reach(ld, &point, "tiles");
}

int tw_manifest_finish_tileset(struct tw_manifest_loader *ld, uint32_t cluster)
{
    int err;
    tw_manifest_set_place(ld, "%s", "");
    if ((err = tw_tileset_finish(ld->ts, cluster))) {
        if (err == TW_ERR_LIMIT) {
            const uint32_t w = widest_prototype(ld->ts);
            tw_manifest_set_place(ld, "prototypes[%u]", w);
            return tw_manifest_fail(ld, err,
                                    "spans more than %g footprints: every frame would have to "
                                    "consider the cells it overhangs",
                                    (double)TW_TILES_MAX_SPAN);
        }
        const int empty = prototype_without_area(ld->ts);
        if (err == TW_ERR_INVALID && empty >= 0) {
            char shown[64];
            tw_manifest_set_place(ld, "prototypes[%d]", empty);
            return tw_manifest_fail(
                ld, TW_ERR_FORMAT,
                "every triangle of \"%s\" has no area (collinear or coincident "
                "corners): it would draw nothing",
                tw_log_escape(ld->ts->prototypes[empty].name, shown, sizeof(shown)));
        }
        return tw_manifest_fail(ld, err, "cannot finish the tileset: %s", tw_error_to_str(err));
    }
    tw_manifest_set_place(ld, "prototypes[%u]", widest_prototype(ld->ts));
    return check_reach(ld, &ld->ts->common_box, "the tileset's content");
}

void tw_manifest_compose_finish(struct tw_manifest_loader *ld)
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
}
