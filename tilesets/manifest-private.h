/*
 * manifest-private.h: the manifest loader's insides, shared by its files;
 * private to tilesets/:
 *   manifest.c          the format, the JSON text and its values read and
 *                       checked, the entry points (tilesets.h)
 *   manifest-compose.c  the tileset composed from them: glTF files imported
 *                       once each, placed within what a frame can afford,
 *                       the tileset finished
 * A load is one struct tw_manifest_loader, used by one thread. The first
 * problem found ends the load: tw_manifest_fail() keeps its message.
 */
#ifndef TW_TILESETS_MANIFEST_PRIVATE_H
#define TW_TILESETS_MANIFEST_PRIVATE_H

#include <stdint.h>

#include "tilesets/tilesets-private.h"
#include "tileworld/tilesets.h"

/* An open-addressing table of indices into an array that the caller owns
 * and compares (UINT32_MAX: an empty slot); grows at half load. */
struct tw_manifest_index_table {
    uint32_t *slots;
    uint64_t *hashes;
    uint32_t size, count;
};

struct tw_manifest_imported_file;
struct tw_manifest_named_file;

/* One load: the manifest, its settings, the tileset being composed and the
 * files imported for it. */
struct tw_manifest_loader {
    const char *name;              /* the manifest, for messages */
    char shown[256];               /* name, escaped */
    int dir_fd;                    /* the manifest's folder */
    struct tw_manifest_settings settings;
    const struct tw_log *log;
    struct tw_tileset *ts;
    struct tw_manifest_imported_file *files;
    uint32_t file_count;
    struct tw_manifest_index_table file_table; /* by identity */
    struct tw_manifest_named_file *names;      /* every distinct name seen */
    uint32_t name_count, name_cap;
    struct tw_manifest_index_table name_table;
    struct tw_manifest_index_table prototype_table; /* prototype names */
    uint64_t file_bytes;           /* summed sizes of the imported files */
    struct tw_gltf_shared shared;  /* bytes read and decoded by all the imports together */
    uint64_t instances;            /* placed so far */
    uint64_t triangles;            /* placed so far */
    uint64_t prototype_triangles;  /* placed so far in the current prototype */
    char place[160];               /* JSON place of the value being read */
    char msg[1536];
};

/* ---- manifest.c ---- */

/* Records "<place>: <reason>" as the load's error, unless one is recorded
 * already; returns err. */
int tw_manifest_fail(struct tw_manifest_loader *ld, int err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Sets the JSON place that messages name. */
void tw_manifest_set_place(struct tw_manifest_loader *ld, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* ---- manifest-compose.c ---- */

/* Creates ld->ts, whose footprint must leave the cells in view bounded. */
int tw_manifest_create_tileset(struct tw_manifest_loader *ld, const char *name,
                               const float footprint[2]);
/* Adds prototype name (at prefix.name) to ld->ts; *out is its index. */
int tw_manifest_add_prototype(struct tw_manifest_loader *ld, const char *prefix, const char *name,
                              float weight, uint32_t *out);
/* Places the glTF file rel (at prefix.gltf) in prototype proto, importing it
 * the first time it is named. */
int tw_manifest_place(struct tw_manifest_loader *ld, uint32_t proto, const char *prefix,
                      const char *rel, const float position[3], float yaw, float scale);
/* Finishes ld->ts with clusters of cluster triangles. */
int tw_manifest_finish_tileset(struct tw_manifest_loader *ld, uint32_t cluster);
/* Frees what composing holds: the imported files, the tables, the shared
 * images and ld->ts unless it was handed out. */
void tw_manifest_compose_finish(struct tw_manifest_loader *ld);

#endif
