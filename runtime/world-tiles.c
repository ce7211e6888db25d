/*
 * Where a world's tiles come from (world-private.h): the provider, checked;
 * the tile source the culling reads; the stream of generated tiles and its
 * sink; the look-ahead; the byte budget; tile events; invalidation.
 */
#include "runtime/world-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <string.h>

/* The fixed tileset's selection as a provider's content(). */
static uint32_t select_content(void *user, struct tw_cell cell)
{
    const struct tw_world *w = user;
    return tw_tiles_select(w->s.tileset, &w->s.selection, cell);
}

static bool box_finite(const struct tw_box *b)
{
    for (int a = 0; a < 3; a++)
        if (!isfinite(b->min[a]) || !isfinite(b->max[a]) || b->min[a] > b->max[a])
            return false;
    return true;
}

int tw_world_resolve_provider(struct tw_world *w)
{
    const struct tw_log *log = &w->s.log;
    if (!w->s.provider) {
        const struct tw_tileset *ts = w->s.tileset;
        w->provider = (struct tw_tile_provider){
            .name = ts->name,
            .footprint = {ts->footprint[0], ts->footprint[1]},
            .bound = ts->common_box,
            .shared = ts,
            .content = select_content,
            .user = w,
        };
        return TW_OK;
    }
    const struct tw_tile_provider *p = w->s.provider;
    w->provider = *p;
    const char *name = p->name ? p->name : "(unnamed)";
    if (!(p->footprint[0] > 0.0f && p->footprint[1] > 0.0f && isfinite(p->footprint[0]) &&
          isfinite(p->footprint[1])) || !box_finite(&p->bound)) {
        tw_log_printf(log, TW_LOG_ERROR, "provider %s: footprint or bound is not a finite box", name);
        return TW_ERR_INVALID;
    }
    if (!p->generate && !p->content) {
        tw_log_printf(log, TW_LOG_ERROR, "provider %s: neither content() nor generate()", name);
        return TW_ERR_INVALID;
    }
    /* Its own coarser levels: a generate_level() and an error for each. */
    if (p->levels > TW_PROVIDER_MAX_LEVELS || (p->levels > 0 && !p->generate_level)) {
        tw_log_printf(log, TW_LOG_ERROR, "provider %s: %u coarser levels%s (at most %u)", name,
                      p->levels, p->generate_level ? "" : " and no generate_level()",
                      TW_PROVIDER_MAX_LEVELS);
        return TW_ERR_INVALID;
    }
    for (uint32_t k = 0; k < p->levels; k++)
        if (!(p->level_error[k] >= 0.0f) || !isfinite(p->level_error[k])) {
            tw_log_printf(log, TW_LOG_ERROR, "provider %s: level %u's error is %g metres", name,
                          k + 1, (double)p->level_error[k]);
            return TW_ERR_INVALID;
        }
    if (p->shared) {
        const struct tw_tileset *ts = p->shared;
        if (!ts->finished || ts->footprint[0] != p->footprint[0] ||
            ts->footprint[1] != p->footprint[1]) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "provider %s: the shared tileset is unfinished or has another footprint",
                          name);
            return TW_ERR_INVALID;
        }
        for (uint32_t k = 0; k < ts->prototype_count; k++) {
            const struct tw_box *b = &ts->prototypes[k].box;
            for (int a = 0; a < 3; a++)
                if (b->min[a] < p->bound.min[a] || b->max[a] > p->bound.max[a]) {
                    tw_log_printf(log, TW_LOG_ERROR,
                                  "provider %s: shared prototype %u '%.48s' exceeds the bound",
                                  name, k, ts->prototypes[k].name);
                    return TW_ERR_INVALID;
                }
        }
    }
    return TW_OK;
}

/* The stream's tile sink: the renderer's GPU store. */
static int sink_upload(void *user, const struct tw_tileset *ts, const struct tw_bvh *const *bvhs,
                       uint32_t *content, uint64_t *bytes_gpu)
{
    const struct tw_world *w = user;
    return tw_renderer_upload(w->renderer, ts, bvhs, content, bytes_gpu);
}

static void sink_release(void *user, uint32_t content)
{
    const struct tw_world *w = user;
    uint32_t level;
    const uint32_t base = tw_renderer_content_base(w->renderer, content, &level);
    /* A host that draws is told once, for the tile (its levels go with it). */
    if (w->s.host.release && level == 0 && tw_renderer_content(w->renderer, content, NULL)) {
        w->s.host.release(w->s.host.user, base, tw_renderer_host_data(w->renderer, content));
        tw_renderer_after_host(w->renderer);
    }
    tw_renderer_release(w->renderer, content);
}

