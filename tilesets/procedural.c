/* What the procedural generators share (procedural.h). */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"

#include <math.h>

void tw_icosphere_each(uint32_t n, tw_icosphere_triangle_fn triangle, void *user)
{
#define PHI 1.6180339887f
    static const float ico[12][3] = {
        {-1, PHI, 0}, {1, PHI, 0}, {-1, -PHI, 0}, {1, -PHI, 0}, {0, -1, PHI}, {0, 1, PHI},
        {0, -1, -PHI}, {0, 1, -PHI}, {PHI, 0, -1}, {PHI, 0, 1}, {-PHI, 0, -1}, {-PHI, 0, 1},
    };
#undef PHI
    static const uint8_t faces[20][3] = {
        {0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
        {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
        {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1},
    };
    for (int f = 0; f < 20; f++) {
        const float *a = ico[faces[f][0]], *b = ico[faces[f][1]], *c = ico[faces[f][2]];
        for (uint32_t i = 0; i < n; i++) {
            for (uint32_t j = 0; i + j < n; j++) {
                /* Two triangles per grid cell, one where the cell is cut by
                 * the face's edge. */
                const uint32_t corners[2][3][2] = {
                    {{i, j}, {i + 1, j}, {i, j + 1}},
                    {{i + 1, j}, {i + 1, j + 1}, {i, j + 1}},
                };
                for (int t = 0; t < (i + j + 1 < n ? 2 : 1); t++) {
                    float v[3][3], len[3];
                    for (int k = 0; k < 3; k++) {
                        const uint32_t ci = corners[t][k][0], cj = corners[t][k][1];
                        for (int d = 0; d < 3; d++)
                            v[k][d] = a[d] + (b[d] - a[d]) * (float)ci / (float)n +
                                      (c[d] - a[d]) * (float)cj / (float)n;
                        len[k] = sqrtf(v[k][0] * v[k][0] + v[k][1] * v[k][1] + v[k][2] * v[k][2]);
                    }
                    triangle(user, (const float(*)[3])v, len);
                }
            }
        }
    }
}

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
