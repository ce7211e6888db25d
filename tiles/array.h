/*
 * The growth of the library's flat arrays, and the layout of a packed block,
 * shared by its modules (tiles, bvh, tilesets, runtime): an array of *cap
 * elements doubles until it holds what is asked for. Private to the library:
 * not installed, not public API.
 */
#ifndef TW_TILES_ARRAY_H
#define TW_TILES_ARRAY_H

#include <assert.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/tiles.h"
#include "tiles/pages.h"

/* Grows *array, of *cap elements of elem bytes, to hold at least need: the
 * capacity (first, at least 1, when it is 0) doubles until it does; it never shrinks.
 * TW_ERR_NOMEM when out of memory or when the bytes would not fit a
 * size_t, TW_ERR_LIMIT when the capacity would pass max elements; *array
 * and *cap stay as they were on failure. The new elements are not
 * initialised. */
static inline int tw_array_reserve_max(void **array, size_t *cap, size_t need, size_t elem,
                                       size_t first, size_t max)
{
    if (need <= *cap)
        return TW_OK;
    size_t n = *cap ? *cap : (first ? first : 1);
    while (n < need) {
        if (n > SIZE_MAX / 2 / elem)
            return TW_ERR_NOMEM;
        if (n > max / 2)
            return TW_ERR_LIMIT;
        n *= 2;
    }
    void *p = realloc(*array, n * elem);
    if (!p)
        return TW_ERR_NOMEM;
    *array = p;
    *cap = n;
    return TW_OK;
}

/* tw_array_reserve_max() with no limit but the size_t. */
static inline int tw_array_reserve(void **array, size_t *cap, size_t need, size_t elem,
                                   size_t first)
{
    return tw_array_reserve_max(array, cap, need, elem, first, SIZE_MAX);
}

/* tw_array_reserve_max() of an array counted in uint32_t: at most
 * UINT32_MAX elements. */
static inline int tw_array_reserve_u32(void **array, uint32_t *cap, uint32_t need, size_t elem,
                                       uint32_t first)
{
    size_t n = *cap;
    const int err = tw_array_reserve_max(array, &n, need, elem, first, UINT32_MAX);
    if (!err)
        *cap = (uint32_t)n;
    return err;
}

/* One block laid out in pieces, each starting at a multiple of 16 bytes:
 * a sizing pass with base NULL (tw_pack_take() returns NULL and only counts
 * used), then, with base a block of that size, a copying pass that takes the
 * same pieces in the same order. What tw_tileset_pack() and tw_bvh_pack()
 * lay a long-lived structure out with. */
struct tw_pack_cursor {
    unsigned char *base;
    size_t used;
};

/* The next piece, bytes long, copied from from (which may be NULL when bytes
 * is 0: an empty piece still gets a valid pointer in the copying pass). */
static inline void *tw_pack_take(struct tw_pack_cursor *c, const void *from, size_t bytes)
{
    const size_t at = c->used;
    c->used += (bytes + 15u) & ~(size_t)15u;
    if (!c->base)
        return NULL;
    if (bytes)
        memcpy(c->base + at, from, bytes);
    return c->base + at;
}

/* Lays from out in one new block of tw_pages_alloc() (whole pages of its
 * own from TW_PAGES_MAP_MIN bytes on, so that freeing a long-lived block
 * returns its pages whatever malloc keeps): layout(from, c) takes the
 * pieces, the new structure first (the block is then that structure's
 * pointer), and returns the new structure when c->base is set; it is run
 * once to size the block and once to fill it. Returns the new structure, or
 * NULL when out of memory (from untouched). The block's size is the
 * cursor's used after the second run, which layout records in the structure;
 * free the block with tw_pack_free() and that size. */
typedef void *(*tw_pack_layout_fn)(const void *from, struct tw_pack_cursor *c);
static inline void *tw_pack_block(const void *from, tw_pack_layout_fn layout)
{
    struct tw_pack_cursor c = {NULL, 0};
    layout(from, &c);
    const size_t bytes = c.used;
    c.base = tw_pages_alloc(bytes);
    if (!c.base)
        return NULL;
    c.used = 0;
    void *out = layout(from, &c);
    assert(out == (void *)c.base && c.used == bytes);
    return out;
}

/* Frees a block of tw_pack_block(), of bytes bytes (the size layout
 * recorded); NULL is ignored. */
static inline void tw_pack_free(void *block, size_t bytes)
{
    tw_pages_free(block, bytes);
}

#endif
