/*
 * Moving objects (README "Moving objects"; Kovalčík & Sochor, Seletsky):
 * the objects of a cell are kept in a prototype of their own (an instance
 * of its model's per object instance, a cluster per model cluster) with a
 * BVH over it, the cell's group. When a frame asks for a cell that has a
 * group, the world gives the culling a composite tile: the cell's tile
 * (its clusters first) joined to the group (its clusters after), one BVH
 * whose root has the tile's BVH on one side and the group's on the other.
 * The tile queries and CHC++ then treat the objects as any geometry of
 * the cell: their boxes are queried, what they draw occludes.
 *
 * Objects move between frames. A move within a cell refits the group's
 * BVH and the composites made of it (boxes only: the culling state of the
 * cell stays, keyed by the composite's key); objects that come or go, or a
 * BVH that refitting has worn down (its interior boxes grown to more than
 * TW_OBJECTS_SPREAD times their area at the build), give the group a new
 * BVH and its composites a new key: their culling state starts afresh.
 *
 * The common box that tile queries draw must hold every cell's content:
 * it is the provider's bound joined with every group's box (cell-local),
 * recomputed when objects move. A cell's objects are those whose position
 * lies in it; a model is at most a footprint from its origin, so the box
 * grows by at most a footprint each way.
 */
#include "runtime/world-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Rebuild a group's BVH when refitting has grown its spread (tw_bvh_spread)
 * to more than this many times its value at the build. */
#define TW_OBJECTS_SPREAD 1.5

/* Keys of the culling state of cells with objects: from here up, apart
 * from the keys of tiles (small numbers, with a level of detail in bits 28
 * and up) and TW_CULL_KEY_EMPTY. */
#define KEY_FIRST 0xC0000000u
#define KEY_LAST 0xFFFFFF00u

struct object {
    struct tw_object o;             /* its position normalised */
    uint32_t group;                 /* the group of its cell (live objects) */
    bool live;
};

struct group {
    struct tw_cell cell;
    uint32_t *objects;              /* ids, in cluster order */
    uint32_t count;
    size_t cap;
    struct tw_prototype proto;      /* instances and clusters of its objects, cell-local */
    size_t instance_cap, cluster_cap;
    struct tw_bvh *bvh;
    double spread;                  /* the BVH's at its build */
    uint32_t content;               /* the renderer's (UINT32_MAX: none yet) */
    uint32_t key;                   /* of a cell with no tile of its own */
    uint32_t version;               /* built afresh: composites made before are stale */
    uint32_t refits;                /* refitted: composites refit their joined BVH */
    bool rebuild, moved;
    bool live;
};

struct composite {
    /* The tile it joins, as tw_world_get_tile() gave it. */
    uint32_t tile_key, tile_content;
    const struct tw_prototype *tile_proto;
    const struct tw_bvh *tile_bvh;
    uint32_t version, refits;       /* of the group when made, refitted */
    struct tw_prototype proto;      /* the tile's clusters, then the group's */
    struct tw_bvh *bvh;
    uint32_t content, key;
    uint64_t used;                  /* the world's frame it was last given out in */
    struct composite *next;         /* the cell's others (another level of its tile) */
};

/* A cell keeps the composites of the tiles it was last given (levels of
 * detail: two views, or a frame and its full-detail pass, may each ask for
 * another), at most this many, none unused for more than two frames. */
#define COMPOSITES_PER_CELL 4

struct tw_objects {
    const struct tw_tileset *models;
    uint32_t model_content;         /* the renderer's content of model 0 */
    struct object *objects;
    size_t object_count, object_cap;
    uint32_t *free_objects;
    size_t free_object_count, free_object_cap;
    struct group **groups;          /* one allocation each: the renderer borrows their protos */
    size_t group_count, group_cap;
    uint32_t *free_groups;
    size_t free_group_count, free_group_cap;
    struct tw_cell_map *group_of;   /* cell -> group index */
    struct tw_cell_map *composite_of;   /* cell -> its struct composite list */
    uint32_t next_key;
    bool changed;                   /* since the last frame */
    /* Heap bytes (tw_objects_bytes), counted again only after something
     * that holds them changed: the budget asks several times a frame. */
    uint64_t bytes;
    bool bytes_known;
    /* The last frame's work. */
    uint32_t rebuilds;
    double ms;
};

