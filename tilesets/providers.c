/* The registry of built-in tile providers (tilesets.h, DESIGN.md §12):
 * names, creation by name, and what every provider shares. The generators
 * are city-gen.c and forest-gen.c. */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <string.h>

const char *const tw_tilesets_provider_names[] = {"city-gen", "forest-gen", NULL};

bool tw_tilesets_is_provider(const char *name)
{
    if (!name)
        return false;
    for (const char *const *n = tw_tilesets_provider_names; *n; n++)
        if (strcmp(*n, name) == 0)
            return true;
    return false;
}

int tw_tilesets_provider_create(const char *name, uint64_t seed,
                                uint32_t max_cluster_triangles, const struct tw_log *log,
                                struct tw_tilesets_provider **out)
{
    if (!tw_procedural_out_given(out, log, "provider"))
        return TW_ERR_INVALID;
    *out = NULL;
    if (!name) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: provider: no provider name given");
        return TW_ERR_INVALID;
    }
    if (strcmp(name, "city-gen") == 0) {
        struct tw_city_settings settings = {0};
        settings.max_cluster_triangles = max_cluster_triangles;
        return tw_tilesets_provider_create_city(seed, &settings, log, out);
    }
    if (strcmp(name, "forest-gen") == 0) {
        struct tw_forest_settings settings = {0};
        settings.max_cluster_triangles = max_cluster_triangles;
        return tw_tilesets_provider_create_forest(seed, &settings, log, out);
    }
    tw_log_printf(log, TW_LOG_ERROR,
                  "tilesets: provider: unknown provider \"%s\" (known: city-gen, forest-gen)",
                  name);
    return TW_ERR_INVALID;
}

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
