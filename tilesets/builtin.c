/* The registry of built-in tilesets (tilesets.h). */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tileworld/tilesets.h"

#include <string.h>

const char *const tw_tilesets_builtin_names[] = {"city", "forest", "hybrid", NULL};

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
    if (strcmp(name, "city") == 0) {
        struct tw_city_settings settings = {0};
        settings.max_cluster_triangles = max_cluster_triangles;
        return tw_tilesets_city(seed, &settings, log, out);
    }
    if (strcmp(name, "forest") == 0) {
        struct tw_forest_settings settings = {0};
        settings.max_cluster_triangles = max_cluster_triangles;
        return tw_tilesets_forest(seed, &settings, log, out);
    }
    if (strcmp(name, "hybrid") == 0) {
        struct tw_hybrid_settings settings = {0};
        settings.max_cluster_triangles = max_cluster_triangles;
        return tw_tilesets_hybrid(seed, &settings, log, out);
    }
    char shown[256];
    tw_log_escape(name, shown, sizeof(shown));
    const size_t n = strlen(name);
    if (strchr(name, '/') || (n > 5 && strcmp(name + n - 5, ".json") == 0))
        tw_log_printf(log, TW_LOG_ERROR,
                      "tileset \"%s\": a file name, not a built-in tileset (city, forest, "
                      "hybrid): a manifest file is loaded by its path",
                      shown);
    else
        tw_log_printf(log, TW_LOG_ERROR,
                      "tileset \"%s\": no such built-in tileset (city, forest, hybrid)", shown);
    return TW_ERR_INVALID;
}