/* ---- placement ------------------------------------------------------------------------- */

/* The object's transform, model-local -> cell-local (row-major 3x4). */
static void object_transform(const struct tw_object *o, float m[12])
{
    const double a = (double)o->yaw * (3.14159265358979323846 / 180.0);
    const float c = (float)cos(a), s = (float)sin(a);
    const float t[12] = {c, 0.0f, s, o->pos.local[0], 0.0f, 1.0f, 0.0f, o->pos.local[1],
                         -s, 0.0f, c, o->pos.local[2]};
    memcpy(m, t, sizeof(t));
}

/* a * b for affine 3x4 row-major matrices. */
static void compose(const float a[12], const float b[12], float out[12])
{
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 4; c++) {
            float v = a[r * 4 + 0] * b[0 * 4 + c] + a[r * 4 + 1] * b[1 * 4 + c] +
                      a[r * 4 + 2] * b[2 * 4 + c];
            if (c == 3)
                v += a[r * 4 + 3];
            out[r * 4 + c] = v;
        }
    }
}

/* The cell-local instances and cluster boxes of group g's object k (at
 * instance *in and cluster *cl), advancing both. */
static void place_object(const struct tw_objects *ob, struct group *g, const struct object *o,
                         uint32_t *in, uint32_t *cl)
{
    const struct tw_prototype *model = &ob->models->prototypes[o->o.model];
    float m[12];
    object_transform(&o->o, m);
    const uint32_t first = *in;
    for (uint32_t i = 0; i < model->instance_count; i++) {
        struct tw_instance *dst = &g->proto.instances[first + i];
        *dst = model->instances[i];
        compose(m, model->instances[i].transform, dst->transform);
        dst->box = tw_box_transform(&model->instances[i].box, m);
        if (dst->merged_into != TW_INSTANCE_NONE)
            dst->merged_into += first;
    }
    *in += model->instance_count;
    for (uint32_t c = 0; c < model->cluster_count; c++) {
        struct tw_cluster *dst = &g->proto.clusters[*cl + c];
        *dst = model->clusters[c];
        dst->instance += first;
        dst->box = tw_box_transform(&model->clusters[c].box, m);
    }
    *cl += model->cluster_count;
}

/* Places every object of g again (same models: the arrays keep their
 * layout) and its box. */
static void place_group(const struct tw_objects *ob, struct group *g)
{
    uint32_t in = 0, cl = 0;
    uint64_t triangles = 0;
    g->proto.box = tw_box_empty();
    for (uint32_t k = 0; k < g->count; k++) {
        const struct object *o = &ob->objects[g->objects[k]];
        const uint32_t c0 = cl;
        place_object(ob, g, o, &in, &cl);
        for (uint32_t c = c0; c < cl; c++) {
            tw_box_add_box(&g->proto.box, &g->proto.clusters[c].box);
            triangles += g->proto.clusters[c].triangle_count;
        }
    }
    g->proto.instance_count = in;
    g->proto.cluster_count = cl;
    g->proto.triangle_count = triangles;
}

/* ---- keys ------------------------------------------------------------------------------ */

/* Keys cycle through [KEY_FIRST, KEY_LAST), where no tile's key nor
 * TW_CULL_KEY_EMPTY lies. */
static uint32_t new_key(struct tw_objects *ob)
{
    const uint32_t k = ob->next_key++;
    if (ob->next_key >= KEY_LAST)
        ob->next_key = KEY_FIRST;
    return k;
}

/* ---- composites ------------------------------------------------------------------------ */

static void composite_free(struct tw_world *w, struct composite *c)
{
    if (!c)
        return;
    if (c->content != UINT32_MAX)
        tw_renderer_remove_content(w->renderer, c->content);
    w->objects->bytes_known = false;
    tw_bvh_destroy(c->bvh);
    free(c->proto.clusters);
    free(c);
}

static void free_list(struct tw_world *w, struct composite *c)
{
    while (c) {
        struct composite *next = c->next;
        composite_free(w, c);
        c = next;
    }
}