/* Host rendering: the host prepares a tile that became ready. */
static uint64_t sink_ready(void *user, uint32_t content, const struct tw_tileset *ts,
                           const struct tw_tileset *levels, void *data)
{
    const struct tw_world *w = user;
    uint64_t bytes = 0;
    tw_renderer_set_host_data(w->renderer, content,
                              w->s.host.prepare(w->s.host.user, content, ts, levels, data, &bytes));
    tw_renderer_after_host(w->renderer);
    return bytes;
}

/* On a worker: the host's own part of making a tile. The world's settings
 * do not change after creation but for the method, which this does not read. */
static void *hook_prepare_worker(void *user, struct tw_cell cell, const struct tw_tileset *ts,
                                 const struct tw_tileset *levels)
{
    const struct tw_world *w = user;
    return w->s.host.prepare_worker(w->s.host.user, cell, ts, levels);
}

static void hook_discard(void *user, void *data)
{
    const struct tw_world *w = user;
    if (w->s.host.release) {
        w->s.host.release(w->s.host.user, TW_HOST_NOT_READY, data);
        tw_renderer_after_host(w->renderer);
    }
}

static void sink_levels(void *user, uint32_t base, uint32_t first, uint32_t count)
{
    const struct tw_world *w = user;
    tw_renderer_tag_levels(w->renderer, base, first, count);
}



static void push_event(struct tw_world *w, const struct tw_tile_event *ev)
{
    if (tw_array_reserve((void **)&w->next_events, &w->next_event_cap, w->next_event_count + 1,
                         sizeof(*w->next_events), 64))
        return;     /* an event lost to memory: the counters still count it */
    w->next_events[w->next_event_count++] = *ev;
}

static void stream_event(void *user, const struct tw_tile_event *e)
{
    push_event(user, e);
}

struct tw_stream_settings tw_world_stream_settings(struct tw_world *w,
                                                   const struct tw_tile_provider *provider,
                                                   uint32_t key_base)
{
    return (struct tw_stream_settings){
        .provider = provider,
        .sink = {sink_upload, sink_release, sink_levels, w->s.host.prepare ? sink_ready : NULL,
                 w},
        .hooks = {w->s.host.prepare_worker ? hook_prepare_worker : NULL, hook_discard, w},
        .bvh = w->t.bvh,
        .workers = w->s.workers,
        .policy = w->s.policy,
        .upload_bytes = w->s.upload_budget_bytes,
        .upload_ms = w->s.upload_budget_ms,
        .evict_after = w->s.evict_after_frames,
        .budget = w->s.cache_budget_bytes,
        .key_base = key_base,
        .lods = w->lod_on,
        .lods_store = w->lods_store,
        .stop_ms = w->s.shutdown_timeout_ms,
        .retry_after = w->s.retry_after_frames == TW_NEVER_RETRY ? 0 : w->s.retry_after_frames,
        .retry_max = w->s.retry_max,
        .max_triangles = w->s.max_tile_triangles == UINT64_MAX ? 0 : w->s.max_tile_triangles,
        .max_bytes = w->s.max_tile_bytes == UINT64_MAX ? 0 : w->s.max_tile_bytes,
        .log = &w->s.log,
    };
}

int tw_world_start_stream(struct tw_world *w)
{
    const struct tw_stream_settings ss =
        tw_world_stream_settings(w, &w->provider, w->shared_count + w->lod_count);
    int err = tw_stream_create(&ss, &w->stream);
    if (!err)
        tw_stream_set_events(w->stream, stream_event, w);
    return err;
}

/* What cell shows, checked: a shared prototype, TW_TILE_OWN or TW_TILE_EMPTY. */
static int content_of(struct tw_world *w, struct tw_cell cell, uint32_t *content)
{
    const struct tw_tile_provider *p = &w->provider;
    const uint32_t c = p->content ? p->content(p->user, cell) : TW_TILE_OWN;
    if (c != TW_TILE_EMPTY && (c == TW_TILE_OWN ? !w->stream : c >= w->shared_count)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "%s %s: cell (%lld, %lld) shows %s %u, but there are %u shared "
                      "prototypes%s",
                      w->s.provider ? "provider" : "selection of tileset",
                      p->name ? p->name : "", (long long)cell.i, (long long)cell.j,
                      c == TW_TILE_OWN ? "content" : "prototype", c, w->shared_count,
                      c == TW_TILE_OWN ? " and no generate() for a tile of its own" : "");
        return TW_ERR_INVALID;
    }
    *content = c;
    return TW_OK;
}

