/*
 * Blocks for the library's packed structures (tw_tileset_pack(),
 * tw_bvh_pack()): a large block is its own anonymous mapping of whole
 * pages, so that freeing it returns its pages to the system whatever the C
 * library's malloc does with its heap (glibc keeps freed heap memory, and
 * raises its mmap threshold as blocks are freed); a small one comes from
 * malloc. Private to the library: not installed, not public API.
 */
#ifndef TW_TILES_PAGES_H
#define TW_TILES_PAGES_H

#include <stddef.h>

/* Blocks of at least this many bytes are mapped; smaller ones are malloc's. */
#define TW_PAGES_MAP_MIN ((size_t)64 * 1024)

/* A block of bytes (> 0) bytes, aligned to at least 16; NULL when out of
 * memory (a failed mapping included). Free it with tw_pages_free() and the
 * same bytes. Thread-safe. */
void *tw_pages_alloc(size_t bytes);

/* Frees a block of tw_pages_alloc(bytes); bytes must be the size it was
 * asked for (which of the two ways it came is told from it). NULL is
 * ignored. */
void tw_pages_free(void *block, size_t bytes);

#endif