static bool drop_composite(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    free_list(user, (struct composite *)(uintptr_t)value);
    return true;
}

/* Forgets the composites of cell (its tile or its objects changed). */
static void forget_composite(struct tw_world *w, struct tw_cell cell)
{
    struct tw_objects *ob = w->objects;
    uint64_t *v = tw_cell_map_find(ob->composite_of, cell);
    if (!v)
        return;
    free_list(w, (struct composite *)(uintptr_t)*v);
    tw_cell_map_remove(ob->composite_of, cell);
}

/* The group's boxes into composite c (the group refitted since). */
static void refit_composite(struct composite *c, const struct group *g)
{
    const uint32_t split = c->tile_proto->cluster_count;
    for (uint32_t k = 0; k < g->proto.cluster_count; k++)
        c->proto.clusters[split + k].box = g->proto.clusters[k].box;
    c->proto.box = c->tile_proto->box;
    tw_box_add_box(&c->proto.box, &g->proto.box);
    tw_bvh_join_refit(c->bvh, c->tile_bvh, g->bvh);
    c->refits = g->refits;
}

/* The node slots a composite keeps for its group's BVH: twice what it
 * has, 16 at least, a power of two, so that objects coming and going
 * rebuild the group's BVH into the same composite (its key, and the
 * culling state of the tile's part, kept) until the group doubles. */
static uint32_t group_capacity(const struct tw_bvh *b)
{
    uint32_t cap = 16;
    while (cap < 2 * b->node_count && cap < (1u << 30))
        cap *= 2;
    return cap;
}

/* Group g's clusters into composite c, after the tile's (c's clusters
 * hold the tile's already), and what they make together. */
static int put_group(struct composite *c, const struct group *g)
{
    const uint32_t split = c->tile_proto->cluster_count;
    const uint64_t n = (uint64_t)split + g->proto.cluster_count;
    if (n > UINT32_MAX)
        return TW_ERR_LIMIT;
    struct tw_cluster *cl = realloc(c->proto.clusters, (size_t)n * sizeof(*cl));
    if (!cl)
        return TW_ERR_NOMEM;
    c->proto.clusters = cl;
    memcpy(cl + split, g->proto.clusters, (size_t)g->proto.cluster_count * sizeof(*cl));
    c->proto.cluster_count = (uint32_t)n;
    c->proto.triangle_count = c->tile_proto->triangle_count + g->proto.triangle_count;
    c->proto.box = c->tile_proto->box;
    tw_box_add_box(&c->proto.box, &g->proto.box);
    c->version = g->version;
    c->refits = g->refits;
    return TW_OK;
}

/* Puts group g, built afresh, into composite c: its clusters, and its BVH
 * into the slots c keeps for it. */
static int rejoin_composite(struct composite *c, const struct group *g)
{
    const int err = put_group(c, g);
    return err ? err : tw_bvh_rejoin(c->bvh, c->tile_bvh, c->tile_proto->cluster_count, g->bvh);
}

/* A composite of tile (the cell's, not empty) and group g. */
static int make_composite(struct tw_world *w, struct group *g, const struct tw_cull_tile *tile,
                          struct composite **out)
{
    struct tw_objects *ob = w->objects;
    struct composite *c = calloc(1, sizeof(*c));
    if (!c)
        return TW_ERR_NOMEM;
    c->content = UINT32_MAX;
    c->tile_key = tile->key;
    c->tile_content = tile->content;
    c->tile_proto = tile->proto;
    c->tile_bvh = tile->bvh;
    const uint32_t split = tile->proto->cluster_count;
    snprintf(c->proto.name, sizeof(c->proto.name), "%.24s with objects", tile->proto->name);
    c->proto.weight = 1.0f;
    c->proto.clusters =
        malloc(((size_t)split + g->proto.cluster_count) * sizeof(*c->proto.clusters));
    int err = c->proto.clusters ? TW_OK : TW_ERR_NOMEM;
    if (!err) {
        memcpy(c->proto.clusters, tile->proto->clusters, (size_t)split * sizeof(struct tw_cluster));
        err = put_group(c, g);
    }
    if (!err)
        err = tw_bvh_join(tile->bvh, split, g->bvh, group_capacity(g->bvh), &c->bvh);
    if (!err)
        err = tw_renderer_add_composite(w->renderer, tile->content, g->content, split, &c->proto,
                                        c->bvh, &c->content);
    if (err) {
        composite_free(w, c);
        return err;
    }
    c->key = new_key(ob);
    *out = c;
    return TW_OK;
}

