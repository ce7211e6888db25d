/* The registry of the built-in tilesets and tile providers (tilesets.h,
 * DESIGN.md §10, §12): one table that names each, says whether it is a
 * fixed tileset or a provider, and makes it with default settings but
 * max_cluster_triangles. The generators know nothing of it. */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <stddef.h>
#include <stdio.h>
#include <string.h>

static int make_city(uint64_t seed, uint32_t max_cluster_triangles, const struct tw_log *log,
                     struct tw_tileset **out)
{
    struct tw_city_settings settings = {0};
    settings.max_cluster_triangles = max_cluster_triangles;
    return tw_tilesets_city(seed, &settings, log, out);
}

static int make_forest(uint64_t seed, uint32_t max_cluster_triangles, const struct tw_log *log,
                       struct tw_tileset **out)
{
    struct tw_forest_settings settings = {0};
    settings.max_cluster_triangles = max_cluster_triangles;
    return tw_tilesets_forest(seed, &settings, log, out);
}

static int make_hybrid(uint64_t seed, uint32_t max_cluster_triangles, const struct tw_log *log,
                       struct tw_tileset **out)
{
    struct tw_hybrid_settings settings = {0};
    settings.max_cluster_triangles = max_cluster_triangles;
    return tw_tilesets_hybrid(seed, &settings, log, out);
}

static int make_city_gen(uint64_t seed, uint32_t max_cluster_triangles, const struct tw_log *log,
                         struct tw_tilesets_provider **out)
{
    struct tw_city_settings settings = {0};
    settings.max_cluster_triangles = max_cluster_triangles;
    return tw_tilesets_provider_create_city(seed, &settings, log, out);
}

static int make_forest_gen(uint64_t seed, uint32_t max_cluster_triangles,
                           const struct tw_log *log, struct tw_tilesets_provider **out)
{
    struct tw_forest_settings settings = {0};
    settings.max_cluster_triangles = max_cluster_triangles;
    return tw_tilesets_provider_create_forest(seed, &settings, log, out);
}

enum entry_kind {
    ENTRY_TILESET,      /* a fixed tileset: tw_tilesets_builtin() */
    ENTRY_PROVIDER,     /* a tile provider: tw_tilesets_provider_create() */
};

static const struct entry {
    const char *name;
    enum entry_kind kind;
    bool streets;       /* the city's streets, default settings, along every tile border */
    union {
        int (*tileset)(uint64_t seed, uint32_t max_cluster_triangles, const struct tw_log *log,
                       struct tw_tileset **out);
        int (*provider)(uint64_t seed, uint32_t max_cluster_triangles,
                        const struct tw_log *log, struct tw_tilesets_provider **out);
    } make;
} registry[] = {
    {"city", ENTRY_TILESET, true, {.tileset = make_city}},
    {"forest", ENTRY_TILESET, false, {.tileset = make_forest}},
    {"hybrid", ENTRY_TILESET, true, {.tileset = make_hybrid}},
    {"city-gen", ENTRY_PROVIDER, true, {.provider = make_city_gen}},
    {"forest-gen", ENTRY_PROVIDER, false, {.provider = make_forest_gen}},
};

enum { ENTRY_COUNT = sizeof(registry) / sizeof(registry[0]) };

/* The table's names of each kind, in its order (tests/test-providers.c
 * checks the two against it). */
const char *const tw_tilesets_builtin_names[] = {"city", "forest", "hybrid", NULL};
const char *const tw_tilesets_provider_names[] = {"city-gen", "forest-gen", NULL};

static const struct entry *find(const char *name, enum entry_kind kind)
{
    for (size_t k = 0; k < ENTRY_COUNT; k++)
        if (registry[k].kind == kind && strcmp(registry[k].name, name) == 0)
            return &registry[k];
    return NULL;
}

/* The names of kind as "a, b, c", for messages. */
static const char *names_of(enum entry_kind kind, char *out, size_t size)
{
    size_t used = 0;
    out[0] = '\0';
    for (size_t k = 0; k < ENTRY_COUNT && used < size; k++)
        if (registry[k].kind == kind)
            used += (size_t)snprintf(out + used, size - used, "%s%s", used ? ", " : "",
                                     registry[k].name);
    return out;
}

int tw_tilesets_builtin(const char *name, uint64_t seed, uint32_t max_cluster_triangles,
                        const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "builtin"))
        return TW_ERR_INVALID;
    *out = NULL;
    if (!name) {
        tw_log_printf(log, TW_LOG_ERROR, "built-in tileset: no name given (caller's bug)");
        return TW_ERR_INVALID;
    }
    const struct entry *e = find(name, ENTRY_TILESET);
    if (e)
        return e->make.tileset(seed, max_cluster_triangles, log, out);
    char shown[256], known[128];
    tw_log_escape(name, shown, sizeof(shown));
    names_of(ENTRY_TILESET, known, sizeof(known));
    const size_t n = strlen(name);
    if (strchr(name, '/') || (n > 5 && strcmp(name + n - 5, ".json") == 0))
        tw_log_printf(log, TW_LOG_ERROR,
                      "tileset \"%s\": a file name, not a built-in tileset (%s): a manifest "
                      "file is loaded by its path",
                      shown, known);
    else
        tw_log_printf(log, TW_LOG_ERROR, "tileset \"%s\": no such built-in tileset (%s)", shown,
                      known);
    return TW_ERR_INVALID;
}

bool tw_tilesets_is_provider(const char *name)
{
    return name && find(name, ENTRY_PROVIDER);
}

bool tw_tilesets_streets(const char *name, struct tw_traffic_settings *streets,
                         char *names, size_t names_size)
{
    bool found = false;
    size_t used = 0;
    if (names_size)
        names[0] = '\0';
    for (size_t k = 0; k < ENTRY_COUNT; k++) {
        if (!registry[k].streets)
            continue;
        found |= name && strcmp(registry[k].name, name) == 0;
        if (used < names_size)
            used += (size_t)snprintf(names + used, names_size - used, "%s%s", used ? ", " : "",
                                     registry[k].name);
    }
    if (found && streets) {
        struct tw_city_settings city;
        tw_tilesets_city_default_settings(&city);
        streets->footprint = city.footprint;
        streets->street_width = city.street_width;
    }
    return found;
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
    const struct entry *e = find(name, ENTRY_PROVIDER);
    if (e)
        return e->make.provider(seed, max_cluster_triangles, log, out);
    char known[128];
    names_of(ENTRY_PROVIDER, known, sizeof(known));
    tw_log_printf(log, TW_LOG_ERROR, "tilesets: provider: unknown provider \"%s\" (known: %s)",
                  name, known);
    return TW_ERR_INVALID;
}
