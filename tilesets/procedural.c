/* What the procedural generators share (procedural.h), and what every
 * built-in provider shares (tilesets-private.h). */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <math.h>

bool tw_procedural_out_given(const void *out, const struct tw_log *log, const char *who)
{
    if (!out)
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: %s: out is NULL (caller's bug)", who);
    return out != NULL;
}

bool tw_procedural_prototypes_valid(uint32_t prototypes, const struct tw_log *log,
                                    const char *who)
{
    if (prototypes < 8 || prototypes > 256) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: prototypes = %u, must be in [8, 256] (caller's settings)",
                      who, (unsigned)prototypes);
        return false;
    }
    return true;
}

bool tw_procedural_in_range(float value, float lo, float hi, const char *field, const char *unit,
                            const struct tw_log *log, const char *who)
{
    if (!isfinite(value) || !(value >= lo) || !(value <= hi)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: %s = %g%s, must be in [%g, %g] (caller's settings)", who,
                      field, (double)value, unit, (double)lo, (double)hi);
        return false;
    }
    return true;
}

int tw_procedural_hand_over(struct tw_tileset *ts, int err, uint32_t max_cluster_triangles,
                            const struct tw_log *log, const char *who, struct tw_tileset **out)
{
    if (!err)
        err = tw_tileset_finish(ts, max_cluster_triangles);
    if (!err) {
        *out = ts;
        return TW_OK;
    }
    tw_log_printf(log, TW_LOG_ERROR, "tilesets: %s: generation failed: %s", who,
                  tw_error_to_str(err));
    tw_tileset_destroy(ts);
    return err;
}

/* ---- built-in providers ------------------------------------------------------------- */

const struct tw_tile_provider *tw_tilesets_provider_get(const struct tw_tilesets_provider *p)
{
    return p ? &p->provider : NULL;
}

void tw_tilesets_provider_destroy(struct tw_tilesets_provider *p)
{
    if (p)
        p->destroy(p);
}

int tw_provider_check_tile(const struct tw_tile_provider *provider, const struct tw_log *log,
                           struct tw_cell cell, const struct tw_tileset *ts)
{
    const char *reason = !ts                          ? "no tileset"
                         : ts->finished               ? "the tileset is finished"
                         : ts->prototype_count != 0   ? "the tileset already has a prototype"
                         : ts->footprint[0] != provider->footprint[0] ||
                                 ts->footprint[1] != provider->footprint[1]
                             ? "the tileset's footprint is not the provider's"
                             : NULL;
    if (!reason)
        return TW_OK;
    tw_log_printf(log, TW_LOG_ERROR, "tilesets: %s: cell (%lld, %lld): %s (caller's bug)",
                  provider->name, (long long)cell.i, (long long)cell.j, reason);
    return TW_ERR_INVALID;
}

void tw_provider_init(struct tw_tile_provider *p, const char *name, float footprint, float top,
                      int (*generate)(void *user, struct tw_cell cell, struct tw_tileset *ts),
                      void *user, uint32_t max_cluster_triangles)
{
    p->name = name;
    p->footprint[0] = p->footprint[1] = footprint;
    p->bound.min[0] = p->bound.min[1] = p->bound.min[2] = 0.0f;
    p->bound.max[0] = p->bound.max[2] = footprint;
    p->bound.max[1] = top;
    p->shared = NULL;
    p->content = NULL;
    p->generate = generate;
    p->user = user;
    p->max_cluster_triangles = max_cluster_triangles;
}