/* ---- groups ---------------------------------------------------------------------------- */

static struct group *group_at(struct tw_objects *ob, struct tw_cell cell)
{
    const uint64_t *v = tw_cell_map_find(ob->group_of, cell);
    return v ? ob->groups[*v] : NULL;
}

static void group_release(struct tw_world *w, struct group *g)
{
    if (g->content != UINT32_MAX)
        tw_renderer_remove_content(w->renderer, g->content);
    g->content = UINT32_MAX;
    tw_bvh_destroy(g->bvh);
    g->bvh = NULL;
}

/* The group of cell, made if there is none (index into *index). */
static int group_for(struct tw_objects *ob, struct tw_cell cell, uint32_t *index)
{
    const uint64_t *v = tw_cell_map_find(ob->group_of, cell);
    if (v) {
        *index = (uint32_t)*v;
        return TW_OK;
    }
    uint32_t gi;
    if (ob->free_group_count) {
        gi = ob->free_groups[--ob->free_group_count];
    } else {
        if (tw_array_reserve((void **)&ob->groups, &ob->group_cap, ob->group_count + 1,
                             sizeof(*ob->groups), 64))
            return TW_ERR_NOMEM;
        ob->groups[ob->group_count] = calloc(1, sizeof(struct group));
        if (!ob->groups[ob->group_count])
            return TW_ERR_NOMEM;
        gi = (uint32_t)ob->group_count++;
    }
    struct group *g = ob->groups[gi];
    g->cell = cell;
    g->count = 0;
    g->content = UINT32_MAX;
    g->live = true;
    g->rebuild = true;
    int err = tw_cell_map_set(ob->group_of, cell, gi);
    if (err) {
        g->live = false;
        ob->free_groups[ob->free_group_count++] = gi;  /* room: reserved with the group */
        return err;
    }
    *index = gi;
    return TW_OK;
}

static int group_add(struct tw_objects *ob, uint32_t gi, uint32_t id)
{
    struct group *g = ob->groups[gi];
    if (tw_array_reserve((void **)&g->objects, &g->cap, g->count + 1, sizeof(*g->objects), 8))
        return TW_ERR_NOMEM;
    g->objects[g->count++] = id;
    g->rebuild = true;
    ob->objects[id].group = gi;
    return TW_OK;
}

static void group_remove(struct tw_objects *ob, uint32_t gi, uint32_t id)
{
    struct group *g = ob->groups[gi];
    for (uint32_t k = 0; k < g->count; k++) {
        if (g->objects[k] == id) {
            memmove(g->objects + k, g->objects + k + 1, (g->count - k - 1) * sizeof(uint32_t));
            g->count--;
            break;
        }
    }
    g->rebuild = true;
}

