/*
 * tilesets: producers of tilesets (DESIGN.md §10): the procedural generators
 * and, later, glTF import and manifests. Everything here returns a finished
 * struct tw_tileset (tiles/tiles.h) that the caller owns.
 */
#ifndef TW_TILESETS_H
#define TW_TILESETS_H

#include <stdint.h>

#include "tiles/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Settings of the procedural city. Zero-initialisable: zero fields take the
 * defaults of tw_tilesets_city_default_settings(). */
struct tw_city_settings {
    uint32_t prototypes;        /* how many blocks; default 12, at least 8 */
    float footprint;            /* tile side in metres (square tiles); default 80 */
    float street_width;         /* full street width; half lies in each tile; default 14 */
    float max_height;           /* tallest building, metres; default 90 */
    uint32_t max_cluster_triangles; /* passed to tw_tileset_finish(); default 2048 */
};

void tw_tilesets_city_default_settings(struct tw_city_settings *s);

/* Generates the city tileset for seed: blocks of buildings of varied
 * footprint and height with window and ledge geometry, streets along every
 * tile border (a camera at local x = 0 or z = 0, eye height, stands on a
 * street). Deterministic: the same seed and settings give the same tileset,
 * bit for bit. settings may be NULL. The caller owns *out. */
int tw_tilesets_city(uint64_t seed, const struct tw_city_settings *settings,
                     const struct tw_log *log, struct tw_tileset **out);

/* Names of the built-in tilesets, NULL-terminated. */
extern const char *const tw_tilesets_builtin_names[];

/* Builds the built-in tileset called name ("city", ...) with default
 * settings but max_cluster_triangles (0: the generator's default). Returns
 * TW_ERR_INVALID for an unknown name. */
int tw_tilesets_builtin(const char *name, uint64_t seed,
                        uint32_t max_cluster_triangles,
                        const struct tw_log *log, struct tw_tileset **out);

#ifdef __cplusplus
}
#endif

#endif
