/*
 * vfc (DESIGN §6): every cell in view, front to back, each drawing the
 * clusters of its tile that meet the frustum within the view distance, in
 * one call. No query, no state kept: the baseline of what a frame costs
 * without occlusion culling. Also the local method of tilequery.
 */
#include "cull/cull-private.h"

#include <stdlib.h>

struct vfc_method {
    struct tw_cull_method_base base;
    struct tw_cull_clusters clusters;
};

static const struct tw_cull_method_ops vfc_ops;

static struct vfc_method *vfc_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &vfc_ops);
    return (struct vfc_method *)m;
}

bool tw_cull_vfc_draw(struct tw_cull_frame *fr, struct tw_cull_clusters *c, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3])
{
    uint32_t *out = tw_cull_frame_clusters(fr, c, tile->proto->cluster_count);
    if (!out)
        return false;
    const uint32_t n = tw_cull_vfc_tile(fr->v, tile->proto, offset, out);
    if (n > 0)
        fr->be->draw(fr->be->ctx, cell, tile->content, offset, out, n);
    return n > 0;
}

static bool draw_tile(struct tw_cull_method_base *m, struct tw_cull_frame *fr, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3])
{
    return tw_cull_vfc_draw(fr, &vfc_from_method(m)->clusters, cell, tile, offset);
}

static int vfc_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    return tw_cull_frame_each_cell(m, fr, draw_tile);
}

static size_t vfc_bytes(const struct tw_cull_method_base *m)
{
    const struct vfc_method *vm = (const struct vfc_method *)m;
    return sizeof(*vm) + sizeof(*vm->clusters.index) * vm->clusters.cap;
}

static void vfc_destroy(struct tw_cull_method_base *m)
{
    struct vfc_method *vm = vfc_from_method(m);
    free(vm->clusters.index);
    free(vm);
}

static const struct tw_cull_method_ops vfc_ops = {
    .destroy = vfc_destroy,
    .frame = vfc_frame,
    .bytes = vfc_bytes,
};

int tw_cull_vfc_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out)
{
    (void)s;
    struct vfc_method *vm = calloc(1, sizeof(*vm));
    if (!vm)
        return TW_ERR_NOMEM;
    vm->base.impl = &vfc_ops;
    *out = &vm->base;
    return TW_OK;
}
