/*
 * The neighbours of a grid cell, in the one order that the cull module's
 * propagations visit them (tile queries, their prefetch, the HZB frontier):
 * the 4 edge neighbours first, +i, -i, +j, -j, then the 4 diagonals, so that
 * a walk over the first 4 or all 8 is deterministic. Private to the library:
 * not installed, not public API.
 */
#ifndef TW_TILES_NEIGHBOURS_H
#define TW_TILES_NEIGHBOURS_H

#include <stdint.h>

#include "tileworld/tiles.h"

/* How many neighbours a cell has: the first 4 share an edge with it, the
 * last 4 a corner. */
#define TW_CELL_NEIGHBOURS 8u

/* Neighbour k (< TW_CELL_NEIGHBOURS) of cell; coordinates wrap around at
 * the int64_t range instead of overflowing. */
static inline struct tw_cell tw_cell_neighbour(struct tw_cell cell, uint32_t k)
{
    static const int8_t di[TW_CELL_NEIGHBOURS] = {1, -1, 0, 0, 1, 1, -1, -1};
    static const int8_t dj[TW_CELL_NEIGHBOURS] = {0, 0, 1, -1, 1, -1, 1, -1};
    const struct tw_cell n = {(int64_t)((uint64_t)cell.i + (uint64_t)(int64_t)di[k]),
                              (int64_t)((uint64_t)cell.j + (uint64_t)(int64_t)dj[k])};
    return n;
}

#endif