/* Builds g's prototype and BVH afresh. */
static int group_build(struct tw_world *w, struct group *g)
{
    struct tw_objects *ob = w->objects;
    uint64_t instances = 0, clusters = 0;
    for (uint32_t k = 0; k < g->count; k++) {
        const struct tw_prototype *m = &ob->models->prototypes[ob->objects[g->objects[k]].o.model];
        instances += m->instance_count;
        clusters += m->cluster_count;
    }
    if (instances > UINT32_MAX / 2 || clusters > UINT32_MAX / 2)
        return TW_ERR_LIMIT;
    if (tw_array_reserve((void **)&g->proto.instances, &g->instance_cap, (size_t)instances,
                         sizeof(*g->proto.instances), 16) ||
        tw_array_reserve((void **)&g->proto.clusters, &g->cluster_cap, (size_t)clusters,
                         sizeof(*g->proto.clusters), 16))
        return TW_ERR_NOMEM;
    place_group(ob, g);
    snprintf(g->proto.name, sizeof(g->proto.name), "objects of (%lld, %lld)",
             (long long)g->cell.i, (long long)g->cell.j);
    g->proto.weight = 1.0f;
    tw_bvh_destroy(g->bvh);
    g->bvh = NULL;
    /* The group's content keeps its id (the composites that name it keep
     * theirs): its BVH is the new one. */
    int err = tw_bvh_build_median(&g->proto, &w->t.bvh, &g->bvh);
    if (!err && g->content == UINT32_MAX)
        err = tw_renderer_add_content(w->renderer, ob->model_content, &g->proto, g->bvh,
                                      &g->content);
    else if (!err)
        tw_renderer_set_content_bvh(w->renderer, g->content, g->bvh);
    if (err)
        return err;
    g->spread = tw_bvh_spread(g->bvh);
    g->version++;
    g->key = new_key(ob);
    g->rebuild = g->moved = false;
    ob->rebuilds++;
    return TW_OK;
}

/* Moves within the cell: boxes again, the BVH refitted (or built afresh
 * when worn down). */
static int group_refit(struct tw_world *w, struct group *g)
{
    place_group(w->objects, g);
    tw_bvh_refit(g->bvh, &g->proto);
    g->moved = false;
    if (tw_bvh_spread(g->bvh) > TW_OBJECTS_SPREAD * g->spread)
        return group_build(w, g);
    g->refits++;
    return TW_OK;
}

static void group_free(struct tw_world *w, uint32_t gi)
{
    struct tw_objects *ob = w->objects;
    struct group *g = ob->groups[gi];
    forget_composite(w, g->cell);
    group_release(w, g);
    tw_cell_map_remove(ob->group_of, g->cell);
    g->live = false;
    g->count = 0;
    ob->free_groups[ob->free_group_count++] = gi;
}

/* ---- the world's side ------------------------------------------------------------------ */

int tw_objects_create(struct tw_world *w)
{
    const struct tw_tileset *models = w->s.object_models;
    if (!models)
        return TW_OK;
    const float *fp = w->provider.footprint;
    const float reach = fminf(fp[0], fp[1]);
    if (!models->finished || models->prototype_count == 0) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "cannot create the world: its object models are not a finished tileset");
        return TW_ERR_INVALID;
    }
    if (tw_world_hlod_wanted(w) > 1) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot create the world: moving objects are not "
                      "there with hierarchical cells (a block's proxy would leave them out)");
        return TW_ERR_STATE;
    }
    for (uint32_t p = 0; p < models->prototype_count; p++) {
        const struct tw_box *b = &models->prototypes[p].box;
        /* Its farthest corner in x and z, turned any way. */
        const float r = 1.41422f * fmaxf(fmaxf(fabsf(b->min[0]), fabsf(b->max[0])),
                                         fmaxf(fabsf(b->min[2]), fabsf(b->max[2])));
        if (!(r <= reach) || !(fabsf(b->min[1]) <= TW_TILES_MAX_COORD) ||
            !(fabsf(b->max[1]) <= TW_TILES_MAX_COORD)) {
            tw_log_printf(&w->s.log, TW_LOG_ERROR,
                          "cannot create the world: object model %u ('%.48s') reaches %g m from "
                          "its origin, turned any way; a model must reach no farther than the "
                          "footprint, %g m",
                          p, models->prototypes[p].name, (double)r, (double)reach);
            return TW_ERR_LIMIT;
        }
    }
    struct tw_objects *ob = calloc(1, sizeof(*ob));
    if (!ob)
        return TW_ERR_NOMEM;
    w->objects = ob;
    ob->models = models;
    ob->next_key = KEY_FIRST;
    int err = tw_cell_map_create(&ob->group_of);
    if (!err)
        err = tw_cell_map_create(&ob->composite_of);
    if (!err)
        err = tw_renderer_upload(w->renderer, models, NULL, &ob->model_content, NULL);
    return err;
}