/* The geometric error, in metres, that a tile may have in the current view
 * at distance (the eye's to its cell's common box, the nearest any of its
 * content can be: conservative): max_screen_error pixels there. 0 without
 * levels of detail, and in a full-detail pass. */
static float max_error_of(const struct tw_world *w, float distance)
{
    if (!w->lod_on || w->lod_full || !(w->lod_px_per_m > 0.0f))
        return 0.0f;
    return distance * w->s.max_screen_error / w->lod_px_per_m;
}

int tw_world_levels_in_view(struct tw_world *w, const struct tw_view *v, bool *any)
{
    *any = true;
    if (w->stream)
        return TW_OK;   /* a generated tile's levels are known once it is made */
    int err = tw_cull_cells_of_frame(&w->cur->cells, v, &w->grid);
    if (err)
        return err;
    /* Front to back: the last cell is the farthest. */
    const float farthest = w->cur->cells.count ? w->cur->cells.cells[w->cur->cells.count - 1].distance : 0.0f;
    *any = max_error_of(w, farthest) >= w->lod_least_error;
    /* A block's proxy is a level of detail of its cells, whatever its error. */
    for (size_t k = 0; k < w->cur->cells.count && !*any; k++)
        *any = w->cur->cells.cells[k].level > 0;
    return TW_OK;
}

static int base_tile(struct tw_world *w, struct tw_cell cell, uint32_t node_level,
                     float distance, unsigned flags, struct tw_cull_tile *out)
{
    const float max_error = max_error_of(w, distance);
    if (node_level > 0)
        return tw_world_hlod_get(w, cell, node_level, distance, flags, max_error, out);
    uint32_t c;
    int err = content_of(w, cell, &c);
    if (err)
        return err;
    if (c != TW_TILE_OWN) {
        /* A cell that had a tile of its own and now shows a shared one: the
         * provider's answer changed, which is an invalidation. */
        if (w->stream && tw_stream_has(w->stream, cell))
            tw_stream_invalidate(w->stream, cell);
        if (c == TW_TILE_EMPTY) {
            /* Nothing to draw, nothing to make: the frame only queries its box. */
            *out = (struct tw_cull_tile){.key = TW_CULL_KEY_EMPTY};
            return TW_OK;
        }
        const uint32_t level = tw_lods_pick(w->lods, c, max_error);
        if (level > 0) {
            const uint32_t k = w->lods->first[c] + level - 1;
            out->proto = &w->lods->levels->prototypes[k];
            out->bvh = w->lod_bvhs[k];
            out->content = w->lod_first + k;
            out->key = w->shared_count + k;
            return TW_OK;
        }
        out->proto = &w->provider.shared->prototypes[c];
        out->bvh = w->bvhs[c];
        out->content = c;
        out->key = c;
        return TW_OK;
    }
    return tw_stream_get(w->stream, cell, distance, flags, max_error, out);
}

int tw_world_get_tile(void *ctx, struct tw_cell cell, uint32_t node_level, float distance,
                      unsigned flags, struct tw_cull_tile *out)
{
    struct tw_world *w = ctx;
    const int err = base_tile(w, cell, node_level, distance, flags, out);
    /* A cell with moving objects: its tile joined to them. A tile not
     * ready yet keeps its objects back too (drawn with it). */
    if (err || !w->objects || node_level > 0)
        return err;
    return tw_objects_tile(w, cell, out);
}

void tw_world_prefetch_tile(void *ctx, struct tw_cell cell, uint32_t node_level, float distance)
{
    struct tw_world *w = ctx;
    if (node_level > 0) {
        tw_world_hlod_prefetch(w, cell, node_level, distance);
        return;
    }
    const struct tw_tile_provider *p = &w->provider;
    if (!p->content || p->content(p->user, cell) == TW_TILE_OWN)
        tw_stream_prefetch(w->stream, cell, distance);   /* not for shared or empty cells */
}

/* Frames ahead the look-ahead predicts, and how many of the cells it would
 * see are requested (the nearest). */
#define LOOK_AHEAD_FRAMES 30
#define LOOK_AHEAD_CELLS 16

