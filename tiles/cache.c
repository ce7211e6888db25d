/* The cell map and the tile cache (tiles.h). */
#include "tileworld/tiles.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* ---- cell map ------------------------------------------------------------------ */

struct cell_entry {
    struct tw_cell cell;
    uint64_t value;
    bool used;
};

struct tw_cell_map {
    struct cell_entry *entries;
    size_t cap;      /* a power of two, or 0 */
    size_t count;
};

static size_t cell_hash(struct tw_cell c)
{
    return (size_t)tw_tiles_hash(0x7ce11, c.i, c.j);
}

int tw_cell_map_create(struct tw_cell_map **out)
{
    if (!out)
        return TW_ERR_INVALID;
    struct tw_cell_map *m = calloc(1, sizeof(*m));
    if (!m)
        return TW_ERR_NOMEM;
    *out = m;
    return TW_OK;
}

void tw_cell_map_destroy(struct tw_cell_map *m)
{
    if (!m)
        return;
    free(m->entries);
    free(m);
}

static bool same_cell(struct tw_cell a, struct tw_cell b)
{
    return a.i == b.i && a.j == b.j;
}

/* The slot that holds cell, or SIZE_MAX: linear probing from its hash to the
 * first unused slot (the table is never full). */
static size_t slot_of(const struct tw_cell_map *m, struct tw_cell cell)
{
    if (!m || m->count == 0)
        return SIZE_MAX;
    const size_t mask = m->cap - 1;
    for (size_t k = cell_hash(cell) & mask;; k = (k + 1) & mask) {
        if (!m->entries[k].used)
            return SIZE_MAX;
        if (same_cell(m->entries[k].cell, cell))
            return k;
    }
}

uint64_t *tw_cell_map_find(const struct tw_cell_map *m, struct tw_cell cell)
{
    const size_t k = slot_of(m, cell);
    return k == SIZE_MAX ? NULL : &m->entries[k].value;
}

static void place(struct cell_entry *entries, size_t cap, struct tw_cell cell, uint64_t value)
{
    const size_t mask = cap - 1;
    size_t k = cell_hash(cell) & mask;
    while (entries[k].used)
        k = (k + 1) & mask;
    entries[k].cell = cell;
    entries[k].value = value;
    entries[k].used = true;
}

static int rehash(struct tw_cell_map *m, size_t cap)
{
    struct cell_entry *entries = calloc(cap, sizeof(*entries));
    if (!entries)
        return TW_ERR_NOMEM;
    for (size_t k = 0; k < m->cap; k++)
        if (m->entries[k].used)
            place(entries, cap, m->entries[k].cell, m->entries[k].value);
    free(m->entries);
    m->entries = entries;
    m->cap = cap;
    return TW_OK;
}

int tw_cell_map_set(struct tw_cell_map *m, struct tw_cell cell, uint64_t value)
{
    if (!m)
        return TW_ERR_INVALID;
    uint64_t *v = tw_cell_map_find(m, cell);
    if (v) {
        *v = value;
        return TW_OK;
    }
    /* Keep the load under one half: probes stay short. */
    if (2 * (m->count + 1) > m->cap) {
        int err = rehash(m, m->cap ? 2 * m->cap : 64);
        if (err)
            return err;
    }
    place(m->entries, m->cap, cell, value);
    m->count++;
    return TW_OK;
}

/* Backward-shift deletion: no tombstones, so lookups never slow down as
 * cells come and go. */
static void remove_at(struct tw_cell_map *m, size_t hole)
{
    const size_t mask = m->cap - 1;
    m->entries[hole].used = false;
    for (size_t k = (hole + 1) & mask; m->entries[k].used; k = (k + 1) & mask) {
        const size_t home = cell_hash(m->entries[k].cell) & mask;
        /* Move the entry into the hole if its home does not lie in (hole, k]. */
        const bool home_between = hole <= k ? (home > hole && home <= k) : (home > hole || home <= k);
        if (!home_between) {
            m->entries[hole] = m->entries[k];
            m->entries[k].used = false;
            hole = k;
        }
    }
    m->count--;
}

bool tw_cell_map_remove(struct tw_cell_map *m, struct tw_cell cell)
{
    const size_t k = slot_of(m, cell);
    if (k == SIZE_MAX)
        return false;
    remove_at(m, k);
    return true;
}

void tw_cell_map_clear(struct tw_cell_map *m)
{
    if (!m)
        return;
    if (m->cap)
        memset(m->entries, 0, sizeof(*m->entries) * m->cap);
    m->count = 0;
}