void tw_objects_destroy(struct tw_world *w)
{
    struct tw_objects *ob = w->objects;
    if (!ob)
        return;
    if (ob->composite_of) {
        tw_cell_map_filter(ob->composite_of, drop_composite, w);
        tw_cell_map_destroy(ob->composite_of);
    }
    for (size_t k = 0; k < ob->group_count; k++) {
        struct group *g = ob->groups[k];
        group_release(w, g);
        free(g->objects);
        free(g->proto.instances);
        free(g->proto.clusters);
        free(g);
    }
    free(ob->groups);
    free(ob->free_groups);
    tw_cell_map_destroy(ob->group_of);
    free(ob->objects);
    free(ob->free_objects);
    free(ob);
    w->objects = NULL;
}

/* Adds composite c's bytes (tw_cell_map_filter over composite_of). */
static bool count_composite(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    for (const struct composite *c = (const struct composite *)(uintptr_t)value; c; c = c->next)
        *(uint64_t *)user += sizeof(*c) +
                             (uint64_t)c->proto.cluster_count * sizeof(struct tw_cluster) +
                             (c->bvh ? c->bvh->bytes : 0);
    return false;
}

uint64_t tw_objects_bytes(const struct tw_world *w)
{
    struct tw_objects *ob = w->objects;
    if (!ob)
        return 0;
    if (ob->bytes_known)
        return ob->bytes;
    uint64_t b = sizeof(*ob) + ob->object_cap * sizeof(struct object) +
                 ob->free_object_cap * sizeof(uint32_t) + ob->group_cap * sizeof(void *) +
                 ob->free_group_cap * sizeof(uint32_t) + tw_cell_map_bytes(ob->group_of) +
                 tw_cell_map_bytes(ob->composite_of);
    for (size_t k = 0; k < ob->group_count; k++) {
        const struct group *g = ob->groups[k];
        b += sizeof(*g) + g->cap * sizeof(uint32_t) + g->instance_cap * sizeof(struct tw_instance) +
             g->cluster_cap * sizeof(struct tw_cluster) + (g->bvh ? g->bvh->bytes : 0);
    }
    tw_cell_map_filter(ob->composite_of, count_composite, &b);
    ob->bytes = b;
    ob->bytes_known = true;
    return b;
}

/* Checks o; its position normalised into *n. */
static int check_object(struct tw_world *w, const struct tw_object *o, struct tw_object *n,
                        const char *what)
{
    const struct tw_objects *ob = w->objects;
    if (!ob) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot %s: the world has no object models "
                      "(tw_world_settings.object_models)", what);
        return TW_ERR_STATE;
    }
    *n = *o;
    if (o->model >= ob->models->prototype_count) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot %s: model %u, but there are %u",
                      what, o->model, ob->models->prototype_count);
        return TW_ERR_INVALID;
    }
    if (!isfinite(o->yaw) || fabsf(o->yaw) > 1e6f || !(fabsf(o->pos.local[1]) <= TW_TILES_MAX_COORD) ||
        tw_tiles_normalize(&n->pos, w->provider.footprint[0], w->provider.footprint[1])) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "cannot %s: its position or yaw is not finite, or out of range", what);
        return TW_ERR_INVALID;
    }
    return TW_OK;
}

static int object_add(struct tw_world *w, const struct tw_object *o, uint32_t *id)
{
    struct tw_object n;
    int err = check_object(w, o, &n, "add an object");
    if (err)
        return err;
    struct tw_objects *ob = w->objects;
    const size_t live = ob->object_count - ob->free_object_count;
    if (live >= TW_MAX_OBJECTS) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot add an object: there are %zu already, "
                      "the most a world holds", live);
        return TW_ERR_LIMIT;
    }
    /* Room first, so that nothing below fails half-way but the group. */
    if (tw_array_reserve((void **)&ob->objects, &ob->object_cap, ob->object_count + 1,
                         sizeof(*ob->objects), 64) ||
        tw_array_reserve((void **)&ob->free_objects, &ob->free_object_cap, ob->object_count + 1,
                         sizeof(*ob->free_objects), 64) ||
        tw_array_reserve((void **)&ob->free_groups, &ob->free_group_cap, ob->group_count + 1,
                         sizeof(*ob->free_groups), 64))
        return TW_ERR_NOMEM;
    uint32_t gi;
    err = group_for(ob, n.pos.cell, &gi);
    if (err)
        return err;
    const uint32_t k = ob->free_object_count ? ob->free_objects[--ob->free_object_count]
                                             : (uint32_t)ob->object_count++;
    ob->objects[k] = (struct object){.o = n, .group = gi, .live = true};
    err = group_add(ob, gi, k);
    if (err) {
        ob->objects[k].live = false;
        ob->free_objects[ob->free_object_count++] = k;
        if (ob->groups[gi]->count == 0)
            group_free(w, gi);
        return err;
    }
    ob->changed = true;
    ob->bytes_known = false;
    *id = k;
    return TW_OK;
}

