/*
 * cull's insides shared by its files (cull.h is the module's contract): the
 * growth of scratch arrays, the front-to-back order of cells and a binary
 * min-heap of (distance, index) entries in caller storage, for traversals
 * nearest first. Private to cull/.
 */
#ifndef TW_CULL_PRIVATE_H
#define TW_CULL_PRIVATE_H

#include <assert.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "cull/cull.h"
#include "tiles/array.h"

/* Grows *p to hold at least need elements of size elem (tiles/array.h's
 * doubling, from 64); the new elements are zeroed. False when out of memory
 * (*p unchanged). */
static inline bool tw_cull_reserve(void **p, size_t *cap, size_t need, size_t elem)
{
    const size_t old = *cap;
    if (tw_array_reserve(p, cap, need, elem, 64) != TW_OK)
        return false;
    if (*cap > old)
        memset((char *)*p + old * elem, 0, (*cap - old) * elem);
    return true;
}

/* Front to back: by distance, ties by cell (i, then j); < 0, 0 or > 0. */
static inline int tw_cull_cell_order(const struct tw_cull_cell *x, const struct tw_cull_cell *y)
{
    if (x->distance != y->distance)
        return x->distance < y->distance ? -1 : 1;
    if (x->cell.i != y->cell.i)
        return x->cell.i < y->cell.i ? -1 : 1;
    return (x->cell.j > y->cell.j) - (x->cell.j < y->cell.j);
}

/* One entry of a distance heap: what (an index of the caller's) and how far. */
struct tw_distance_entry {
    float distance;
    uint32_t index;
};

/* Nearest first, ties by index: a total order, so traversals are
 * deterministic. */
static inline int tw_distance_less(const struct tw_distance_entry *a,
                                   const struct tw_distance_entry *b)
{
    if (a->distance != b->distance)
        return a->distance < b->distance;
    return a->index < b->index;
}

/* Pushes onto heap[0, *count); the caller has made room (*count < cap). */
static inline void tw_distance_push(struct tw_distance_entry *heap, size_t *count,
                                    float distance, uint32_t index)
{
    const struct tw_distance_entry e = {distance, index};
    size_t i = (*count)++;
    while (i > 0) {
        const size_t parent = (i - 1) / 2;
        if (!tw_distance_less(&e, &heap[parent]))
            break;
        heap[i] = heap[parent];
        i = parent;
    }
    heap[i] = e;
}

/* Pops the nearest entry's index off a non-empty heap. */
static inline uint32_t tw_distance_pop(struct tw_distance_entry *heap, size_t *count)
{
    assert(*count > 0);
    const uint32_t top = heap[0].index;
    const struct tw_distance_entry last = heap[--*count];
    const size_t n = *count;
    size_t i = 0;
    for (;;) {
        size_t c = 2 * i + 1;
        if (c >= n)
            break;
        if (c + 1 < n && tw_distance_less(&heap[c + 1], &heap[c]))
            c++;
        if (!tw_distance_less(&heap[c], &last))
            break;
        heap[i] = heap[c];
        i = c;
    }
    if (n > 0)
        heap[i] = last;
    return top;
}

#endif
