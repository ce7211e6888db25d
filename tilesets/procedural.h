/*
 * Private to tilesets/: what the procedural generators (city, forest,
 * hybrid and the providers over them) share beyond the mesh builder and
 * the shapes: the checks of their callers' arguments and settings, and the
 * hand-over of a generated tileset. procedural.c also holds what every
 * built-in provider shares (tilesets-private.h). Not installed, not public
 * API.
 */
#ifndef TW_TILESETS_PROCEDURAL_H
#define TW_TILESETS_PROCEDURAL_H

#include <stdbool.h>
#include <stdint.h>

#include "tileworld/tiles.h"

/* x clamped to [lo, hi]. */
static inline float tw_clampf(float x, float lo, float hi)
{
    return x < lo ? lo : x > hi ? hi : x;
}

/* False, with a message naming who ("city", "forest-gen", ...), when a
 * caller's out pointer is NULL: the caller's bug. */
bool tw_procedural_out_given(const void *out, const struct tw_log *log, const char *who);

/* The checks that every generator's settings share; false with a message
 * naming who and the field (a caller's settings) when they fail. */
bool tw_procedural_prototypes_valid(uint32_t prototypes, const struct tw_log *log,
                                    const char *who);
/* lo <= value <= hi and finite; unit ("" or " m") follows the value in the
 * message. */
bool tw_procedural_in_range(float value, float lo, float hi, const char *field, const char *unit,
                            const struct tw_log *log, const char *who);

/* The end of a generation into ts (NULL if its creation failed): when err
 * is 0, finishes ts with clusters of max_cluster_triangles and hands it to
 * the caller in *out; otherwise, or when finishing fails, logs that who's
 * generation failed and destroys ts. Returns err, or the finish's error. */
int tw_procedural_hand_over(struct tw_tileset *ts, int err, uint32_t max_cluster_triangles,
                            const struct tw_log *log, const char *who, struct tw_tileset **out);

#endif