static int object_update(struct tw_world *w, uint32_t id, const struct tw_object *o)
{
    struct tw_object n;
    int err = check_object(w, o, &n, "move an object");
    if (err)
        return err;
    struct tw_objects *ob = w->objects;
    if (id >= ob->object_count || !ob->objects[id].live) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot move object %u: there is none", id);
        return TW_ERR_INVALID;
    }
    struct object *obj = &ob->objects[id];
    const struct tw_cell from = obj->o.pos.cell;
    if (from.i == n.pos.cell.i && from.j == n.pos.cell.j) {
        struct group *g = ob->groups[obj->group];
        if (n.model != obj->o.model)
            g->rebuild = true;
        else
            g->moved = true;
        obj->o = n;
        ob->changed = true;
        ob->bytes_known = false;
        return TW_OK;
    }
    if (tw_array_reserve((void **)&ob->free_groups, &ob->free_group_cap, ob->group_count + 1,
                         sizeof(*ob->free_groups), 64))
        return TW_ERR_NOMEM;
    uint32_t gi;
    err = group_for(ob, n.pos.cell, &gi);
    if (err)
        return err;
    const uint32_t old = obj->group;
    err = group_add(ob, gi, id);
    if (err) {
        if (ob->groups[gi]->count == 0)
            group_free(w, gi);
        return err;
    }
    group_remove(ob, old, id);
    if (ob->groups[old]->count == 0)
        group_free(w, old);
    obj = &ob->objects[id];
    obj->o = n;
    ob->changed = true;
    ob->bytes_known = false;
    return TW_OK;
}

static int object_remove(struct tw_world *w, uint32_t id)
{
    struct tw_objects *ob = w->objects;
    if (!ob) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot remove an object: the world has no "
                      "object models (tw_world_settings.object_models)");
        return TW_ERR_STATE;
    }
    if (id >= ob->object_count || !ob->objects[id].live) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot remove object %u: there is none", id);
        return TW_ERR_INVALID;
    }
    const uint32_t gi = ob->objects[id].group;
    group_remove(ob, gi, id);
    if (ob->groups[gi]->count == 0)
        group_free(w, gi);
    ob->objects[id].live = false;
    ob->free_objects[ob->free_object_count++] = id;    /* room: reserved when added */
    ob->changed = true;
    ob->bytes_known = false;
    return TW_OK;
}

int tw_world_object_add(struct tw_world *w, const struct tw_object *o, uint32_t *id)
{
    if (!w || !o || !id)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "add an object", false);
    if (err)
        return err;
    err = object_add(w, o, id);
    tw_world_leave(w, false);
    return err;
}

int tw_world_object_update(struct tw_world *w, uint32_t id, const struct tw_object *o)
{
    if (!w || !o)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "move an object", false);
    if (err)
        return err;
    err = object_update(w, id, o);
    tw_world_leave(w, false);
    return err;
}

int tw_world_object_remove(struct tw_world *w, uint32_t id)
{
    if (!w)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "remove an object", false);
    if (err)
        return err;
    err = object_remove(w, id);
    tw_world_leave(w, false);
    return err;
}