void tw_world_look_ahead(struct tw_world *w, const struct tw_view *v)
{
    const float *fp = w->provider.footprint;
    if (w->cur->has_prev) {
        float moved[3];
        tw_tiles_cell_offset(v->cell, w->cur->prev_pos.cell, fp[0], fp[1], moved);
        for (int a = 0; a < 3; a++)
            moved[a] += v->eye[a] - w->cur->prev_pos.local[a];
        const float step = sqrtf(moved[0] * moved[0] + moved[1] * moved[1] + moved[2] * moved[2]);
        for (int a = 0; a < 3; a++)
            w->cur->velocity[a] = step > v->view_distance ? 0.0f  /* a jump: no motion to follow */
                                                     : 0.7f * w->cur->velocity[a] + 0.3f * moved[a];
    }
    w->cur->prev_pos.cell = v->cell;
    memcpy(w->cur->prev_pos.local, v->eye, sizeof(v->eye));
    w->cur->has_prev = true;
    const float speed2 = w->cur->velocity[0] * w->cur->velocity[0] + w->cur->velocity[2] * w->cur->velocity[2];
    if (speed2 < 1e-4f)
        return;
    struct tw_view ahead = *v;
    for (int a = 0; a < 3; a += 2)
        ahead.eye[a] += LOOK_AHEAD_FRAMES * w->cur->velocity[a];
    /* The same matrices moved: the frustum of the eye translated. */
    float translate[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    translate[12] = -LOOK_AHEAD_FRAMES * w->cur->velocity[0];
    translate[14] = -LOOK_AHEAD_FRAMES * w->cur->velocity[2];
    for (int c = 0; c < 4; c++)
        for (int r = 0; r < 4; r++) {
            float sum = 0.0f;
            for (int k = 0; k < 4; k++)
                sum += v->view_proj[k * 4 + r] * translate[c * 4 + k];
            ahead.view_proj[c * 4 + r] = sum;
        }
    tw_cull_frustum_from_matrix(ahead.view_proj, &ahead.frustum);
    if (tw_cull_cells_of_frame(&w->cur->ahead, &ahead, &w->grid))
        return;
    const size_t n = w->cur->ahead.count < LOOK_AHEAD_CELLS ? w->cur->ahead.count : LOOK_AHEAD_CELLS;
    for (size_t k = 0; k < n; k++) {
        const struct tw_cull_cell *c = &w->cur->ahead.cells[k];
        float off[3];
        tw_tiles_cell_offset(c->cell, v->cell, fp[0], fp[1], off);
        const struct tw_box box = tw_cull_node_box(&w->grid, c->level);
        tw_world_prefetch_tile(w, c->cell, c->level,
                               v->view_distance + tw_cull_box_distance(v, &box, off));
    }
}

/* Every byte the world's tiles cost: shared content once, generated tiles,
 * every method's culling state. */
static void count_bytes(const struct tw_world *w, uint64_t *cpu, uint64_t *gpu, uint64_t *state)
{
    uint64_t scpu = 0, sgpu = 0, culling = 0;
    if (w->stream)
        tw_stream_bytes(w->stream, &scpu, &sgpu);
    tw_world_hlod_bytes(w, &scpu, &sgpu);
    /* Every view's culling state. */
    const struct tw_view_state *vs = &w->own;
    for (const struct tw_viewport *vp = w->viewports;; vp = vp->next) {
        for (int m = 0; m < TW_METHOD_ALL; m++)
            if (vs->methods[m].driver)
                culling += tw_cull_driver_bytes(vs->methods[m].driver);
        if (!vp)
            break;
        vs = &vp->state;
    }
    *cpu = w->shared_cpu + scpu + culling + tw_objects_bytes(w);
    *gpu = w->shared_gpu + sgpu;
    if (state)
        *state = culling;
}

void tw_world_keep_budget(struct tw_world *w, const struct method_state *ms,
                          struct tw_frame_stats *st)
{
    uint64_t cpu, gpu, state;
    count_bytes(w, &cpu, &gpu, NULL);
    const uint64_t budget = w->s.cache_budget_bytes;
    uint32_t instances = 0;
    /* Evicting can grow a table (the record of evictions): count again. */
    while (budget && cpu + gpu > budget && w->stream &&
           tw_stream_trim(w->stream, cpu + gpu - budget, tw_world_keep_from(w), NULL, NULL) > 0)
        count_bytes(w, &cpu, &gpu, NULL);
    while (budget && cpu + gpu > budget && tw_world_hlod_trim(w, cpu + gpu - budget) > 0)
        count_bytes(w, &cpu, &gpu, NULL);
    /* The culling state of every other method of every view, then this
     * method's own. */
    for (int pass = 0; pass < 2 && budget && cpu + gpu > budget; pass++) {
        struct tw_viewport *k = NULL;
        bool started = false;
        for (struct tw_view_state *vs; (vs = tw_world_next_view(w, &k, &started));)
            for (int m = 0; m < TW_METHOD_ALL && cpu + gpu > budget; m++) {
                const struct method_state *other = &vs->methods[m];
                if (!other->driver || (other == ms) != (pass == 1))
                    continue;
                /* Another method's instances are all older than its next frame. */
                tw_cull_driver_trim(other->driver, cpu + gpu - budget,
                                    other->frame + (other != ms), &instances);
                count_bytes(w, &cpu, &gpu, NULL);
            }
    }
    count_bytes(w, &cpu, &gpu, &state);
    st->bytes_cpu = cpu;
    st->bytes_gpu = gpu;
    st->bytes_state = state;
    st->bytes_needed = cpu + gpu;
    st->over_budget = budget && cpu + gpu > budget;
    if (w->stream) {
        const struct tw_stream_stats *ss = tw_stream_stats(w->stream);
        st->bytes_needed = cpu + gpu - tw_stream_tile_bytes(w->stream) + ss->bytes_used;
        st->loads_requested = ss->loads_requested;
        st->loads_done = ss->loads_done;
        st->evictions = ss->evictions;
        st->ms_upload = ss->ms_upload;
        st->bytes_loading = ss->bytes_loading;
        st->tiles_loading = ss->tiles_loading;
    }
    tw_world_hlod_stats(w, st);
    st->evictions += instances;
}

const struct tw_tile_event *tw_world_tile_events(const struct tw_world *w, size_t *count)
{
    if (!w || !count) {
        if (count)
            *count = 0;
        return NULL;
    }
    *count = w->event_count;
    return w->events;
}

int tw_world_invalidate_rect(struct tw_world *w, struct tw_cell lo, struct tw_cell hi)
{
    if (!w || lo.i > hi.i || lo.j > hi.j)
        return TW_ERR_INVALID;
    const int err = tw_world_enter(w, "invalidate cells", true);
    if (err)
        return err;
    if (w->stream) {
        if (lo.i == hi.i && lo.j == hi.j)
            tw_stream_invalidate(w->stream, lo);
        else
            tw_stream_invalidate_rect(w->stream, lo, hi);
    }
    tw_world_hlod_invalidate(w, lo, hi);
    tw_objects_invalidate(w, lo, hi);
    /* Every method's culling state of those cells: made for what they showed. */
    for (int m = 0; m < TW_METHOD_ALL; m++) {
        struct tw_cull_driver *d = w->cur->methods[m].driver;
        if (!d)
            continue;
        const uint64_t wi = (uint64_t)hi.i - (uint64_t)lo.i, wj = (uint64_t)hi.j - (uint64_t)lo.j;
        if (wi < 64 && wj < 64) {
            for (uint64_t a = 0; a <= wi; a++)
                for (uint64_t b = 0; b <= wj; b++)
                    tw_cull_driver_forget(d, (struct tw_cell){(int64_t)((uint64_t)lo.i + a),
                                                              (int64_t)((uint64_t)lo.j + b)});
        } else {
            tw_cull_driver_forget_rect(d, lo, hi);
        }
    }
    tw_world_leave(w, true);
    return TW_OK;
}

int tw_world_retry_cell(struct tw_world *w, struct tw_cell cell)
{
    if (!w)
        return TW_ERR_INVALID;
    const int err = tw_world_enter(w, "retry a cell", true);
    if (err)
        return err;
    if (w->stream)
        tw_stream_retry(w->stream, cell);
    tw_world_leave(w, true);
    return TW_OK;
}

int tw_world_invalidate(struct tw_world *w, struct tw_cell cell)
{
    return tw_world_invalidate_rect(w, cell, cell);
}

int tw_world_cache_totals(const struct tw_world *w, struct tw_cache_totals *out)
{
    if (!w || !out)
        return TW_ERR_INVALID;
    memset(out, 0, sizeof(*out));
    if (!w->stream)
        return TW_OK;
    const struct tw_stream_totals *t = tw_stream_totals(w->stream);
    out->tiles_ready = tw_stream_ready_count(w->stream);
    out->tiles_loading = tw_stream_loading_count(w->stream);
    out->tile_bytes = tw_stream_tile_bytes(w->stream);
    out->loads_requested = t->loads_requested;
    out->loads_done = t->loads_done;
    out->evictions = t->evictions;
    out->reloads = t->reloads;
    out->refused = t->refused;
    return TW_OK;
}
