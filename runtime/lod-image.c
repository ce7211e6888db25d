/*
 * What levels of detail change in the image (DESIGN §17): under --verify,
 * each frame is also drawn at full detail (untimed, before the method's
 * frame), and the method's image is compared with it, pixel by pixel:
 * colours that differ, and how far apart the surfaces they show lie. A
 * measure separate from missed pixels, which compare a method with the
 * oracle at the same levels.
 */
#include "runtime/world-private.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A pixel differs when a channel differs by more than this (of 255): the
 * rounding of two draws of the same surface is not a difference. */
#define LOD_COLOUR_TOLERANCE 2

void tw_lod_image_finish(struct tw_lod_image *li)
{
    tw_cull_driver_destroy(li->vfc);
    free(li->rgb);
    free(li->depth);
    free(li->frame_rgb);
    free(li->frame_depth);
    memset(li, 0, sizeof(*li));
}

static int init(struct tw_world *w)
{
    struct tw_lod_image *li = &w->lod_image;
    if (li->vfc)
        return TW_OK;
    const size_t npix = (size_t)w->s.width * w->s.height;
    li->rgb = malloc(3 * npix);
    li->frame_rgb = malloc(3 * npix);
    li->depth = malloc(sizeof(float) * npix);
    li->frame_depth = malloc(sizeof(float) * npix);
    if (!li->rgb || !li->frame_rgb || !li->depth || !li->frame_depth)
        return TW_ERR_NOMEM;
    /* Every tile in view, whatever the policy; not counted as drawn. */
    const struct tw_cull_driver_settings vfc = {
        .method = TW_CULL_VFC,
        .source_flags = TW_TILE_SOURCE_WAIT | TW_TILE_SOURCE_QUIET,
        .evict_after_frames = w->s.evict_after_frames,
    };
    return tw_cull_driver_create(&vfc, &li->vfc);
}

int tw_lod_image_full_pass(struct tw_world *w, const struct tw_view *v)
{
    int err = init(w);
    if (err)
        return err;
    struct tw_lod_image *li = &w->lod_image;
    w->lod_full = true;
    tw_renderer_begin_frame(w->renderer, v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    struct tw_cull_frame_stats cs = {0};
    struct tw_view fv = *v;
    fv.frame = ++li->frame;
    /* Cells only: a block's proxy is a level of detail too. */
    struct tw_cull_grid cells_only = w->grid;
    cells_only.levels.count = 0;
    err = tw_cull_driver_frame(li->vfc, &fv, &cells_only, &be, &w->cur->cells, &cs);
    tw_renderer_end_frame(w->renderer);
    w->lod_full = false;
    if (err)
        return err;
    err = tw_renderer_read_rgb(w->renderer, li->rgb);
    if (!err)
        tw_renderer_read_depth(w->renderer, li->depth);
    return err;
}

static bool same(const uint8_t *a, const uint8_t *b)
{
    for (int c = 0; c < 3; c++)
        if (abs((int)a[c] - (int)b[c]) > LOD_COLOUR_TOLERANCE)
            return false;
    return true;
}

/* Whether pixel (x, y) of a has its colour in b at (x, y) or a neighbour
 * of it (8 around). */
static bool near_match(const uint8_t *a, const uint8_t *b, uint32_t width, uint32_t height,
                       uint32_t x, uint32_t y)
{
    const uint8_t *p = a + 3 * ((size_t)y * width + x);
    for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
            const int64_t qx = (int64_t)x + dx, qy = (int64_t)y + dy;
            if (qx < 0 || qy < 0 || qx >= width || qy >= height)
                continue;
            if (same(p, b + 3 * ((size_t)qy * width + (size_t)qx)))
                return true;
        }
    return false;
}

int tw_lod_image_compare(struct tw_world *w, const struct tw_view *v, struct tw_frame_stats *st)
{
    struct tw_lod_image *li = &w->lod_image;
    int err = tw_renderer_read_rgb(w->renderer, li->frame_rgb);
    if (err)
        return err;
    tw_renderer_read_depth(w->renderer, li->frame_depth);
    const bool reversed = tw_renderer_reversed_z(w->renderer);
    const float sky = reversed ? 0.0f : 1.0f;
    const uint32_t width = w->s.width, height = w->s.height;
    uint64_t differ = 0, exact = 0, both = 0;
    double depth_sum = 0.0;
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            const size_t k = (size_t)y * width + x;
            if (same(li->rgb + 3 * k, li->frame_rgb + 3 * k))
                continue;
            exact++;
            /* A difference a shift of one pixel explains is within the
             * bound: a level's edge may lie up to max_screen_error away. */
            if (near_match(li->rgb, li->frame_rgb, width, height, x, y) &&
                near_match(li->frame_rgb, li->rgb, width, height, x, y))
                continue;
            differ++;
            /* How far the surface moved, where both images show one (depth
             * rows are bottom first). */
            const size_t kd = (size_t)(height - 1 - y) * width + x;
            const float za = li->depth[kd], zb = li->frame_depth[kd];
            if (za == sky || zb == sky)
                continue;
            both++;
            depth_sum += fabs(tw_eye_distance(za, v->near_plane, v->far_plane, reversed) -
                              tw_eye_distance(zb, v->near_plane, v->far_plane, reversed));
        }
    st->lod_pixels = differ;
    st->lod_pixels_exact = exact;
    st->lod_depth_m = both ? depth_sum / (double)both : 0.0;
    return TW_OK;
}