size_t tw_cell_map_count(const struct tw_cell_map *m)
{
    return m ? m->count : 0;
}

size_t tw_cell_map_bytes(const struct tw_cell_map *m)
{
    return m ? sizeof(*m) + sizeof(*m->entries) * m->cap : 0;
}

void tw_cell_map_filter(struct tw_cell_map *m,
                        bool (*fn)(void *user, struct tw_cell cell, uint64_t value), void *user)
{
    if (!m || !fn)
        return;
    /* Removal shifts later entries back into the hole, so re-examine the
     * same index after a removal; a shift can also wrap an entry from the
     * table's start to its end, which is then visited twice: harmless for a
     * predicate that depends only on the entry. */
    for (size_t k = 0; k < m->cap;) {
        struct cell_entry *e = &m->entries[k];
        if (e->used && fn(user, e->cell, e->value))
            remove_at(m, k);
        else
            k++;
    }
}

/* ---- tile cache ---------------------------------------------------------------- */

struct slot {
    struct tw_tile_info info;
    void *state;
    uint32_t generation;   /* odd while alive: a handle matches only its own life */
    uint32_t next_free;
};

struct tw_tile_cache {
    uint32_t evict_after;
    struct slot *slots;
    uint32_t slot_count, slot_cap;
    uint32_t free_head;    /* UINT32_MAX: none */
    uint32_t live;
    uint64_t state_bytes;
    struct tw_cell_map *by_cell;   /* cell -> slot */
};

int tw_tile_cache_create(uint32_t evict_after, struct tw_tile_cache **out)
{
    if (!out)
        return TW_ERR_INVALID;
    struct tw_tile_cache *c = calloc(1, sizeof(*c));
    if (!c)
        return TW_ERR_NOMEM;
    c->evict_after = evict_after;
    c->free_head = UINT32_MAX;
    int err = tw_cell_map_create(&c->by_cell);
    if (err) {
        free(c);
        return err;
    }
    *out = c;
    return TW_OK;
}

void tw_tile_cache_destroy(struct tw_tile_cache *c)
{
    if (!c)
        return;
    for (uint32_t k = 0; k < c->slot_count; k++)
        free(c->slots[k].state);
    free(c->slots);
    tw_cell_map_destroy(c->by_cell);
    free(c);
}

static struct slot *live_slot(const struct tw_tile_cache *c, struct tw_tile_handle h)
{
    if (h.slot >= c->slot_count || (h.generation & 1u) == 0)
        return NULL;
    struct slot *s = &c->slots[h.slot];
    return s->generation == h.generation ? s : NULL;
}

bool tw_tile_cache_find(const struct tw_tile_cache *c, struct tw_cell cell,
                        struct tw_tile_handle *out)
{
    if (!c || !out)
        return false;
    const uint64_t *v = tw_cell_map_find(c->by_cell, cell);
    if (!v)
        return false;
    out->slot = (uint32_t)*v;
    out->generation = c->slots[*v].generation;
    return true;
}

/* Frees slot k's instance; its handles go stale. */
static void release(struct tw_tile_cache *c, uint32_t k)
{
    struct slot *s = &c->slots[k];
    tw_cell_map_remove(c->by_cell, s->info.cell);
    free(s->state);
    s->state = NULL;
    c->state_bytes -= s->info.state_bytes;
    s->generation++;        /* odd (alive) -> even (free): old handles go stale */
    s->next_free = c->free_head;
    c->free_head = k;
    c->live--;
}

