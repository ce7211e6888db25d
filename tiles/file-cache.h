/* Files kept on disk by a 64-bit key, the least recently used going first
 * beyond a byte limit: the 3D Tiles fetcher's bodies (tilesets/http.c)
 * and the levels of detail (tiles/lod.c). Thread-safe, and several
 * processes may share a folder: a file is written whole or not at all (a
 * temporary of its own, then a rename), and one that goes while it is read
 * is read whole (its data stays until it is closed). What a file holds and
 * whether it is the one asked for (two keys may share a name) is the
 * caller's to check. */
#ifndef TW_TILES_FILE_CACHE_H
#define TW_TILES_FILE_CACHE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

struct tw_file_cache;

/* A cache in dir (copied; made if missing, with its parents), its files
 * named KEY.suffix (suffix copied, up to 7 characters), at most max_bytes
 * together (> 0). Fails with TW_ERR_IO and a sentence in err for a folder
 * that cannot be made or is not one; TW_ERR_INVALID for bad arguments. */
int tw_file_cache_open(const char *dir, const char *suffix, uint64_t max_bytes,
                       struct tw_file_cache **out, char *err, size_t err_size);
void tw_file_cache_close(struct tw_file_cache *c);

/* The file of key, opened for reading; NULL if there is none. */
FILE *tw_file_cache_get(const struct tw_file_cache *c, uint64_t key);
/* Marks the file of key used now: the eviction takes the oldest. */
void tw_file_cache_touch(const struct tw_file_cache *c, uint64_t key);
/* Stores head then body as the file of key, replacing any; a failure only
 * loses the copy (false). Beyond the limit, the oldest files go until the
 * rest fit 7/8 of it. */
bool tw_file_cache_put(struct tw_file_cache *c, uint64_t key, const void *head, size_t head_size,
                       const void *body, size_t body_size);

#endif
