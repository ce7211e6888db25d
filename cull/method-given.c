/*
 * A given set (TW_CULL_GIVEN): draws exactly the clusters of
 * tw_cull_driver_give(), one draw call per run of clusters of one tile,
 * with no test of its own. What the world's oracles and its frames of a
 * fixed set draw with.
 */
#include "cull/cull-private.h"

#include <stdlib.h>

struct given_method {
    struct tw_cull_method_base base;
    const struct tw_drawn_cluster *set;     /* borrowed until the frame is done */
    size_t count;
    struct tw_cull_clusters clusters;
};

static const struct tw_cull_method_ops given_ops;

static struct given_method *given_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &given_ops);
    return (struct given_method *)m;
}

static void given_give(struct tw_cull_method_base *m, const struct tw_drawn_cluster *set,
                       size_t count)
{
    struct given_method *gm = given_from_method(m);
    gm->set = set;
    gm->count = count;
}

static int given_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    struct given_method *gm = given_from_method(m);
    const struct tw_drawn_cluster *set = gm->set;
    const size_t count = gm->count;
    size_t k = 0;
    while (k < count) {
        const struct tw_cell cell = set[k].cell;
        const uint32_t content = set[k].prototype;
        size_t end = k;
        while (end < count && set[end].cell.i == cell.i && set[end].cell.j == cell.j &&
               set[end].prototype == content)
            end++;
        uint32_t *out = tw_cull_frame_clusters(fr, &gm->clusters, end - k);
        if (!out)
            return fr->err;
        for (size_t c = k; c < end; c++)
            out[c - k] = set[c].cluster;
        float offset[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], offset);
        fr->be->draw(fr->be->ctx, cell, content, offset, out, (uint32_t)(end - k));
        fr->st->tiles_visible++;
        k = end;
    }
    return TW_OK;
}

static size_t given_bytes(const struct tw_cull_method_base *m)
{
    const struct given_method *gm = (const struct given_method *)m;
    return sizeof(*gm) + sizeof(*gm->clusters.index) * gm->clusters.cap;
}

static void given_destroy(struct tw_cull_method_base *m)
{
    struct given_method *gm = given_from_method(m);
    free(gm->clusters.index);
    free(gm);
}

static const struct tw_cull_method_ops given_ops = {
    .destroy = given_destroy,
    .frame = given_frame,
    .bytes = given_bytes,
    .give = given_give,
};

int tw_cull_given_method_create(const struct tw_cull_driver_settings *s,
                                struct tw_cull_method_base **out)
{
    (void)s;
    struct given_method *gm = calloc(1, sizeof(*gm));
    if (!gm)
        return TW_ERR_NOMEM;
    gm->base.impl = &given_ops;
    *out = &gm->base;
    return TW_OK;
}