int tw_tile_cache_acquire(struct tw_tile_cache *c, struct tw_cell cell, uint32_t prototype,
                          size_t state_bytes, uint64_t frame, struct tw_tile_handle *out,
                          bool *created)
{
    if (!c || !out || !created)
        return TW_ERR_INVALID;
    if (tw_tile_cache_find(c, cell, out)) {
        struct slot *s = &c->slots[out->slot];
        if (s->info.prototype == prototype && s->info.state_bytes == state_bytes) {
            s->info.visible_frame = frame;
            *created = false;
            return TW_OK;
        }
        /* The cell shows other content than when its instance was made (an
         * impure selection, or content the host changed): the old state
         * describes another tree. Drop it, and start afresh. */
        release(c, out->slot);
    }
    uint32_t index;
    if (c->free_head != UINT32_MAX) {
        index = c->free_head;
        c->free_head = c->slots[index].next_free;
    } else {
        const int err = tw_array_reserve_u32((void **)&c->slots, &c->slot_cap,
                                             c->slot_count + 1, sizeof(*c->slots), 64);
        if (err)
            return err;
        index = c->slot_count++;
        c->slots[index].generation = 0;
    }
    struct slot *s = &c->slots[index];
    s->state = state_bytes ? calloc(1, state_bytes) : NULL;
    int err = (state_bytes && !s->state) ? TW_ERR_NOMEM
                                         : tw_cell_map_set(c->by_cell, cell, index);
    if (err) {
        free(s->state);
        s->state = NULL;
        s->next_free = c->free_head;
        c->free_head = index;
        return err;
    }
    s->generation++;            /* even (free) -> odd (alive) */
    s->info.cell = cell;
    s->info.prototype = prototype;
    s->info.created_frame = frame;
    s->info.visible_frame = frame;
    s->info.state_bytes = state_bytes;
    c->state_bytes += state_bytes;
    c->live++;
    out->slot = index;
    out->generation = s->generation;
    *created = true;
    return TW_OK;
}

void *tw_tile_cache_state(const struct tw_tile_cache *c, struct tw_tile_handle h)
{
    if (!c)
        return NULL;
    struct slot *s = live_slot(c, h);
    return s ? s->state : NULL;
}

const struct tw_tile_info *tw_tile_cache_info(const struct tw_tile_cache *c,
                                              struct tw_tile_handle h)
{
    if (!c)
        return NULL;
    struct slot *s = live_slot(c, h);
    return s ? &s->info : NULL;
}

bool tw_tile_cache_alive(const struct tw_tile_cache *c, struct tw_tile_handle h)
{
    if (!c)
        return false;
    return live_slot(c, h) != NULL;
}

uint64_t tw_tile_handle_pack(struct tw_tile_handle h)
{
    return ((uint64_t)h.generation << 32) | h.slot;
}

struct tw_tile_handle tw_tile_handle_unpack(uint64_t packed)
{
    struct tw_tile_handle h = {(uint32_t)packed, (uint32_t)(packed >> 32)};
    return h;
}

uint32_t tw_tile_cache_evict(struct tw_tile_cache *c, uint64_t frame)
{
    if (!c)
        return 0;
    uint32_t evicted = 0;
    for (uint32_t k = 0; k < c->slot_count; k++) {
        struct slot *s = &c->slots[k];
        if ((s->generation & 1u) == 0 || s->info.visible_frame + c->evict_after >= frame)
            continue;
        release(c, k);
        evicted++;
    }
    return evicted;
}

uint32_t tw_tile_cache_count(const struct tw_tile_cache *c)
{
    return c ? c->live : 0;
}

uint64_t tw_tile_cache_bytes(const struct tw_tile_cache *c)
{
    if (!c)
        return 0;
    return sizeof(*c) + (uint64_t)sizeof(*c->slots) * c->slot_cap + tw_cell_map_bytes(c->by_cell) +
           c->state_bytes;
}

bool tw_tile_cache_remove(struct tw_tile_cache *c, struct tw_cell cell)
{
    struct tw_tile_handle h;
    if (!c || !tw_tile_cache_find(c, cell, &h))
        return false;
    release(c, h.slot);
    return true;
}

bool tw_tile_cache_evict_oldest(struct tw_tile_cache *c, uint64_t frame, uint64_t *bytes)
{
    if (!c)
        return false;
    uint32_t best = UINT32_MAX;
    for (uint32_t k = 0; k < c->slot_count; k++) {
        const struct slot *s = &c->slots[k];
        if ((s->generation & 1u) == 0 || s->info.visible_frame >= frame)
            continue;
        if (best == UINT32_MAX || s->info.visible_frame < c->slots[best].info.visible_frame)
            best = k;
    }
    if (best == UINT32_MAX)
        return false;
    if (bytes)
        *bytes = c->slots[best].info.state_bytes;
    release(c, best);
    return true;
}

uint32_t tw_tile_cache_remove_rect(struct tw_tile_cache *c, struct tw_cell lo, struct tw_cell hi)
{
    uint32_t removed = 0;
    for (uint32_t k = 0; c && k < c->slot_count; k++) {
        const struct slot *s = &c->slots[k];
        if ((s->generation & 1u) == 0)
            continue;
        const struct tw_cell cell = s->info.cell;
        if (cell.i >= lo.i && cell.i <= hi.i && cell.j >= lo.j && cell.j <= hi.j) {
            release(c, k);
            removed++;
        }
    }
    return removed;
}