int tw_objects_apply(struct tw_world *w)
{
    struct tw_objects *ob = w->objects;
    if (!ob)
        return TW_OK;
    ob->rebuilds = 0;
    ob->ms = 0.0;
    if (!ob->changed)
        return TW_OK;
    const double t0 = tw_clock_monotonic_ms();
    struct tw_box box = w->provider.bound;
    int err = TW_OK;
    for (size_t k = 0; k < ob->group_count && !err; k++) {
        struct group *g = ob->groups[k];
        if (!g->live)
            continue;
        if (g->rebuild)
            err = group_build(w, g);
        else if (g->moved)
            err = group_refit(w, g);
        if (!err)
            tw_box_add_box(&box, &g->proto.box);
    }
    ob->changed = false;
    ob->bytes_known = false;
    /* The common box holds every group's box (the cells in view follow
     * it: tw_cull_cells_of_frame). */
    w->grid.common_box = box;
    ob->ms = tw_clock_monotonic_ms() - t0;
    return err;
}

void tw_objects_stats(const struct tw_world *w, struct tw_frame_stats *st)
{
    const struct tw_objects *ob = w->objects;
    if (!ob)
        return;
    st->objects = (uint32_t)(ob->object_count - ob->free_object_count);
    st->object_cells = (uint32_t)tw_cell_map_count(ob->group_of);
    st->object_rebuilds = ob->rebuilds;
    st->ms_objects = ob->ms;
}

int tw_objects_tile(struct tw_world *w, struct tw_cell cell, struct tw_cull_tile *tile)
{
    struct tw_objects *ob = w->objects;
    struct group *g = group_at(ob, cell);
    if (!g || !g->bvh)
        return TW_OK;
    if (!tile->proto) {
        /* An empty cell, or a tile not ready: its objects alone. */
        *tile = (struct tw_cull_tile){.proto = &g->proto, .bvh = g->bvh, .content = g->content,
                                      .key = g->key};
        return TW_OK;
    }
    uint64_t *v = tw_cell_map_find(ob->composite_of, cell);
    struct composite *head = v ? (struct composite *)(uintptr_t)*v : NULL, *c = head;
    while (c && (c->tile_key != tile->key || c->tile_content != tile->content ||
                 c->tile_proto != tile->proto || c->tile_bvh != tile->bvh))
        c = c->next;
    /* The group built afresh since: into the same composite while its
     * slots hold it (rejoin_composite), else a composite afresh. */
    if (c && c->version != g->version) {
        ob->bytes_known = false;
        if (rejoin_composite(c, g) != TW_OK)
            c->version = UINT32_MAX;    /* stale: pruned below */
    }
    if (c && c->version != g->version)
        c = NULL;
    if (!c) {
        int err = make_composite(w, g, tile, &c);
        ob->bytes_known = false;
        if (err)
            return err;
        /* Stale ones go: made for another version of the group, unused for
         * two frames, or beyond the cell's few. */
        struct composite **link = &c->next;
        uint32_t kept = 1;
        for (struct composite *o = head; o;) {
            struct composite *next = o->next;
            if (o->version != UINT32_MAX && o->used + 2 >= w->frame_serial &&
                kept < COMPOSITES_PER_CELL) {
                *link = o;
                link = &o->next;
                kept++;
            } else {
                composite_free(w, o);
            }
            o = next;
        }
        *link = NULL;
        err = tw_cell_map_set(ob->composite_of, cell, (uint64_t)(uintptr_t)c);
        if (err) {
            free_list(w, c);
            tw_cell_map_remove(ob->composite_of, cell);
            return err;
        }
    } else if (c->refits != g->refits) {
        refit_composite(c, g);
    }
    c->used = w->frame_serial;
    *tile = (struct tw_cull_tile){.proto = &c->proto, .bvh = c->bvh, .content = c->content,
                                  .key = c->key};
    return TW_OK;
}

void tw_objects_invalidate(struct tw_world *w, struct tw_cell lo, struct tw_cell hi)
{
    struct tw_objects *ob = w->objects;
    if (!ob)
        return;
    /* Few cells hold objects: look at those, not at the rectangle. */
    for (size_t k = 0; k < ob->group_count; k++) {
        const struct group *g = ob->groups[k];
        if (g->live && g->cell.i >= lo.i && g->cell.i <= hi.i && g->cell.j >= lo.j &&
            g->cell.j <= hi.j)
            forget_composite(w, g->cell);
    }
}
